"""Appendix A range decoder and models."""
import bisect
import struct

from common import DlgsError

M64 = (1 << 64) - 1


class RangeDecoder:
    def __init__(self, words_bytes, off=None, what=""):
        n = len(words_bytes) // 4
        self.w = list(struct.unpack("<%dI" % n, bytes(words_bytes[:4 * n])))
        self.W = n
        self.off = off
        self.what = what
        self.point = (self.word(0) << 32) | self.word(1)
        self.next = 2
        self.lower = 0
        self.range = M64

    def word(self, i):
        return self.w[i] if i < self.W else 0

    def _quantile(self, P):
        scale = self.range >> P
        q = ((self.point - self.lower) & M64) // scale
        if q >= (1 << P):
            raise DlgsError("Payload", self.off, f"{self.what}: range decoder error")
        return scale, q

    def _update(self, scale, c, f):
        self.lower = (self.lower + scale * c) & M64
        self.range = scale * f
        if self.range < (1 << 32):
            self.lower = (self.lower << 32) & M64
            self.range = (self.range << 32) & M64
            self.point = ((self.point << 32) & M64) | self.word(self.next)
            self.next += 1

    def categorical(self, cum, P):
        """cum: list of S+1 cumulative starts (cum[0]=0, cum[S]=2^P)."""
        scale, q = self._quantile(P)
        s = bisect.bisect_right(cum, q) - 1
        self._update(scale, cum[s], cum[s + 1] - cum[s])
        return s

    def binary(self, p0):
        """16-bit binary model; returns bit."""
        scale, q = self._quantile(16)
        if q >= p0:
            self._update(scale, p0, 65536 - p0)
            return 1
        self._update(scale, 0, p0)
        return 0

    def binary_p(self, p1, P):
        """two-symbol categorical (2^P - p1, p1)."""
        scale, q = self._quantile(P)
        c1 = (1 << P) - p1
        if q >= c1:
            self._update(scale, c1, p1)
            return 1
        self._update(scale, 0, c1)
        return 0

    def uniform(self, k):
        scale, q = self._quantile(16)
        v = q >> (16 - k)
        self._update(scale, v << (16 - k), 1 << (16 - k))
        return v

    def cdf_fn(self, C, L, P):
        """Decode with a model given as function C(j) for j in 0..L (monotone)."""
        scale, q = self._quantile(P)
        lo, hi = 0, L  # find largest s with C(s) <= q
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if C(mid) <= q:
                lo = mid
            else:
                hi = mid
        c0 = C(lo)
        c1 = C(lo + 1)
        self._update(scale, c0, c1 - c0)
        return lo


class BinModel:
    __slots__ = ("p", "seen")

    def __init__(self):
        self.p = 32768
        self.seen = 0

    def update(self, bit):
        s = min(self.seen + 1, 6)
        if bit:
            self.p -= self.p >> s
        else:
            self.p += (65536 - self.p) >> s
        if self.p < 32:
            self.p = 32
        elif self.p > 65504:
            self.p = 65504
        self.seen = min(self.seen + 1, 255)


def dec_adaptive(rd, m):
    b = rd.binary(m.p)
    m.update(b)
    return b


def dec_raw(rd):
    return rd.binary(32768)


def self_test():
    w = struct.pack("<II", 0xFDFFEFF0, 0x207FB0E0)
    rd = RangeDecoder(w)
    cum = [0, 4032, 4064, 4096]
    out = [rd.categorical(cum, 12) for _ in range(7)]
    assert out == [1, 2, 0, 2, 1, 2, 0], out


self_test()
