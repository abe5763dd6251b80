"""Canonical Gaussian state (§6.1 layout) and CRAW."""
import hashlib

import numpy as np

from common import DlgsError, Reader, zstd_exact


def floats_per(h):
    L = h.L
    return 3 + 3 + 4 + 1 + 3 * (h.sh_degree + 1) ** 2 + ((1 + L) if L > 0 else 0)


class GSet:
    """One set of n Gaussians, arrays f32."""
    FIELDS = ("pos", "ls", "rot", "op", "sh", "lop", "lang")

    def __init__(self, n, h):
        C = 3 * (h.sh_degree + 1) ** 2
        L = h.L
        self.n = n
        self.pos = np.zeros((n, 3), np.float32)
        self.ls = np.zeros((n, 3), np.float32)
        self.rot = np.zeros((n, 4), np.float32)
        self.op = np.zeros((n,), np.float32)
        self.sh = np.zeros((n, C), np.float32)
        self.lop = np.zeros((n,), np.float32) if L else None
        self.lang = np.zeros((n, L), np.float32) if L else None

    def copy(self):
        o = GSet.__new__(GSet)
        o.n = self.n
        for f in self.FIELDS:
            v = getattr(self, f)
            setattr(o, f, None if v is None else v.copy())
        return o

    def body(self):
        parts = [self.pos, self.ls, self.rot, self.op, self.sh]
        if self.lop is not None:
            parts += [self.lop, self.lang]
        return b"".join(np.ascontiguousarray(p, dtype="<f4").tobytes() for p in parts)

    @staticmethod
    def from_body(buf, n, h):
        s = GSet(n, h)
        a = np.frombuffer(buf, "<f4").astype(np.float32)
        p = 0

        def take(k):
            nonlocal p
            v = a[p:p + k]
            p += k
            return v
        s.pos = take(3 * n).reshape(n, 3).copy()
        s.ls = take(3 * n).reshape(n, 3).copy()
        s.rot = take(4 * n).reshape(n, 4).copy()
        s.op = take(n).copy()
        C = 3 * (h.sh_degree + 1) ** 2
        s.sh = take(C * n).reshape(n, C).copy()
        if h.L:
            s.lop = take(n).copy()
            s.lang = take(h.L * n).reshape(n, h.L).copy()
        assert p == len(a)
        return s


class State:
    def __init__(self, st, dy):
        self.sets = [st, dy]

    def copy(self):
        return State(self.sets[0].copy(), self.sets[1].copy())

    def sha(self):
        return hashlib.sha256(self.sets[0].body() + self.sets[1].body()).hexdigest()


def parse_craw(p, base, h):
    r = Reader(p, base, "CRAW")
    sh = r.u8()
    lw = r.u8()
    codec = r.u8()
    r.u8()
    ns = r.u32()
    nd = r.u32()
    blen = r.u64()
    # GUESS: order of the field checks = offset order; codec other than 0/1 is Payload
    if sh != h.sh_degree:
        raise DlgsError("Payload", base + 0, "CRAW sh_degree")
    if lw != h.L:
        raise DlgsError("Payload", base + 1, "CRAW lang_width")
    if codec not in (0, 1):
        raise DlgsError("Payload", base + 2, "CRAW codec")
    if ns != h.n_static:
        raise DlgsError("Payload", base + 4, "CRAW n_static")
    if nd != h.n_dynamic:
        raise DlgsError("Payload", base + 8, "CRAW n_dynamic")
    F = floats_per(h)
    if blen != (ns + nd) * F * 4:
        raise DlgsError("Payload", base + 12, "CRAW body_len")
    rest = p[20:]
    if codec == 0:
        if len(rest) != blen:
            raise DlgsError("Payload", base + 20, "CRAW body size")
        body = rest
    else:
        body = zstd_exact(rest, blen, base + 20, "CRAW")
    nb = ns * F * 4
    return State(GSet.from_body(body[:nb], ns, h), GSet.from_body(body[nb:], nd, h))
