"""Shared helpers: errors, CRC-32C, binary reading, exact f32 arithmetic helpers,
Appendix B elementary functions (binary64, unfused)."""
import math
import struct

import numpy as np
import zstandard

f32 = np.float32
f64 = np.float64


class DlgsError(Exception):
    def __init__(self, kind, offset=None, msg=""):
        super().__init__(f"{kind} at {offset}: {msg}")
        self.kind = kind
        self.offset = offset
        self.msg = msg


# ---------------------------------------------------------------- CRC-32C (§1)
def _make_table():
    poly = 0x82F63B78  # reflected 0x1EDC6F41
    t = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ poly if c & 1 else c >> 1
        t.append(c)
    return t


_CRC_T = _make_table()


def crc32c(data):
    c = 0xFFFFFFFF
    t = _CRC_T
    for b in data:
        c = t[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


assert crc32c(b"123456789") == 0xE3069283


# ---------------------------------------------------------------- reading
class Reader:
    """Little-endian cursor over a bytes object; offsets reported absolute."""

    def __init__(self, data, base=0, chunk=""):
        self.d = data
        self.p = 0
        self.base = base
        self.chunk = chunk

    def left(self):
        return len(self.d) - self.p

    def need(self, n, kind="Truncated"):
        if n < 0 or self.p + n > len(self.d):
            raise DlgsError(kind, self.base + self.p, f"{self.chunk}: need {n} bytes")

    def take(self, n):
        self.need(n)
        b = self.d[self.p:self.p + n]
        self.p += n
        return b

    def u8(self):
        return self.take(1)[0]

    def u16(self):
        return struct.unpack("<H", self.take(2))[0]

    def u32(self):
        return struct.unpack("<I", self.take(4))[0]

    def i32(self):
        return struct.unpack("<i", self.take(4))[0]

    def u64(self):
        return struct.unpack("<Q", self.take(8))[0]

    def f32(self):
        return np.frombuffer(self.take(4), "<f4")[0]

    def f16(self):
        return np.float32(np.frombuffer(self.take(2), "<f2")[0])

    def f64(self):
        return struct.unpack("<d", self.take(8))[0]

    def varint(self):
        v = 0
        start = self.p
        for i in range(5):
            b = self.u8()
            v |= (b & 0x7F) << (7 * i)
            if not b & 0x80:
                if v >= 1 << 32:
                    raise DlgsError("InvalidField", self.base + start, "varint >= 2^32")
                return v
        raise DlgsError("InvalidField", self.base + start, "varint longer than 5 bytes")

    def off(self):
        return self.base + self.p


def zstd_exact(data, size, off=None, what=""):
    """§1: exactly one zstd frame decompressing to exactly `size` bytes, nothing after."""
    try:
        dctx = zstandard.ZstdDecompressor()
        obj = dctx.decompressobj()
        out = obj.decompress(bytes(data))
        if not obj.eof:
            raise DlgsError("Decompress", off, f"{what}: incomplete zstd frame")
        if obj.unused_data:
            raise DlgsError("Decompress", off, f"{what}: bytes after zstd frame")
    except zstandard.ZstdError as e:
        raise DlgsError("Decompress", off, f"{what}: {e}")
    if len(out) != size:
        raise DlgsError("Decompress", off, f"{what}: size {len(out)} != {size}")
    return out


# ---------------------------------------------------------------- f32 helpers
def bits32(x):
    return np.array(x, dtype=np.float32).view(np.uint32)


def fromhex32(h):
    return np.array([h], dtype=np.uint32).view(np.float32)[0]


def fromhex64(h):
    return struct.unpack("<d", struct.pack("<Q", h))[0]


def fma32(a, b, c):
    """Correctly rounded binary32 fused multiply-add, vectorised.
    a*b is exact in binary64; p + c is computed with round-to-odd in binary64
    (53 >= 24 + 2 bits), then rounded to binary32: a single correct rounding."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    p = a * b
    with np.errstate(all="ignore"):
        s = p + c
        bb = s - p
        err = (p - (s - bb)) + (c - bb)
        sv = s.view(np.int64) if s.ndim else np.array(s).view(np.int64)
        fix = (err != 0) & ((sv & 1) == 0) & np.isfinite(s)
        if np.any(fix):
            s = np.where(fix, np.nextafter(s, np.where(err > 0, np.inf, -np.inf)), s)
    return s.astype(np.float32)


# ---------------------------------------------------------------- Appendix B (binary64)
LN2_HI = fromhex64(0x3FE62E42FEE00000)
LN2_LO = fromhex64(0x3DEA39EF35793C76)
PIO2_HI = fromhex64(0x3FF921FB54400000)
PIO2_LO = fromhex64(0x3DD0B4611A626331)
SQRT2 = fromhex64(0x3FF6A09E667F3BCD)
LOG2_E = fromhex64(0x3FF71547652B82FE)
FRAC_2_PI = fromhex64(0x3FE45F306DC9C883)
PI = fromhex64(0x400921FB54442D18)
FRAC_PI_2 = fromhex64(0x3FF921FB54442D18)


def fact(n):
    r = 1.0
    for i in range(1, n + 1):
        r = r * float(i)
    return r


def round_away(x):
    t = math.trunc(x)
    if abs(x - t) >= 0.5:
        t += 1 if x > 0 else -1
    return float(t)


def ln64(x):
    if math.isnan(x) or x < 0:
        return math.nan
    if x == 0:
        return -math.inf
    if math.isinf(x):
        return math.inf
    e = 0
    if x < 2.0 ** -1022:
        x = x * 2.0 ** 54
        e = -54
    bitsx = struct.unpack("<Q", struct.pack("<d", x))[0]
    e = e + ((bitsx >> 52) & 0x7FF) - 1023
    m = struct.unpack("<d", struct.pack("<Q", (bitsx & ~(0x7FF << 52)) | (1023 << 52)))[0]
    if m > SQRT2:
        m = m * 0.5
        e = e + 1
    f = m - 1
    s = f / (2 + f)
    z = s * s
    r = 0.0
    for k in range(12, 0, -1):
        r = (r + 2.0 / (2 * k + 1)) * z
    hfsq = (0.5 * f) * f
    d = float(e)
    return d * LN2_HI - ((hfsq - (s * (hfsq + r) + d * LN2_LO)) - f)


_INV_FACT = [None] + [1.0 / fact(j) for j in range(1, 18)]


def exp64(x):
    if math.isnan(x):
        return math.nan
    if x > 709:
        return math.inf
    if x < -708:
        return 0.0
    k = round_away(x * LOG2_E)
    r = (x - k * LN2_HI) - k * LN2_LO
    p = 0.0
    for j in range(13, 0, -1):
        p = (p + _INV_FACT[j]) * r
    p = p + 1
    return p * struct.unpack("<d", struct.pack("<Q", (int(k) + 1023) << 52))[0]


_SIN_TERMS = [None] + [((-1.0 if j % 2 else 1.0) / fact(2 * j + 1), (-1.0 if j % 2 else 1.0) / fact(2 * j)) for j in range(1, 9)]


def sin64(x):
    if not math.isfinite(x):
        return math.nan
    k = round_away(x * FRAC_2_PI)
    r = (x - k * PIO2_HI) - k * PIO2_LO
    z = r * r
    ps = 0.0
    pc = 0.0
    for j in range(8, 0, -1):
        ps = (ps + _SIN_TERMS[j][0]) * z
        pc = (pc + _SIN_TERMS[j][1]) * z
    s = r + r * ps
    c = 1 + pc
    q = int(k) % 4
    return (s, c, -s, -c)[q]


def _asin_coeffs():
    a = [None]
    t = 1.0
    for n in range(1, 27):
        t = (t * float(2 * n - 1)) / float(2 * n)
        a.append(t / float(2 * n + 1))
    return a


_ASIN_A = _asin_coeffs()


def asin_small(y):
    z = y * y
    p = 0.0
    for n in range(26, 0, -1):
        p = (p + _ASIN_A[n]) * z
    return y + y * p


def acos64(x):
    if math.isnan(x) or abs(x) > 1:
        return math.nan
    if abs(x) <= 0.5:
        return FRAC_PI_2 - asin_small(x)
    if x > 0:
        return 2 * asin_small(math.sqrt((1 - x) * 0.5))
    return PI - 2 * asin_small(math.sqrt((1 + x) * 0.5))


def ln32(x):
    return np.float32(ln64(float(x)))


def sin32(x):
    return np.float32(sin64(float(x)))


def acos32(x):
    return np.float32(acos64(float(x)))


# ---------------------------------------------------------------- tanh32 (§6.4)
T_LOG2E = fromhex32(0x3FB8AA3B)
T_LN2_HI = fromhex32(0x3F317200)
T_LN2_LO = fromhex32(0x35BFBE8E)
T_C = [np.float32(1), np.float32(1), np.float32(0.5), fromhex32(0x3E2AAAAB), fromhex32(0x3D2AAAAB),
       fromhex32(0x3C088889), fromhex32(0x3AB60B61), fromhex32(0x39500D01)]


def round_away_arr(x):
    t = np.trunc(x)
    return np.where(np.abs(x - t) >= 0.5, t + np.sign(x), t)


def tanh32(x):
    x = np.asarray(x, dtype=np.float32)
    with np.errstate(all="ignore"):
        a = np.minimum(np.abs(x), np.float32(9))
        a = np.where(np.isnan(x), np.float32(9), a).astype(np.float32)
        y = (np.float32(-2) * a).astype(np.float32)
        n = round_away_arr((y * T_LOG2E).astype(np.float32)).astype(np.float32)
        r = fma32(-n, T_LN2_LO, fma32(-n, T_LN2_HI, y))
        p = np.full_like(r, T_C[7])
        for c in (T_C[6], T_C[5], T_C[4], T_C[3], T_C[2], T_C[1], T_C[0]):
            p = fma32(p, r, c)
        e = (p * np.exp2(n).astype(np.float32)).astype(np.float32)
        t = ((np.float32(1) - e) / (np.float32(1) + e)).astype(np.float32)
        return np.copysign(t, x).astype(np.float32)


def layer_fma(W, x, bias=None):
    """out[..., o] = fma chain over i ascending of W[o, i] * x[..., i], starting at bias or +0.
    W: (out, in) f32; x: (..., in) f32."""
    W = np.asarray(W, dtype=np.float32)
    x = np.asarray(x, dtype=np.float32)
    shape = x.shape[:-1] + (W.shape[0],)
    if bias is None:
        acc = np.zeros(shape, dtype=np.float32)
    else:
        acc = np.broadcast_to(np.asarray(bias, dtype=np.float32), shape).astype(np.float32)
    for i in range(W.shape[1]):
        acc = fma32(W[:, i], x[..., i:i + 1], acc)
    return acc


def layer_unfused(W, x, bias):
    W = np.asarray(W, dtype=np.float32)
    x = np.asarray(x, dtype=np.float32)
    shape = x.shape[:-1] + (W.shape[0],)
    acc = np.broadcast_to(np.asarray(bias, dtype=np.float32), shape).astype(np.float32)
    for i in range(W.shape[1]):
        acc = (acc + (W[:, i] * x[..., i:i + 1]).astype(np.float32)).astype(np.float32)
    return acc


def relu(v):
    return np.maximum(v, np.float32(0)).astype(np.float32)


# coverage counters (which paths the vectors exercised)
import collections as _c
COVER = _c.Counter()
