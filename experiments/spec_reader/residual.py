"""§6.6 RNTC and §6.7 RDLT."""
import math

import numpy as np

from common import COVER, DlgsError, Reader, exp64, fma32, fromhex32, layer_fma, relu, zstd_exact
from gridcodec import decode_cells
from rangecoder import RangeDecoder

F32 = np.float32
EPS9 = fromhex32(0x3089705F)


def group_widths(h):
    C = 3 * (h.sh_degree + 1) ** 2
    return [3, 3, 4, 3, C - 3, 1, 1 if h.L else 0, h.L]


def group_view(gset, gid):
    """Returns (getter, setter) over an (n, w) f32 array for group gid."""
    if gid == 0:
        return gset.pos, lambda v: setattr(gset, "pos", v)
    if gid == 1:
        return gset.ls, lambda v: setattr(gset, "ls", v)
    if gid == 2:
        return gset.rot, lambda v: setattr(gset, "rot", v)
    if gid == 3:
        def s3(v):
            gset.sh[:, 0:3] = v
        return gset.sh[:, 0:3], s3
    if gid == 4:
        def s4(v):
            gset.sh[:, 3:] = v
        return gset.sh[:, 3:], s4
    if gid == 5:
        return gset.op[:, None], lambda v: setattr(gset, "op", v[:, 0].copy())
    if gid == 6:
        return gset.lop[:, None], lambda v: setattr(gset, "lop", v[:, 0].copy())
    if gid == 7:
        return gset.lang, lambda v: setattr(gset, "lang", v)


# ---------------------------------------------------------------- RDLT
def apply_rdlt(p, base, h, ref):
    r = Reader(p, base, "RDLT")
    G = r.u8()
    if G > 8:
        raise DlgsError("Payload", base, "RDLT G")
    r.take(3)
    widths = group_widths(h)
    groups = []
    seen = set()
    for k in range(G):
        o = base + 4 + 12 * k
        gid = r.u8()
        mode = r.u8()
        r.u16()
        step = r.f32()
        bound = r.f32()
        if gid > 7 or widths[gid] == 0 or gid in seen:
            raise DlgsError("Payload", o, "RDLT group id")
        seen.add(gid)
        if mode > 1:
            raise DlgsError("Payload", o + 1, "RDLT mode")
        if mode == 1:
            if not (np.isfinite(step) and step > 0):
                raise DlgsError("Payload", o + 4, "RDLT step")
            if not (np.isfinite(bound) and bound >= 0):
                raise DlgsError("Payload", o + 4, "RDLT bound")  # spec says at 8 + 12 k
        groups.append((gid, mode, step))
    out = ref.copy()
    for gid, mode, step in groups:
        w = widths[gid]
        for si in (0, 1):
            gs = out.sets[si]
            n = gs.n
            W = math.isqrt(n - 1) + 1 if n else 0
            arr, setter = group_view(gs, gid)
            arr = np.array(arr, dtype=np.float32)
            for c in range(w):
                co = r.off()
                kmin = r.i32()
                codec = r.u8()
                bits = r.u8()
                r.u16()
                ln = r.u32()
                data = r.take(ln)
                if codec <= 2:
                    if not 1 <= bits <= 16:
                        raise DlgsError("Payload", co, "RDLT bits")
                    q = np.array(decode_cells(bits, codec, data, n, W, None, None, co + 12, "RDLT"), dtype=np.int64)
                elif codec == 3:
                    if bits != 32:
                        raise DlgsError("Payload", co, "RDLT wide bits")
                    raw = np.frombuffer(zstd_exact(data, 4 * n, co + 12, "RDLT"), np.uint8).reshape(4, n).astype(np.int64)
                    q = raw[0] | (raw[1] << 8) | (raw[2] << 16) | (raw[3] << 24)
                else:
                    raise DlgsError("Payload", co, "RDLT codec")
                kk = ((kmin + q) & 0xFFFFFFFF).astype(np.uint32)
                col = arr[:, c].copy()
                if mode == 0:
                    col = (col.view(np.uint32) + kk).astype(np.uint32).view(np.float32)
                else:
                    ki = kk.view(np.int32).astype(np.float32)
                    col = (col + (ki * F32(step)).astype(F32)).astype(F32)
                arr[:, c] = col
            setter(arr)
    return out


# ---------------------------------------------------------------- binary segments (§6.6.3)
def decode_segments(r, sizes, scope, groups_of, off, what):
    """sizes: bits per segment; groups_of: group id per segment (for scope 1).
    Returns list of np.int8 arrays of 0/1."""
    pairs = []
    for i, nbits in enumerate(sizes):
        po = r.off()
        ones = r.u32()
        nb = r.u32()
        if ones > nbits:
            raise DlgsError("Payload", po, f"{what}: ones > bits")
        const = ones == 0 or ones == nbits
        if const and nb != 0 or (not const and (nb == 0 or nb % 4)):
            raise DlgsError("Payload", po, f"{what}: segment bytes")
        pairs.append((ones, nb))
    tot = {}
    for i, (ones, nb) in enumerate(pairs):
        g = groups_of[i]
        a, b = tot.get(g, (0, 0))
        tot[g] = (a + ones, b + sizes[i])
    segs = []
    for i, (ones, nb) in enumerate(pairs):
        nbits = sizes[i]
        data = r.take(nb)
        if ones == 0:
            segs.append(np.zeros(nbits, np.int8))
            continue
        if ones == nbits:
            segs.append(np.ones(nbits, np.int8))
            continue
        if scope == 0:
            o_, n_ = ones, nbits
        else:
            o_, n_ = tot[groups_of[i]]
        p1 = (o_ * (1 << 24) + n_ // 2) // n_
        p1 = min(max(p1, 1), (1 << 24) - 1)
        COVER[f"{what} coded segment scope {scope}"] += 1
        rd = RangeDecoder(data, off, what)
        bits = np.fromiter((rd.binary_p(p1, 24) for _ in range(nbits)), np.int8, nbits)
        if int(bits.sum()) != ones:
            raise DlgsError("Payload", off, f"{what}: segment holds {int(bits.sum())} ones, want {ones}")
        segs.append(bits)
    return segs


def grid_read(u, R, T, Fn, bits):
    """§6.6.4 steps 1-3. u: (n, D) f32 in [0,1]; bits: int8 array entry-major (e*F+f).
    Returns (n, F) f32."""
    n, D = u.shape
    r = F32(R - 2)
    pos = ((u * r).astype(F32) + F32(0.5)).astype(F32)
    g = np.floor(pos).astype(np.int64)
    w = (pos - g.astype(F32)).astype(F32)
    dense = R ** D <= (1 << T)
    from common import COVER as _CV
    _CV[f"grid D={D} dense={dense}"] += 1
    s = np.zeros(n, F32)
    acc = np.zeros((n, Fn), F32)
    sgn = bits.reshape(-1, Fn).astype(F32) * 2 - 1  # +1 / -1
    primes = [1, 2654435761, 805459861]
    wts = []
    for c in range(1 << D):
        k = np.empty((n, D), np.int64)
        weight = np.ones(n, F32)
        keep = np.ones(n, bool)
        for d in range(D):
            up = (c >> d) & 1
            k[:, d] = np.minimum(g[:, d] + up, R - 1)
            keep &= (k[:, d] != 0) & (k[:, d] != R - 1)
            fac = w[:, d] if up else (F32(1) - w[:, d]).astype(F32)
            weight = (weight * fac).astype(F32)
        if dense:
            idx = np.zeros(n, np.int64)
            mul = 1
            for d in range(D):
                idx += k[:, d] * mul
                mul *= R
        else:
            idx = np.zeros(n, np.int64)
            for d in range(D):
                idx ^= (k[:, d] * primes[d]) & 0xFFFFFFFF
            idx &= (1 << T) - 1
        idx = np.where(keep, idx, 0)
        wk = np.where(keep, weight, F32(0)).astype(F32)
        s = np.where(keep, (s + weight).astype(F32), s).astype(F32)
        contrib = (sgn[idx] * wk[:, None]).astype(F32)
        acc = np.where(keep[:, None], (acc + contrib).astype(F32), acc).astype(F32)
    s = (s + EPS9).astype(F32)
    return (acc / s[:, None]).astype(F32)


class NtcField:
    pass


def parse_rntc(p, base, h, anchor=False):
    r = Reader(p, base, "RNTC")
    f = NtcField()
    f.groups = r.u8()
    if anchor:
        widths = [50, 30, 6]
        if f.groups == 0 or f.groups & 0xF8:
            raise DlgsError("Payload", base, "RNTC groups")
    else:
        widths = group_widths(h)
        if f.groups == 0 or any((f.groups >> b) & 1 and widths[b] == 0 for b in range(8)):
            raise DlgsError("Payload", base, "RNTC groups")
    f.sets = r.u8()
    if f.sets == 0 or f.sets & 0xFC:
        raise DlgsError("Payload", base + 1, "RNTC sets")
    f.F, f.T2, f.T3, f.Lv = r.u8(), r.u8(), r.u8(), r.u8()
    if not (1 <= f.F <= 8 and 1 <= f.T2 <= 20 and 1 <= f.T3 <= 20 and 1 <= f.Lv <= 8):
        raise DlgsError("Payload", base + 2, "RNTC F/T2/T3/Lv")
    f.scope = r.u8()
    if f.scope > 1:
        raise DlgsError("Payload", base + 6, "RNTC scope")
    r.u8()
    f.bmin = np.array([r.f32() for _ in range(3)], F32)
    if not np.all(np.isfinite(f.bmin)):
        raise DlgsError("NonFinite", base + 8, "RNTC bmin")
    f.bmax = np.array([r.f32() for _ in range(3)], F32)
    if not np.all(np.isfinite(f.bmax)):
        raise DlgsError("NonFinite", base + 20, "RNTC bmax")
    for a in range(3):
        if not f.bmax[a] > f.bmin[a]:
            raise DlgsError("Payload", base + 20 + 4 * a, "RNTC bmax <= bmin")
    f.R3 = r.u32()
    if not 3 <= f.R3 <= 1 << 20:
        raise DlgsError("Payload", base + 32, "RNTC R3")
    f.R = []
    for l in range(f.Lv):
        v = r.u32()
        if not 3 <= v <= 1 << 20:
            raise DlgsError("Payload", r.off() - 4, "RNTC R")
        f.R.append(v)
    ho = r.off()
    f.H = r.u16()
    if not 1 <= f.H <= 1024:
        raise DlgsError("Payload", ho, "RNTC H")
    f.O = r.u16()
    sel = [b for b in range(len(widths)) if (f.groups >> b) & 1]
    if f.O != sum(widths[b] for b in sel):
        raise DlgsError("Payload", ho, "RNTC O")
    f.sel = sel
    f.widths = widths
    sizes = [(1 << f.T2) * f.F] * (3 * f.Lv) + [1 << f.T3]
    groups_of = [0] * (3 * f.Lv) + [1]
    f.segs = decode_segments(r, sizes, f.scope, groups_of, base, "RNTC")
    wlen = r.u32()
    wb = r.take(wlen)
    I = 3 * f.Lv * f.F
    nparam = (I + 1) * f.H + (f.H + 1) * f.O
    vals = np.frombuffer(zstd_exact(wb, 4 * nparam, r.off() - wlen, "RNTC weights"), "<f4").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("Payload", base, "RNTC weights non-finite")
    o = 0
    f.W1 = vals[o:o + I * f.H].reshape(f.H, I); o += I * f.H
    f.b1 = vals[o:o + f.H]; o += f.H
    f.W2 = vals[o:o + f.H * f.O].reshape(f.O, f.H); o += f.H * f.O
    f.b2 = vals[o:o + f.O]
    return f


def eval_field(f, x):
    """rows (n, O) f32 at positions x (n, 3)."""
    x = np.asarray(x, F32)
    n = x.shape[0]
    u = ((x - f.bmin).astype(F32) / (f.bmax - f.bmin).astype(F32)).astype(F32)
    inside = np.all((u >= 0) & (u <= 1), axis=1)
    rows = np.zeros((n, f.O), F32)
    if not inside.any():
        return rows
    ui = u[inside]
    gate = grid_read(ui, f.R3, f.T3, 1, f.segs[-1])[:, 0]
    gate = np.array([F32(1.0 / (1.0 + exp64(-float(v)))) for v in gate], F32)
    planes = [(0, 1), (0, 2), (1, 2)]
    feats = []
    for pi, (a, b) in enumerate(planes):
        for l in range(f.Lv):
            val = grid_read(ui[:, [a, b]], f.R[l], f.T2, f.F, f.segs[pi * f.Lv + l])
            feats.append((val * gate[:, None]).astype(F32))
    inp = np.concatenate(feats, axis=1).astype(F32)
    hid = relu(layer_fma(f.W1, inp, f.b1))
    out = layer_fma(f.W2, hid, f.b2)
    rows[inside] = out
    return rows


def apply_rntc(p, base, h, ref):
    f = parse_rntc(p, base, h)
    out = ref.copy()
    for si in (0, 1):
        if not (f.sets >> si) & 1:
            continue
        gs = out.sets[si]
        if gs.n == 0:
            continue
        rows = eval_field(f, ref.sets[si].pos)
        col = 0
        for gid in f.sel:
            w = f.widths[gid]
            arr, setter = group_view(gs, gid)
            setter((np.array(arr, F32) + rows[:, col:col + w]).astype(F32))
            col += w
    return out
