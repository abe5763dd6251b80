"""§6.5.3 grid codecs 0-5 (cells of one channel record)."""
import struct

import numpy as np

from common import COVER, DlgsError, Reader, zstd_exact
from rangecoder import BinModel, RangeDecoder


def bitlen(v):
    return v.bit_length()


def zigzag(r):
    return 2 * r if r >= 0 else -2 * r - 1


def unzigzag(z):
    return z >> 1 if z % 2 == 0 else -((z + 1) >> 1)


def signed(v, bits):
    v &= (1 << bits) - 1
    return v - (1 << bits) if v >= 1 << (bits - 1) else v


def neighbours(cells, i, W):
    col = i % W
    row = i // W
    a = cells[i - 1] if col > 0 else 0
    b = cells[i - W] if row > 0 else 0
    c = cells[i - W - 1] if (row > 0 and col > 0) else 0
    return a, b, c, col > 0, row > 0


def predict(a, b, c, has_a, has_b, i):
    if i == 0:
        return 0
    if not has_b:  # first row
        return a
    if not has_a:  # first column
        return b
    if c >= max(a, b):
        return min(a, b)
    if c <= min(a, b):
        return max(a, b)
    return a + b - c


def residuals_of(cells, bits, W):
    """codec 2's residual (signed) of every cell of a decoded channel."""
    out = []
    for i in range(len(cells)):
        a, b, c, ha, hb = neighbours(cells, i, W)
        p = predict(a, b, c, ha, hb, i)
        out.append(signed(cells[i] - p, bits))
    return out


# ---------------------------------------------------------------- squash / stretch (codec 5 modes 5/6)
_KN = [1, 2, 4, 6, 10, 17, 27, 45, 74, 120, 194, 311, 488, 747, 1102, 1546, 2048, 2550, 2994, 3349,
       3608, 3785, 3902, 3976, 4022, 4051, 4069, 4079, 4086, 4090, 4092, 4094, 4095]


def squash(d):
    if d > 2047:
        d = 2047
    if d < -2047:
        d = -2047
    if d == 2047:
        return 4095
    if d == -2047:
        return 1
    w = d & 127
    j = (d >> 7) + 16
    return (_KN[j] * (128 - w) + _KN[j + 1] * w + 64) >> 7


_SQ = [squash(d) for d in range(-2047, 2048)]
_STRETCH = []
for _p in range(4096):
    _r = 2047
    for _i, _s in enumerate(_SQ):
        if _s >= _p:
            _r = _i - 2047
            break
    _STRETCH.append(_r)


def decode_cells(bits, codec, data, n, W, prev, prev2, off, what="CSOG", compact=False):
    """prev/prev2: (cells list, bits) or None. Returns list of ints."""
    mask = (1 << bits) - 1
    COVER[f"{what} codec {codec}"] += 1
    if codec == 0:
        if len(data) != 0:
            raise DlgsError("Payload", off, f"{what}: codec 0 with data")  # GUESS kind
        return [0] * n
    if codec == 1:
        size = n if bits <= 8 else 2 * n
        raw = zstd_exact(data, size, off, what)
        if bits <= 8:
            cells = list(raw)
        else:
            cells = list(struct.unpack("<%dH" % n, raw))
        return cells
    r = Reader(data, off, what)
    if codec == 2:
        t0 = r.u8()
        models = []
        for ctx in range(3):
            m = r.u8()
            if m > bits + 1:
                raise DlgsError("Payload", r.off(), f"{what}: codec 2 m > bits + 1")
            probs = [r.u16() for _ in range(m)]
            if m:
                if min(probs) == 0 or sum(probs) != 4096:
                    raise DlgsError("Payload", r.off(), f"{what}: codec 2 probabilities")
                cum = [0]
                for p in probs:
                    cum.append(cum[-1] + p)
                models.append(cum)
            else:
                models.append(None)
        words = r.u32()
        wb = r.take(4 * words)
        mant = r.d[r.p:]
        rd = RangeDecoder(wb, off, what)
        bitpos = 0
        cells = []
        for i in range(n):
            a, b, c, ha, hb = neighbours(cells, i, W)
            A = abs(a - c) + abs(b - c) + abs(a - b)
            K = bitlen(A)
            ctx = 0 if K <= t0 else (1 if K <= t0 + 2 else 2)
            cum = models[ctx]
            if cum is None:
                raise DlgsError("Payload", off, f"{what}: cell in a context without model")
            k = rd.categorical(cum, 12)
            if k == 0:
                z = 0
            elif k == 1:
                z = 1
            else:
                nb = k - 1
                if bitpos + nb > 8 * len(mant):
                    raise DlgsError("Truncated", off, f"{what}: mantissa bits")
                m_ = 0
                for j in range(nb):
                    bp = bitpos + j
                    m_ |= ((mant[bp >> 3] >> (bp & 7)) & 1) << j
                bitpos += nb
                z = (1 << (k - 1)) + m_
            p = predict(a, b, c, ha, hb, i)
            q = (p + unzigzag(z)) & mask
            cells.append(q)
        return cells
    if codec in (3, 4):
        if codec == 4 and (prev is None or prev[1] != bits):
            raise DlgsError("Payload", off, f"{what}: codec 4 without a previous channel of the same bits")
        S = r.u16()
        if not (2 <= S <= min(4096, 1 << bits)):
            raise DlgsError("Payload", off, f"{what}: codec 3 alphabet {S}")
        tlen = r.u32()
        tb = r.take(tlen)
        tab = zstd_exact(tb, 2 * S, off, what + " table")
        probs = struct.unpack("<%dH" % S, tab)
        if min(probs) == 0 or sum(probs) != 65536:
            raise DlgsError("Payload", off, f"{what}: codec 3 probabilities")
        cum = [0]
        for p in probs:
            cum.append(cum[-1] + p)
        words = r.u32()
        wb = r.take(4 * words)
        if r.left():
            raise DlgsError("Payload", off, f"{what}: bytes after words")
        rd = RangeDecoder(wb, off, what)
        cells = [rd.categorical(cum, 16) for _ in range(n)]
        if codec == 4:
            pq = prev[0]
            cells = [(d + pq[i]) & mask for i, d in enumerate(cells)]
        return cells
    if codec == 5:
        mode = r.u8()
        kf = r.u8()
        if compact:
            wb = r.d[r.p:]
            if len(wb) % 4:
                raise DlgsError("Payload", off, f"{what}: codec 5 words not a multiple of 4")
        else:
            words = r.u32()
            wb = r.take(4 * words)
            if r.left():
                raise DlgsError("Payload", off, f"{what}: bytes after words")
        k2 = 0
        k = kf
        ok = False
        if mode in (0, 1, 2, 4) and kf == 0:
            ok = True
        elif mode == 3 and 1 <= kf <= 8:
            ok = True
        elif mode == 5 and 0 <= kf <= 8:
            ok = True
        elif mode == 6:
            k = kf & 15
            k2 = kf >> 4
            ok = 1 <= k <= 8 and 1 <= k2 <= 4
        if not ok:
            raise DlgsError("Payload", off, f"{what}: codec 5 (mode, k) = ({mode}, {kf})")
        needs_prev = mode in (1, 2, 3, 6) or (mode == 5 and k > 0)
        if needs_prev and prev is None:
            raise DlgsError("Payload", off, f"{what}: codec 5 mode {mode} without previous channel")
        if mode == 6 and prev2 is None:
            raise DlgsError("Payload", off, f"{what}: codec 5 mode 6 without the channel before")
        if mode == 2 and prev[1] != bits:
            raise DlgsError("Payload", off, f"{what}: codec 5 mode 2 with other bits")
        if mode >= 3 and bits > 10:
            raise DlgsError("Payload", off, f"{what}: codec 5 mode {mode} with bits > 10")
        COVER[f"{what} codec 5 mode {mode}" + (" k>0" if k else "")] += 1
        rd = RangeDecoder(wb, off, what)
        if mode <= 2:
            return _c5_resid(rd, mode, bits, n, W, prev)
        if mode in (3, 4):
            return _c5_tree(rd, mode, k, bits, n, prev)
        return _c5_mix(rd, mode, k, k2, bits, n, W, prev, prev2)
    raise DlgsError("Payload", off, f"{what}: codec {codec}")


def _c5_resid(rd, mode, bits, n, W, prev):
    mask = (1 << bits) - 1
    U = {}
    T = {}
    rps = None
    if mode in (1, 2):
        pq, pb = prev
        rps = residuals_of(pq, pb, W)
    cells = []
    for i in range(n):
        a, b, c, ha, hb = neighbours(cells, i, W)
        p = predict(a, b, c, ha, hb, i)
        A = abs(a - c) + abs(b - c) + abs(a - b) if (ha and hb) else 0
        act = min(bitlen(A), 12) // 2
        if mode == 0:
            pc = 0
        else:
            rp = rps[i]
            pc = min(bitlen(zigzag(rp)), 7)
        x = 8 * act + pc
        K = 0
        for j in range(bits):
            key = (x, j)
            m = U.get(key)
            if m is None:
                m = U[key] = BinModel()
            bit = rd.binary(m.p)
            m.update(bit)
            if not bit:
                break
            K += 1
        if K == 0:
            z = 0
        elif K == 1:
            z = 1
        else:
            key = (x, K)
            m = T.get(key)
            if m is None:
                m = T[key] = BinModel()
            bit = rd.binary(m.p)
            m.update(bit)
            z = (1 << (K - 1)) | (bit << (K - 2))
            for j in range(K - 3, -1, -1):
                z |= rd.binary(32768) << j
        r = unzigzag(z)
        if mode == 2:
            r = r + rps[i]
        cells.append((p + r) & mask)
    return cells


def _c5_tree(rd, mode, k, bits, n, prev):
    M = {}
    cells = []
    for i in range(n):
        if mode == 3:
            pq, pb = prev
            x = pq[i] >> max(pb - k, 0)
        else:
            x = 0
        node = 1
        for _ in range(bits):
            key = (x, node)
            m = M.get(key)
            if m is None:
                m = M[key] = BinModel()
            bit = rd.binary(m.p)
            m.update(bit)
            node = 2 * node + bit
        cells.append(node - (1 << bits))
    return cells


def _c5_mix(rd, mode, k, k2, bits, n, W, prev, prev2):
    m = 2 if (mode == 5 and k == 0) else (3 if mode == 5 else 4)
    O = {}
    N = {}
    P = {}
    B = {}
    wts = [[65536 // m] * m + [0] for _ in range(bits)]
    cells = []
    ST = _STRETCH
    for i in range(n):
        col = i % W
        row = i // W
        sa = 1 + (cells[i - 1] >> max(bits - 2, 0)) if col > 0 else 0
        sb = 1 + (cells[i - W] >> max(bits - 2, 0)) if row > 0 else 0
        y = 5 * sa + sb
        if m >= 3:
            pq, pb = prev
            x = pq[i] >> max(pb - k, 0)
        if m == 4:
            pq2, pb2 = prev2
            x2 = pq2[i] >> max(pb2 - k2, 0)
            bx = x2 * (1 << min(k, pb)) + x
        node = 1
        for lvl in range(bits):
            mods = []
            for fam, key in ((O, node), (N, (y, node))):
                md = fam.get(key)
                if md is None:
                    md = fam[key] = BinModel()
                mods.append(md)
            if m >= 3:
                key = (x, node)
                md = P.get(key)
                if md is None:
                    md = P[key] = BinModel()
                mods.append(md)
            if m == 4:
                key = (bx, node)
                md = B.get(key)
                if md is None:
                    md = B[key] = BinModel()
                mods.append(md)
            s = [ST[md.p >> 4] for md in mods] + [256]
            w = wts[lvl]
            dot = sum(w[j] * s[j] for j in range(m + 1)) >> 16
            if dot > 2047:
                dot = 2047
            elif dot < -2047:
                dot = -2047
            p12 = squash(dot)
            p0 = min(max(p12 << 4, 32), 65504)
            bit = rd.binary(p0)
            e = -p12 if bit else 4095 - p12
            for j in range(m + 1):
                v = w[j] + ((s[j] * e) >> 10)
                w[j] = min(max(v, -(1 << 22)), 1 << 22)
            for md in mods:
                md.update(bit)
            node = 2 * node + bit
        cells.append(node - (1 << bits))
    return cells
