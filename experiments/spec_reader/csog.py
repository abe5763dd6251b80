"""§6.5 CSOG: sets, parted sets, octree sets, coarse rotations, compact records."""
import math

import numpy as np

from canon import GSet, State
from common import COVER, DlgsError, Reader, fromhex32, ln32
from gridcodec import decode_cells
from rangecoder import BinModel, RangeDecoder


def isqrt_ceil(n):
    if n == 0:
        return 0
    r = math.isqrt(n)
    return r if r * r == n else r + 1


def n_channels(h):
    return 3 + 3 + 1 + 3 + 1 + 3 * (h.sh_degree + 1) ** 2 + ((1 + h.L) if h.L else 0)


def dequant(q, mn, mx, bits):
    mn = np.float32(mn)
    mx = np.float32(mx)
    d = np.float32(mx - mn)
    l = np.float32((1 << bits) - 1)
    step = np.float32(d / l)
    qf = np.asarray(q, dtype=np.float32)
    return (mn + (qf * step).astype(np.float32)).astype(np.float32)


class Rec:
    pass


def read_record(r, compact, is_index):
    rec = Rec()
    rec.off = r.off()
    if compact:
        hd = r.u8()
        rec.bits = (hd & 15) + 1
        rec.codec = (hd >> 4) & 7
        hflag = hd >> 7
        if rec.codec > 5:
            raise DlgsError("Payload", rec.off, "CSOG codec > 5")
        if is_index:
            if hflag:
                raise DlgsError("Payload", rec.off, "CSOG index record with h = 1")
            rec.min, rec.max = np.float32(0), np.float32(3)
        elif hflag:
            rec.min, rec.max = r.f16(), r.f16()
        else:
            rec.min, rec.max = r.f32(), r.f32()
        ln = r.varint()
    else:
        rec.bits = r.u8()
        rec.codec = r.u8()
        rec.min, rec.max = r.f32(), r.f32()
        ln = r.u32()
    if not (np.isfinite(rec.min) and np.isfinite(rec.max)):
        raise DlgsError("NonFinite", rec.off, "CSOG range")
    if not 1 <= rec.bits <= 16:
        raise DlgsError("Payload", rec.off, "CSOG bits")
    if rec.codec > 5:
        raise DlgsError("Payload", rec.off, "CSOG codec")
    if is_index and (rec.bits != 2 or rec.min != 0 or rec.max != 3):
        raise DlgsError("Payload", rec.off, "CSOG rotation index record")
    rec.data_off = r.off()
    rec.data = r.take(ln)
    return rec


# ---------------------------------------------------------------- octree (§6.5.5)
def decode_octree(wb, n, B, off):
    rd = RangeDecoder(wb, off, "CSOG octree")
    O = {}
    S = {}
    C = {}
    pts = []
    st = {"pend": 0}

    def model(fam, key):
        m = fam.get(key)
        if m is None:
            m = fam[key] = BinModel()
        return m

    def adapt(m):
        b = rd.binary(m.p)
        m.update(b)
        return b

    def check():
        if len(pts) + st["pend"] > n:
            raise DlgsError("Payload", off, "octree: more points than n")

    def lone(px, py, pz, k):
        if k:
            vx = rd.uniform(k)
            vy = rd.uniform(k)
            vz = rd.uniform(k)
        else:
            vx = vy = vz = 0
        pts.append(((px << k) | vx, (py << k) | vy, (pz << k) | vz))

    def crowded(l, px, py, pz, kpar):
        st["pend"] -= 2
        occ = []
        s = 0
        for j in range(8):
            if j == 7 and s == 0:
                occ.append(7)
                s += 1
                continue
            b = adapt(model(O, (min(l, 15), j, min(s, 3), min(max(kpar, 1), 4) - 1)))
            if b:
                occ.append(j)
                s += 1
        c = len(occ)
        lones = []
        if c >= 2:
            for j in occ:
                lones.append(adapt(model(S, (min(l + 1, 16), min(c, 4) - 2))))
        else:
            lones = [0]
        st["pend"] += sum(1 if lo else 2 for lo in lones)
        check()
        for j, lo in zip(occ, lones):
            cx = (px << 1) | (j >> 2)
            cy = (py << 1) | ((j >> 1) & 1)
            cz = (pz << 1) | (j & 1)
            if lo:
                st["pend"] -= 1
                lone(cx, cy, cz, B - l - 1)
            elif l + 1 == B:
                st["pend"] -= 2
                L = 1
                i = 1
                while True:
                    b = adapt(model(C, i - 1))
                    if not b:
                        break
                    if i == 31:
                        raise DlgsError("Payload", off, "octree: count prefix of 31 ones")
                    L += 1
                    i += 1
                v = 1
                for _ in range(L - 1):
                    v = (v << 1) | rd.binary(32768)
                m = v + 1
                COVER["octree duplicate voxel"] += 1
                for _ in range(m):
                    pts.append((cx, cy, cz))
                check()
            else:
                crowded(l + 1, cx, cy, cz, c)

    if n == 1:
        lone(0, 0, 0, B)
    elif n >= 2:
        st["pend"] = 2
        crowded(0, 0, 0, 0, 1)
    if len(pts) != n:
        raise DlgsError("Payload", off, f"octree: {len(pts)} points, expected {n}")
    return np.array(pts, dtype=np.int64).reshape(n, 3)


def place(pts, W, n, ranges, B):
    """§6.5.5 order: returns array cell -> point index."""
    steps = []
    for a in range(3):
        mn, mx = float(ranges[a][0]), float(ranges[a][1])
        steps.append(max(mx - mn, 0.0) / float((1 << B) - 1))
    cell_of = np.full(n, -1, dtype=np.int64)
    H = (n + W - 1) // W if W else 0

    def valid(x0, y0, w, h):
        t = 0
        for y in range(y0, y0 + h):
            t += min(max(n - y * W - x0, 0), w)
        return t

    def first_valid(x0, y0, w, h):
        for y in range(y0, y0 + h):
            for x in range(x0, x0 + w):
                if y * W + x < n:
                    return y * W + x
        raise AssertionError

    def rec(idx, x0, y0, w, h):
        if len(idx) == 0:
            return
        if len(idx) == 1 or w * h == 1:
            cell_of[first_valid(x0, y0, w, h)] = idx[0]
            return
        if w >= h:
            halves = ((x0, y0, w // 2, h), (x0 + w // 2, y0, w - w // 2, h))
        else:
            halves = ((x0, y0, w, h // 2), (x0, y0 + h // 2, w, h - h // 2))
        na = valid(*halves[0])
        P = pts[idx]
        best = -1
        bestv = None
        for a in range(3):
            e = float(P[:, a].max() - P[:, a].min()) * steps[a]
            if bestv is None or e > bestv:
                best, bestv = a, e
        order = np.lexsort((idx, P[:, best]))
        s = idx[order]
        rec(s[:na], *halves[0])
        rec(s[na:], *halves[1])

    rec(np.arange(n, dtype=np.int64), 0, 0, W, H)
    assert (cell_of >= 0).all()
    return cell_of


# ---------------------------------------------------------------- sets
def read_set(r, n, h, compact, octree, coarse):
    st = {"n": n}
    nch = n_channels(h)
    if not compact:
        w = r.u32()
        if w != isqrt_ceil(n):
            raise DlgsError("Payload", r.off() - 4, "CSOG width")
        c = r.u16()
        if c != nch:
            raise DlgsError("Payload", r.off() - 2, "CSOG channels")
    recs = []
    first = 0
    if octree:
        o = r.off()
        if compact:
            b0 = r.u8()
            bits = b0 & 127
            hflag = b0 >> 7
            rng = [(r.f16(), r.f16()) if hflag else (r.f32(), r.f32()) for _ in range(3)]
        else:
            bits = r.u8()
            rng = [(r.f32(), r.f32()) for _ in range(3)]
        if not 1 <= bits <= 16:
            raise DlgsError("Payload", o, "octree bits")
        for a, b in rng:
            if not (np.isfinite(a) and np.isfinite(b)):
                raise DlgsError("NonFinite", o, "octree range")
        if compact:
            ln = r.varint()
            wb = r.take(ln)
            if ln % 4:
                raise DlgsError("Payload", o, "octree len not a multiple of 4")
        else:
            ln = r.u32()
            blob = r.take(ln)
            rr = Reader(blob, o, "octree")
            words = rr.u32()
            wb = rr.take(4 * words)
            if rr.left():
                raise DlgsError("Payload", o, "bytes after octree words")
        st["oct"] = (bits, rng, wb, o)
        if coarse:
            ms = r.u8()
            if ms > 8:
                raise DlgsError("Payload", r.off() - 1, "max_shift")
            th = r.f32()
            if not np.isfinite(th):
                raise DlgsError("NonFinite", r.off() - 4, "threshold")
            st["coarse"] = (ms, th)
        first = 3
    for ci in range(first, nch):
        recs.append((ci, read_record(r, compact, ci == 6)))
    st["recs"] = recs
    return st


def decode_set(st, h, compact, octree_set):
    n = st["n"]
    W = isqrt_ceil(n)
    g = GSet(n, h)
    cells = {}
    prev = None
    prev2 = None
    vals = {}
    coarse = st.get("coarse")
    for ci, rec in st["recs"]:
        c = decode_cells(rec.bits, rec.codec, rec.data, n, W, prev, prev2, rec.data_off, "CSOG", compact)
        lim = 4 if ci == 6 else (1 << rec.bits)
        if any(v >= lim for v in c):
            raise DlgsError("Payload", rec.data_off, "CSOG cell out of range")
        cells[ci] = (c, rec)
        prev2 = prev
        prev = (c, rec.bits)
    # values
    if octree_set:
        bits, rng, wb, o = st["oct"]
        pts = decode_octree(wb, n, bits, o)
        cell_of = place(pts, W, n, rng, bits)
        q = pts[cell_of]
        for a in range(3):
            g.pos[:, a] = dequant(q[:, a], rng[a][0], rng[a][1], bits)
    else:
        for a in range(3):
            c, rec = cells[a]
            g.pos[:, a] = dequant(c, rec.min, rec.max, rec.bits)
    for a in range(3):
        c, rec = cells[3 + a]
        g.ls[:, a] = dequant(c, rec.min, rec.max, rec.bits)
    idx = np.array(cells[6][0], dtype=np.int64)
    comps = []
    for a in range(3):
        c, rec = cells[7 + a]
        comps.append(dequant(c, rec.min, rec.max, rec.bits))
    if coarse is not None and coarse[0] > 0:
        ms, th = coarse
        k = shifts(g.ls, ms, th)
        COVER[f"coarse shifts>0: {int((k>0).sum())}"] += 1
        order = np.argsort(k, kind="stable")
        idx2 = np.empty_like(idx)
        idx2[order] = idx
        idx = idx2
        nc = []
        for a in range(3):
            v = np.empty_like(comps[a])
            v[order] = comps[a]
            v = (v * np.exp2(k).astype(np.float32)).astype(np.float32)
            nc.append(v)
        comps = nc
    a_, b_, c_ = comps
    s = ((a_ * a_).astype(np.float32) + (b_ * b_).astype(np.float32)).astype(np.float32)
    s = (s + (c_ * c_).astype(np.float32)).astype(np.float32)
    t = (np.float32(1) - s).astype(np.float32)
    t = np.where(t > 0, t, np.float32(0)).astype(np.float32)  # max(x, 0): 0 when negative or NaN
    big = np.sqrt(t).astype(np.float32)
    for i in range(n):
        m = idx[i]
        others = [a_[i], b_[i], c_[i]]
        q = others[:m] + [big[i]] + others[m:]
        g.rot[i] = q
    c, rec = cells[10]
    g.op = opacity_decode(c, rec)
    C = 3 * (h.sh_degree + 1) ** 2
    for j in range(C):
        c, rec = cells[11 + j]
        g.sh[:, j] = dequant(c, rec.min, rec.max, rec.bits)
    if h.L:
        c, rec = cells[11 + C]
        g.lop = opacity_decode(c, rec)
        for j in range(h.L):
            c, rec = cells[12 + C + j]
            g.lang[:, j] = dequant(c, rec.min, rec.max, rec.bits)
    return g


def shifts(ls, ms, th):
    m = np.fmax(np.fmax(ls[:, 0], ls[:, 1]), ls[:, 2]).astype(np.float32)
    x = ((np.float32(th) - m).astype(np.float32) * fromhex32(0x3FB8AA3B)).astype(np.float32)
    with np.errstate(invalid="ignore"):
        k = np.where(x >= 1, np.minimum(np.floor(np.nan_to_num(x, nan=0.0)), ms), 0)
    return k.astype(np.int64)


_LN_CACHE = {}


def opacity_decode(c, rec):
    alpha = dequant(c, rec.min, rec.max, rec.bits)
    l = np.float32((1 << rec.bits) - 1)
    eps = np.float32(np.float32(0.5) / l)  # GUESS: eps = f32 division 0.5f / l
    one_m = np.float32(np.float32(1) - eps)  # GUESS: 1 - eps from the f32 eps
    a = np.clip(alpha, eps, one_m).astype(np.float32)
    x = (a / (np.float32(1) - a).astype(np.float32)).astype(np.float32)
    out = np.empty_like(x)
    for i, v in enumerate(x):
        key = v.tobytes()
        r = _LN_CACHE.get(key)
        if r is None:
            r = _LN_CACHE[key] = ln32(v)
        out[i] = r
    return out


# ---------------------------------------------------------------- payload
def read_parted(r, n, h, compact, octree, coarse):
    o = r.off()
    parts = r.u8()
    if parts > 16 or (parts == 0 and n != 0):
        raise DlgsError("Payload", o, "CSOG parts")
    out = []
    left = n
    for _ in range(parts):
        po = r.off()
        cnt = r.varint() if compact else r.u32()
        if cnt > left:
            raise DlgsError("Payload", po, "CSOG part count")
        left -= cnt
        out.append(read_set(r, cnt, h, compact, octree, coarse))
    if left:
        raise DlgsError("Payload", o, "CSOG part counts do not add up")
    return out


def parse_csog(p, base, h):
    r = Reader(p, base, "CSOG")
    layout = r.u8()
    if layout > 4:
        raise DlgsError("Payload", base, "CSOG layout")
    compact = layout == 4
    sets = []
    for si, n in enumerate((h.n_static, h.n_dynamic)):
        octree = si == 0 and layout >= 2
        coarse = si == 0 and layout >= 3
        if layout == 0:
            parts = [read_set(r, n, h, False, False, False)]
        else:
            parts = read_parted(r, n, h, compact, octree, coarse)
        sets.append((n, parts, octree))
    if r.left():
        raise DlgsError("Payload", r.off(), "bytes after CSOG dynamic set")
    gs = []
    for n, parts, octree in sets:
        decoded = [decode_set(st, h, compact, octree) for st in parts]
        g = GSet(n, h)
        for f in GSet.FIELDS:
            arrs = [getattr(d, f) for d in decoded]
            if getattr(g, f) is None:
                continue
            if arrs:
                setattr(g, f, np.concatenate(arrs).astype(np.float32))
        gs.append(g)
    return State(gs[0], gs[1])
