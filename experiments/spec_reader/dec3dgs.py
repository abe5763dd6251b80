"""3DGS (variant 0) GOP state decoding with residual chains."""
from canon import parse_craw
from common import DlgsError
from container import NOREF


class Decoder3DGS:
    def __init__(self, c):
        self.c = c
        self.h = c.head
        if self.h.variant != 0:
            raise DlgsError("Request", 0, "3DGS decoder on a variant-1 file")
        self.states = {}

    def state(self, g):
        if g in self.states:
            return self.states[g]
        c = self.c
        h = self.h
        (ff, fc, ref), chunks = c.gop(g)
        if ref == NOREF:
            if b"CSOG" in chunks:
                from csog import parse_csog
                ch = chunks[b"CSOG"]
                st = parse_csog(c.payload(ch), ch.poff, h)
            else:
                ch = chunks[b"CRAW"]
                st = parse_craw(c.payload(ch), ch.poff, h)
        else:
            base = self.state(ref)
            ch = chunks[b"RES"]
            if ch.type == b"RDLT":
                from residual import apply_rdlt
                st = apply_rdlt(c.payload(ch), ch.poff, h, base)
            else:
                from residual import apply_rntc
                st = apply_rntc(c.payload(ch), ch.poff, h, base)
        self.states[g] = st
        return st
