"""§6.8 LAED language autoencoder decoder."""
import numpy as np

from common import DlgsError, Reader, layer_fma, relu, zstd_exact

F32 = np.float32


def parse_laed(p, base, h):
    r = Reader(p, base, "LAED")
    vt = r.u8()
    layers = r.u8()
    neg = r.u8()
    r.u8()
    if h.lang_levels == 0:
        raise DlgsError("Payload", base, "LAED in a scene without language")
    if vt > 1 or not 1 <= layers <= 8 or neg > 64:
        raise DlgsError("Payload", base, "LAED header")  # GUESS kind for bad value_type/layers/negatives
    ws = [r.u16() for _ in range(layers + 1)]
    if any(not 1 <= w <= 4096 for w in ws):
        raise DlgsError("Payload", base + 4, "LAED width")
    if ws[0] != h.lang_dims:
        raise DlgsError("Payload", base + 4, "LAED w_0 != lang_dims")
    names = []
    for _ in range(neg):
        ln = r.u8()
        names.append(r.take(ln).decode("utf-8"))
    total = sum(ws[j] * ws[j + 1] + ws[j + 1] for j in range(layers)) + neg * ws[-1]
    vb = r.u32()
    if vb != total * (4 if vt == 0 else 2):
        raise DlgsError("Payload", r.off() - 4, "LAED value_bytes")
    vals = np.frombuffer(zstd_exact(r.d[r.p:], vb, r.off(), "LAED"), "<f4" if vt == 0 else "<f2").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("NonFinite", base, "LAED values")
    o = 0
    lay = []
    for j in range(layers):
        W = vals[o:o + ws[j] * ws[j + 1]].reshape(ws[j + 1], ws[j]); o += ws[j] * ws[j + 1]
        b = vals[o:o + ws[j + 1]]; o += ws[j + 1]
        lay.append((W, b))
    negs = vals[o:].reshape(neg, ws[-1])
    return {"layers": lay, "negatives": negs, "names": names}


def decode_embed(laed, x):
    v = np.asarray(x, F32)
    for j, (W, b) in enumerate(laed["layers"]):
        v = layer_fma(W, v, b)
        if j < len(laed["layers"]) - 1:
            v = relu(v)
    n2 = (v[..., 0] * v[..., 0]).astype(F32)
    for i in range(1, v.shape[-1]):
        n2 = (n2 + (v[..., i] * v[..., i]).astype(F32)).astype(F32)
    nrm = np.sqrt(n2).astype(F32)
    with np.errstate(divide="ignore"):
        inv = np.where(nrm > 0, (F32(1) / nrm).astype(F32), F32(0)).astype(F32)
    return (v * inv[..., None]).astype(F32)


def compare_embeddings(d, laed, path):
    h = d.h
    ref = np.fromfile(path, "<f4")
    st = d.state(0)
    outs = []
    for gs in st.sets:
        for i in range(gs.n):
            for l in range(h.lang_levels):
                outs.append(decode_embed(laed, gs.lang[i:i + 1, l * h.lang_dims:(l + 1) * h.lang_dims])[0])
    outs.append(laed["negatives"].ravel())
    got = np.concatenate([np.ravel(o) for o in outs]).astype(F32)
    if got.shape != ref.shape:
        return f"embeddings: size {got.shape} vs {ref.shape}"
    same = int(np.sum(got.view(np.uint32) == ref.view(np.uint32)))
    return f"embeddings: {same}/{len(ref)} bit-identical, max |diff| {float(np.max(np.abs(got.astype(np.float64) - ref))):.3g}"
