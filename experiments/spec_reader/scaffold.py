"""Scaffold-GS variant (§6.9-§6.13)."""
import os

import numpy as np

from common import DlgsError, Reader, exp64, fromhex32, layer_fma, relu, tanh32, zstd_exact
from container import NOREF
from dynamic import locate, parse_tfea

F32 = np.float32
EPS12 = fromhex32(0x2B8CBCCC)


class Anchors:
    def __init__(self, n):
        self.n = n
        self.pos = np.zeros((n, 3), F32)
        self.feat = np.zeros((n, 50), F32)
        self.off = np.zeros((n, 30), F32)
        self.ls = np.zeros((n, 6), F32)

    def copy(self):
        a = Anchors(self.n)
        a.pos, a.feat, a.off, a.ls = self.pos.copy(), self.feat.copy(), self.off.copy(), self.ls.copy()
        return a

    def sub(self, lo, hi):
        a = Anchors(hi - lo)
        a.pos, a.feat, a.off, a.ls = self.pos[lo:hi], self.feat[lo:hi], self.off[lo:hi], self.ls[lo:hi]
        return a


def check_head(h):
    def bad(msg):
        raise DlgsError("Payload", 0, "variant-1 HEAD: " + msg)
    if h.sh_degree != 0:
        bad("sh_degree")
    if h.residual_mode not in (0, 1):
        bad("residual_mode")
    if h.deform_model != 1:
        bad("deform_model")
    if h.time_channels != (16 if h.n_dynamic > 0 else 0):
        bad("time_channels")
    if not ((h.lang_levels, h.lang_dims) in ((3, 3), (0, 0))):
        bad("language")


def parse_ancr(p, base, h):
    r = Reader(p, base, "ANCR")
    codec = r.u8()
    r.take(3)
    ns, nd, blen = r.u32(), r.u32(), r.u64()
    if codec > 1:
        raise DlgsError("Payload", base, "ANCR codec")
    if ns != h.n_static:
        raise DlgsError("Payload", base + 4, "ANCR n_static")
    if nd != h.n_dynamic:
        raise DlgsError("Payload", base + 8, "ANCR n_dynamic")
    N = ns + nd
    if blen != N * 89 * 4:
        raise DlgsError("Payload", base + 12, "ANCR body_len")
    rest = r.d[20:]
    if codec == 0:
        if len(rest) != blen:
            raise DlgsError("Payload", base + 20, "ANCR body size")
        body = rest
    else:
        body = zstd_exact(rest, blen, base + 20, "ANCR")
    v = np.frombuffer(body, "<f4").astype(F32)
    if not np.all(np.isfinite(v)):
        raise DlgsError("Payload", base + 20, "ANCR non-finite")
    a = Anchors(N)
    o = 0
    for lo, n in ((0, ns), (ns, nd)):
        for name, w in (("pos", 3), ("feat", 50), ("off", 30), ("ls", 6)):
            getattr(a, name)[lo:lo + n] = v[o:o + w * n].reshape(n, w)
            o += w * n
    return a


def read_mlp(vals, o, inp, h, out, bias=True):
    W1 = vals[o:o + h * inp].reshape(h, inp); o += h * inp
    b1 = None
    if bias:
        b1 = vals[o:o + h]; o += h
    W2 = vals[o:o + out * h].reshape(out, h); o += out * h
    b2 = None
    if bias:
        b2 = vals[o:o + out]; o += out
    return (W1, b1, W2, b2), o


def parse_amlp(p, base, h, has_ref, ref_mlps):
    r = Reader(p, base, "AMLP")
    flags = r.u8()
    r.take(3)
    lang = h.lang_levels > 0
    if flags & 0xFC:
        raise DlgsError("Payload", base, "AMLP flags bits 2-7")
    if flags & 2:
        if not has_ref:
            raise DlgsError("Payload", base, "AMLP language-only in an intra GOP")
        if flags != 3 or not lang:
            raise DlgsError("Payload", base, "AMLP language-only flags")
        hh = r.u16()
        if not 1 <= hh <= 1024:
            raise DlgsError("Payload", base + 4, "AMLP hidden")
        size = 4 * (54 * hh + hh + 90 * hh + 90)
        vals = np.frombuffer(zstd_exact(r.d[r.p:], size, r.off(), "AMLP"), "<f4").astype(F32)
        if not np.all(np.isfinite(vals)):
            raise DlgsError("Payload", base, "AMLP non-finite")
        m, _ = read_mlp(vals, 0, 54, hh, 90)
        out = dict(ref_mlps)
        out["lang"] = m
        return out
    if bool(flags & 1) != lang:
        raise DlgsError("Payload", base, "AMLP language flag")
    outs = [("op", 20 if lang else 10), ("col", 30), ("cov", 70)] + ([("lang", 90)] if lang else [])
    hs = []
    for _ in outs:
        v = r.u16()
        if not 1 <= v <= 1024:
            raise DlgsError("Payload", r.off() - 2, "AMLP hidden")
        hs.append(v)
    size = 4 * sum(54 * hh + hh + o * hh + o for hh, (_, o) in zip(hs, outs))
    vals = np.frombuffer(zstd_exact(r.d[r.p:], size, r.off(), "AMLP"), "<f4").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("Payload", base, "AMLP non-finite")
    res = {}
    o = 0
    for hh, (name, out) in zip(hs, outs):
        res[name], o = read_mlp(vals, o, 54, hh, out)
    return res


def parse_adef(p, base, h):
    r = Reader(p, base, "ADEF")
    bmin = np.array([r.f32() for _ in range(3)], F32)
    bmax = np.array([r.f32() for _ in range(3)], F32)
    if not (np.all(np.isfinite(bmin)) and np.all(np.isfinite(bmax))):
        raise DlgsError("Payload", base, "ADEF box non-finite")
    if not np.all(bmax > bmin):
        raise DlgsError("Payload", base + 12, "ADEF bmax <= bmin")
    hs = [r.u16() for _ in range(4)]
    if any(not 1 <= v <= 1024 for v in hs):
        raise DlgsError("Payload", base + 24, "ADEF hidden")
    dims = [(19, 3), (16, 50), (16, 30), (16, 6)]
    size = 4 * sum(i * hh + hh * o for hh, (i, o) in zip(hs, dims))
    vals = np.frombuffer(zstd_exact(r.d[32:], size, base + 32, "ADEF"), "<f4").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("Payload", base, "ADEF non-finite")  # GUESS kind (AMLP says Payload)
    ms = []
    o = 0
    for hh, (i, out) in zip(hs, dims):
        m, o = read_mlp(vals, o, i, hh, out, bias=False)
        ms.append(m)
    return {"bmin": bmin, "bmax": bmax, "xyz": ms[0], "feat": ms[1], "off": ms[2], "ls": ms[3]}


def mlp2(m, x, act=None):
    W1, b1, W2, b2 = m
    hdn = relu(layer_fma(W1, x, b1))
    out = layer_fma(W2, hdn, b2)
    if act == "tanh":
        out = tanh32(out)
    elif act == "sig":
        out = logistic(out)
    return out


def logistic(v):
    v = np.asarray(v, F32)
    flat = np.array([F32(1.0 / (1.0 + exp64(-float(x)))) for x in v.ravel()], F32)
    return flat.reshape(v.shape)


def exp32(v):
    v = np.asarray(v, F32)
    return np.array([F32(exp64(float(x))) for x in v.ravel()], F32).reshape(v.shape)


class ScaffoldDecoder:
    def __init__(self, c):
        self.c = c
        self.h = c.head
        if self.h.variant != 1:
            raise DlgsError("Request", 0, "not a variant-1 file")
        check_head(self.h)
        self.cache = {}

    def gop(self, g):
        if g in self.cache:
            return self.cache[g]
        c, h = self.c, self.h
        (ff, fc, ref), chunks = c.gop(g)
        has_ref = ref != NOREF
        if not has_ref:
            if b"AHAC" in chunks:
                from ahac import parse_ahac
                ch = chunks[b"AHAC"]
                anchors = parse_ahac(c.payload(ch), ch.poff, h)
            else:
                ch = chunks[b"ANCR"]
                anchors = parse_ancr(c.payload(ch), ch.poff, h)
            ch = chunks[b"AMLP"]
            mlps = parse_amlp(c.payload(ch), ch.poff, h, False, None)
            pos0 = anchors.pos
        else:
            from residual import eval_field, parse_rntc
            rg = self.gop(ref)
            ch = chunks[b"RES"]
            f = parse_rntc(c.payload(ch), ch.poff, h, anchor=True)
            base = rg["anchors"]
            anchors = base.copy()
            ns = h.n_static
            for si, (lo, hi) in enumerate(((0, ns), (ns, base.n))):
                if not (f.sets >> si) & 1 or hi == lo:
                    continue
                rows = eval_field(f, rg["pos0"][lo:hi])
                col = 0
                for gid in f.sel:
                    name = ("feat", "off", "ls")[gid]
                    w = f.widths[gid]
                    arr = getattr(anchors, name)
                    arr[lo:hi] = (arr[lo:hi] + rows[:, col:col + w]).astype(F32)
                    col += w
            if b"AMLP" in chunks:
                ch = chunks[b"AMLP"]
                mlps = parse_amlp(c.payload(ch), ch.poff, h, True, rg["mlps"])
            else:
                mlps = rg["mlps"]
            pos0 = rg["pos0"]
        adef = tfea = None
        if h.n_dynamic > 0:
            ch = chunks[b"ADEF"]
            adef = parse_adef(c.payload(ch), ch.poff, h)
            ch = chunks[b"TFEA"]
            tfea, _ = parse_tfea(c.payload(ch), ch.poff, h)
        res = {"anchors": anchors, "mlps": mlps, "adef": adef, "tfea": tfea, "pos0": pos0}
        self.cache[g] = res
        return res

    def check_all(self):
        for g in range(self.h.gop_count):
            self.gop(g)

    def frame(self, t, eye):
        h = self.h
        g, k, dl, _ = locate(t, h)
        G = self.gop(g)
        A = G["anchors"]
        ns = h.n_static
        a = A.pos.copy()
        feat = A.feat.copy()
        off = A.off.copy()
        ls = A.ls.copy()
        if h.n_dynamic > 0:
            F = G["tfea"]
            D = G["adef"]
            omd = F32(F32(1) - dl)
            Fl = ((F[:, k, :] * omd).astype(F32) + (F[:, k + 1, :] * dl).astype(F32)).astype(F32)
            cpos = A.pos[ns:]
            u = ((cpos - D["bmin"]).astype(F32) / (D["bmax"] - D["bmin"]).astype(F32)).astype(F32)
            xin = np.concatenate([Fl, u], axis=1).astype(F32)
            a[ns:] = (cpos + mlp2(D["xyz"], xin)).astype(F32)
            feat[ns:] = (feat[ns:] + mlp2(D["feat"], Fl)).astype(F32)
            off[ns:] = (off[ns:] + mlp2(D["off"], Fl)).astype(F32)
            ls[ns:] = (ls[ns:] + mlp2(D["ls"], Fl)).astype(F32)
        e = np.asarray(eye, F32)
        v = (A.pos - e).astype(F32)
        dist = (v[:, 0] * v[:, 0]).astype(F32)
        dist = (dist + (v[:, 1] * v[:, 1]).astype(F32)).astype(F32)
        dist = (dist + (v[:, 2] * v[:, 2]).astype(F32)).astype(F32)
        dist = np.sqrt(dist).astype(F32)
        with np.errstate(divide="ignore", invalid="ignore"):
            dirv = np.where(dist[:, None] > 0, (v / dist[:, None]).astype(F32), F32(0)).astype(F32)
        x = np.concatenate([feat, dirv, dist[:, None]], axis=1).astype(F32)
        M = G["mlps"]
        lang = h.lang_levels > 0
        alpha = mlp2(M["op"], x, "tanh")
        col = mlp2(M["col"], x, "sig")
        cov = mlp2(M["cov"], x)
        lng = mlp2(M["lang"], x) if lang else None
        E = exp32(ls)
        out = []
        for i in range(A.n):
            for kk in range(10):
                ac = alpha[i, 2 * kk] if lang else alpha[i, kk]
                if not ac > 0:
                    continue
                pos = (a[i] + (off[i, 3 * kk:3 * kk + 3] * E[i, 0:3]).astype(F32)).astype(F32)
                sc = (E[i, 3:6] * logistic(cov[i, 7 * kk:7 * kk + 3])).astype(F32)
                q = cov[i, 7 * kk + 3:7 * kk + 7]
                n2 = F32(q[0] * q[0])
                for j in (1, 2, 3):
                    n2 = F32(n2 + F32(q[j] * q[j]))
                nq = max(F32(np.sqrt(n2)), EPS12)
                rot = (q / nq).astype(F32)
                rec = [pos, sc, rot, col[i, 3 * kk:3 * kk + 3], [ac]]
                if lang:
                    rec += [[alpha[i, 2 * kk + 1]], lng[i, 9 * kk:9 * kk + 9]]
                out.append(np.concatenate([np.asarray(r_, F32).ravel() for r_ in rec]))
        return out


def compare_frames(d, path):
    name = os.path.basename(path)
    if "residual" in name:
        times = [2.0, 2.85, 3.95]
    elif "refresh" in name:
        times = [4.35, 6.0, 7.95]
    else:
        times = [0.0, 0.85, 1.95]
    ref = np.fromfile(path, "<f4")
    got = []
    counts = []
    for t in times:
        ch = d.frame(t, [0.4, -0.3, -2.5])
        counts.append(len(ch))
        got.append(np.array([len(ch)], F32))
        got += ch
    got = np.concatenate(got).astype(F32)
    if got.shape != ref.shape:
        return f"frames: size {got.shape} vs {ref.shape} (counts {counts})"
    same = int(np.sum(got.view(np.uint32) == ref.view(np.uint32)))
    return f"frames (children {counts}): {same}/{len(ref)} bit-identical, max |diff| {float(np.max(np.abs(got.astype(np.float64) - ref))):.3g}"
