"""§6.13 AHAC: HAC-coded canonical anchors."""
import math
import os

import numpy as np

from common import DlgsError, Reader, exp64, fromhex32, layer_unfused, zstd_exact
from rangecoder import RangeDecoder
from residual import decode_segments, grid_read
from scaffold import Anchors

F32 = np.float32
EPS9 = fromhex32(0x3089705F)
C_INV = fromhex32(0x37800080)
E6 = fromhex32(0x358637BD)

_T = None


def phi_table():
    global _T
    if _T is None:
        p = os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../format-spec/vectors/phi_table.txt")
        _T = [int(x) for x in open(p).read().split()]
        assert len(_T) == 4097
    return _T


def phifix(t):
    T = phi_table()
    t = min(max(t, F32(-8)), F32(8))
    v = F32(F32(t + F32(8)) * F32(256))
    k = min(int(math.floor(v)), 4095)
    fr = int(math.floor(float(F32(v - F32(k))) * 65536.0))
    return T[k] + (((T[k + 1] - T[k]) * fr) >> 16)


def relu_nan0(v):
    return np.where(v > 0, v, F32(0)).astype(F32)


def parse_ahac(p, base, h):
    r = Reader(p, base, "AHAC")
    ns, nd = r.u32(), r.u32()
    if ns != h.n_static:
        raise DlgsError("Payload", base, "AHAC n_static")
    if nd != h.n_dynamic:
        raise DlgsError("Payload", base + 4, "AHAC n_dynamic")
    N = ns + nd
    B = r.u32()
    if not 1 <= B <= 1 << 20:
        raise DlgsError("Payload", base + 8, "AHAC B")
    bmin = np.array([r.f32() for _ in range(3)], F32)
    bmax = np.array([r.f32() for _ in range(3)], F32)
    if not (np.all(np.isfinite(bmin)) and np.all(np.isfinite(bmax))):
        raise DlgsError("NonFinite", base + 12, "AHAC box")
    with np.errstate(over="ignore"):
        ext = (bmax - bmin).astype(F32)
    if not (np.all(bmax > bmin) and np.all(np.isfinite(ext))):
        raise DlgsError("Payload", base + 24, "AHAC box")
    QB = np.array([r.f32() for _ in range(3)], F32)
    if not np.all(np.isfinite(QB)):
        raise DlgsError("NonFinite", base + 36, "AHAC Q_BASE")
    if not np.all(QB > 0):
        raise DlgsError("Payload", base + 36, "AHAC Q_BASE")
    L3, T3, F3, L2, T2, F2, scope, _ = [r.u8() for _ in range(8)]
    if not (L3 <= 16 and 1 <= T3 <= 22 and 1 <= F3 <= 8 and L2 <= 16 and 1 <= T2 <= 22 and 1 <= F2 <= 8
            and scope <= 1):
        raise DlgsError("Payload", base + 48, "AHAC grid shape")
    R3 = [r.u32() for _ in range(L3)]
    R2 = [r.u32() for _ in range(L2)]
    if any(not 3 <= v <= 1 << 20 for v in R3 + R2):
        raise DlgsError("Payload", base + 56, "AHAC resolutions")
    H = r.u16()
    O = r.u16()
    if not 1 <= H <= 1024:
        raise DlgsError("Payload", r.off() - 4, "AHAC H")
    if O != 175:
        raise DlgsError("Payload", r.off() - 2, "AHAC O")
    I = L3 * F3 + 3 * L2 * F2
    if I < 1:
        raise DlgsError("Payload", base + 48, "AHAC I = 0")
    plen = r.u32()
    pb = r.take(plen)
    q = np.frombuffer(zstd_exact(pb, 6 * N, r.off() - plen, "AHAC positions"), "<u2").reshape(3, N).T
    interval = (((bmax - bmin).astype(F32) * C_INV).astype(F32) + E6).astype(F32)
    pos = ((q.astype(F32) * interval).astype(F32) + bmin).astype(F32)
    # grids
    levels = []  # (R, T, F, D)
    for R in R3:
        levels.append((R, T3, F3, 3))
    for _ in range(3):
        for R in R2:
            levels.append((R, T2, F2, 2))
    sizes = []
    for R, T, Fn, D in levels:
        rows = -(-min(1 << T, R ** D) // 8) * 8
        sizes.append(rows * Fn)
    groups_of = [0] * L3 + [1] * (3 * L2)
    segs = decode_segments(r, sizes, scope, groups_of, base, "AHAC")
    wlen = r.u32()
    wb = r.take(wlen)
    nparam = (I + 1) * H + (H + 1) * O
    vals = np.frombuffer(zstd_exact(wb, 4 * nparam, r.off() - wlen, "AHAC mlp_grid"), "<f4").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("Payload", base, "AHAC mlp_grid non-finite")
    o = 0
    W1 = vals[o:o + H * I].reshape(H, I); o += H * I
    b1 = vals[o:o + H]; o += H
    W2 = vals[o:o + O * H].reshape(O, H); o += O * H
    b2 = vals[o:o + O]
    # stream headers
    nb = -(-N // B)
    hdrs = []
    for b in range(nb):
        for a in range(3):
            ho = r.off()
            lo, hi, nbytes = r.i32(), r.i32(), r.u32()
            if not (-(2 ** 23 - 1) <= lo <= hi <= 2 ** 23 - 1 and hi - lo + 1 <= 1 << 16):
                raise DlgsError("Payload", ho, f"AHAC batch {b} attribute {a} bounds")
            if nbytes % 4 or ((nbytes == 0) != (lo == hi)):
                raise DlgsError("Payload", ho, f"AHAC batch {b} attribute {a} bytes")
            hdrs.append((lo, hi, nbytes))
    streams = [r.take(hb[2]) for hb in hdrs]
    if r.left():
        raise DlgsError("Payload", r.off(), "AHAC bytes after the last stream")
    # context
    u = ((pos - bmin).astype(F32) / (bmax - bmin).astype(F32)).astype(F32)
    inside = np.all((u >= 0) & (u <= 1), axis=1)
    feats = np.zeros((N, I), F32)
    if inside.any():
        ui = u[inside]
        cols = []
        li = 0
        for l in range(L3):
            cols.append(grid_read(ui, R3[l], T3, F3, segs[li])); li += 1
        for (a0, a1) in ((0, 1), (0, 2), (1, 2)):
            for l in range(L2):
                cols.append(grid_read(ui[:, [a0, a1]], R2[l], T2, F2, segs[li])); li += 1
        feats[inside] = np.concatenate(cols, axis=1)
    hid = relu_nan0(layer_unfused(W1, feats, b1))
    out = layer_unfused(W2, hid, b2)
    mean = [out[:, 0:50], out[:, 106:112 - 0][:, :0], None]
    mean = [out[:, 0:50], out[:, 100:106], out[:, 112:142]]
    scale = [out[:, 50:100], out[:, 106:112], out[:, 142:172]]
    adj = out[:, 172:175]
    Qs = np.zeros((N, 3), F32)
    for i in range(N):
        for a in range(3):
            v = adj[i, a]
            v = F32(0) if np.isnan(v) else F32(min(max(v, F32(-20)), F32(20)))
            av = abs(float(v))
            m = 1.0 - 2.0 / (exp64(2.0 * av) + 1.0)
            t = F32(m)
            if v < 0:
                t = -t
            Qs[i, a] = F32(QB[a] * F32(F32(1) + t))
    A = Anchors(N)
    A.pos = pos
    widths = [50, 6, 30]
    ints = [np.zeros((N, w), np.int64) for w in widths]
    for b in range(nb):
        a0, a1 = b * B, min((b + 1) * B, N)
        for a in range(3):
            lo, hi, nbytes = hdrs[3 * b + a]
            if lo == hi:
                ints[a][a0:a1] = lo
                continue
            L = hi - lo + 1
            rd = RangeDecoder(streams[3 * b + a], base, f"AHAC batch {b} attribute {a}")
            for i in range(a0, a1):
                Q = Qs[i, a]
                for c in range(widths[a]):
                    mu = mean[a][i, c]
                    sg = scale[a][i, c]
                    sg = sg if sg > EPS9 else EPS9
                    cache = {}

                    def C(j, lo=lo, L=L, Q=Q, mu=mu, sg=sg, cache=cache):
                        if j == 0:
                            return 0
                        if j == L:
                            return 1 << 24
                        v = cache.get(j)
                        if v is None:
                            e = F32(F32(F32(lo + j) - F32(0.5)) * Q)
                            t = F32(F32(e - mu) / sg)
                            if np.isnan(t):
                                t = F32(-8)
                            v = cache[j] = ((phifix(t) * ((1 << 24) - L)) >> 32) + j
                        return v
                    s = rd.cdf_fn(C, L, 24)
                    ints[a][i, c] = lo + s
    A.feat = (ints[0].astype(F32) * Qs[:, 0:1]).astype(F32)
    A.ls = (ints[1].astype(F32) * Qs[:, 1:2]).astype(F32)
    A.off = (ints[2].astype(F32) * Qs[:, 2:3]).astype(F32)
    return A
