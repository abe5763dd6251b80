"""§6.2 TFEA, §6.3 MLPW, §6.4 dynamic frames, §6.14 LIFE."""
import math
import struct
import subprocess

import numpy as np

from common import (DlgsError, Reader, acos32, fma32, fromhex32, layer_fma, relu, round_away, sin32,
                    tanh32, zstd_exact)

F32 = np.float32


# ---------------------------------------------------------------- HEVC via ffmpeg
def hevc_decode(stream, W, H, off):
    try:
        pr = subprocess.run(
            ["ffmpeg", "-v", "error", "-threads", "1", "-f", "hevc", "-i", "pipe:0",
             "-f", "rawvideo", "-pix_fmt", "gray12le", "-fps_mode", "passthrough", "pipe:1"],
            input=bytes(stream), capture_output=True, check=False)
    except FileNotFoundError:
        raise NotImplementedError("no ffmpeg")
    if pr.returncode != 0:
        raise DlgsError("Payload", off, "HEVC decode failed: " + pr.stderr.decode(errors="replace")[:200])
    raw = np.frombuffer(pr.stdout, "<u2")
    if len(raw) % (W * H):
        raise DlgsError("Payload", off, "HEVC picture size")
    return raw.reshape(-1, H, W)


def parse_tfea(p, base, h):
    r = Reader(p, base, "TFEA")
    codec = r.u8()
    bd = r.u8()
    ch = r.u16()
    n = r.u32()
    keys = r.u32()
    side = r.u32()
    N, K, C = h.n_dynamic, h.K, h.time_channels
    # §6.2 check order (stated since 1.18): channels/n/keys as one check, then the
    # (codec, bit_depth) pair, both `Payload` at offset 0.
    if ch != C or n != N or keys != K:
        raise DlgsError("Payload", base, f"TFEA channels/n/keys {ch}/{n}/{keys} != {C}/{N}/{K}")
    pair_ok = ((codec == 0 and bd == 0) or (codec in (1, 2, 3) and bd == 12)
               or (codec == 4 and 6 <= bd <= 12))
    if not pair_ok:
        raise DlgsError("Payload", base, f"TFEA (codec, bit_depth) = ({codec}, {bd})")
    if codec == 0:
        raw = zstd_exact(r.d[r.p:], N * K * C * 4, r.off(), "TFEA")
        return np.frombuffer(raw, "<f4").astype(F32).reshape(N, K, C), "exact"
    if codec == 4:
        # side: reserved for codec 4, readers ignore it.
        return parse_tfea_quantised(r, base, bd, N, K, C), f"quantised codec 4 ({bd} bit)"
    if not (side * side >= N and 4 * side <= 16384 and ((C + 3) // 4) * side <= 16384):
        raise DlgsError("InvalidField", base + 12, "TFEA side")
    if codec in (1, 3):
        rng = [(r.f32(), r.f32()) for _ in range(C)]
        if not all(np.isfinite(a) and np.isfinite(b) for a, b in rng):
            raise DlgsError("NonFinite", base + 16, "TFEA ranges")
    else:
        lo, hi = r.f64(), r.f64()
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise DlgsError("NonFinite", base + 16, "TFEA range")
    pc = r.u32()
    if 4 * pc > r.left():
        raise DlgsError("Truncated", r.off(), "TFEA packet_count")
    pkts = []
    for _ in range(pc):
        ln = r.u32()
        pkts.append(r.take(ln))
    if r.left():
        raise DlgsError("Payload", r.off(), "TFEA bytes after last packet")
    if codec == 3 and pc != K:
        raise DlgsError("Payload", base, "TFEA codec 3 packet_count != K")
    W, H = 4 * side, ((C + 3) // 4) * side
    if codec == 3:
        pics = np.concatenate([hevc_decode(pk, W, H, base) for pk in pkts])
    else:
        pics = hevc_decode(b"".join(pkts), W, H, base)
    if pics.shape[0] != K:
        raise DlgsError("Payload", base, f"HEVC gave {pics.shape[0]} pictures, want {K}")
    i = np.arange(N)
    out = np.zeros((N, K, C), F32)
    for c in range(C):
        y = (c // 4) * side + i // side
        x = (c % 4) * side + i % side
        q = pics[:, y, x].T.astype(np.int64)  # (N, K)
        if codec in (1, 3):
            lo, hi = rng[c]
            if hi > lo:
                step = F32(F32(hi - lo) / F32(4095))
                out[:, :, c] = (lo + (q.astype(F32) * step).astype(F32)).astype(F32)
            else:
                out[:, :, c] = lo
        else:
            v16 = (q << 4) | (q >> 8)
            out[:, :, c] = ((v16.astype(np.float64) / 65535.0) * (hi - lo) + lo).astype(F32)
    return out, f"hevc codec {codec}"


def parse_tfea_quantised(r, base, b, N, K, C):
    """§6.2 codec 4 (since 1.19): per-channel b-bit samples, two byte planes in one zstd frame."""
    po = r.off()
    pred = r.u8()
    if pred > 1:
        raise DlgsError("InvalidField", po, f"TFEA predictor {pred}")
    # §6.2 (1.19): NonFinite at the first value that is not finite; hi - lo (binary32) must be
    # finite too (NonFinite at that pair's lo); cut short: Truncated.
    rng = []
    for _ in range(C):
        lo_at = r.off()
        lo = r.f32()
        if not np.isfinite(lo):
            raise DlgsError("NonFinite", lo_at, "TFEA range lo")
        hi_at = r.off()
        hi = r.f32()
        if not np.isfinite(hi):
            raise DlgsError("NonFinite", hi_at, "TFEA range hi")
        with np.errstate(over="ignore"):
            if not np.isfinite(F32(F32(hi) - F32(lo))):
                raise DlgsError("NonFinite", lo_at, "TFEA range hi - lo")
        rng.append((lo, hi))
    fo = r.off()
    M = N * K * C
    raw = np.frombuffer(zstd_exact(r.d[r.p:], 2 * M, fo, "TFEA"), np.uint8)
    z = raw[:M].astype(np.int64) + 256 * raw[M:].astype(np.int64)  # j = (k C + c) N + i
    lim = 1 << b
    bad = np.flatnonzero(z >= lim)
    if bad.size:
        raise DlgsError("InvalidField", fo, f"TFEA sample z[{bad[0]}] = {z[bad[0]]} >= 2^{b}")
    z = z.reshape(K, C, N)
    if pred == 1:
        d = np.where(z & 1, -((z + 1) >> 1), z >> 1)  # zigzag
        d[0] = z[0]  # key 0 is stored as is
        q = np.cumsum(d, axis=0) % lim
    else:
        q = z
    out = np.empty((K, C, N), F32)
    for c in range(C):
        lo, hi = F32(rng[c][0]), F32(rng[c][1])
        if hi > lo:
            # §6.2: the difference, the quotient, the product and the sum, each binary32.
            step = F32(F32(hi - lo) / F32(lim - 1))
            out[:, c, :] = (lo + (q[:, c, :].astype(F32) * step).astype(F32)).astype(F32)
        else:
            out[:, c, :] = lo
    return np.ascontiguousarray(out.transpose(2, 0, 1))  # (N, K, C) like codec 0


# ---------------------------------------------------------------- MLPW
def parse_mlpw(p, base, h):
    if h.time_channels != 16:
        raise DlgsError("Payload", base, "MLPW needs time_channels 16")
    r = Reader(p, base, "MLPW")
    wt = r.u8()
    flags = r.u8()
    count = r.u8()
    r.u8()
    if wt > 1:
        raise DlgsError("Payload", base, "MLPW weight_type")
    if not 1 <= count <= 5:
        raise DlgsError("Payload", base + 2, "MLPW count")
    descs = []
    for _ in range(count):
        o = r.off()
        role = r.u8()
        layers = r.u8()
        if not 1 <= layers <= 8:
            raise DlgsError("Payload", o, "MLPW layers")
        ws = [r.u16() for _ in range(layers + 1)]
        if any(not 1 <= w <= 4096 for w in ws):
            raise DlgsError("Payload", o, "MLPW width")
        descs.append((role, ws, o))
    roles = [d[0] for d in descs]
    if len(set(roles)) != len(roles) or any(x > 4 for x in roles):
        raise DlgsError("Payload", base + 4, "MLPW roles")
    need = {0, 1, 2, 3} | ({4} if h.L else set())
    if set(roles) != need:
        raise DlgsError("Payload", base + 4, "MLPW required roles")
    m_max = (h.sh_degree + 1) ** 2
    for role, ws, o in descs:
        ok = {0: ws[0] == 12 and ws[-1] == 6, 1: ws[0] == 12 and ws[-1] == 7,
              2: ws[0] == 12 and ws[-1] in (1, 2),
              3: ws[0] == 12 and ws[-1] % 3 == 0 and 1 <= ws[-1] // 3 <= m_max,
              4: ws[0] == 8 and ws[-1] == h.L}[role]
        if not ok:
            raise DlgsError("Payload", o, "MLPW role widths")
    total = sum(ws[j] * ws[j + 1] for _, ws, _ in descs for j in range(len(ws) - 1))
    wb = r.u32()
    if wb != total * (4 if wt == 0 else 2):
        raise DlgsError("Payload", r.off() - 4, "MLPW weight_bytes")
    raw = zstd_exact(r.d[r.p:], wb, r.off(), "MLPW")
    vals = np.frombuffer(raw, "<f4" if wt == 0 else "<f2").astype(F32)
    if not np.all(np.isfinite(vals)):
        raise DlgsError("NonFinite", base, "MLPW weights")
    mlps = {}
    pos = 0
    for role, ws, _ in descs:
        mats = []
        for j in range(len(ws) - 1):
            k = ws[j] * ws[j + 1]
            mats.append(vals[pos:pos + k].reshape(ws[j + 1], ws[j]))
            pos += k
        mlps[role] = mats
    return {"mlps": mlps, "scale_offsets": bool(flags & 1)}


def run_mlp(mats, x, last_tanh=False):
    for j, Wm in enumerate(mats):
        x = layer_fma(Wm, x)
        if j < len(mats) - 1:
            x = relu(x)
    if last_tanh:
        x = tanh32(x)
    return x


# ---------------------------------------------------------------- LIFE
def parse_life(p, base, h):
    r = Reader(p, base, "LIFE")
    cnt = r.u32()
    if cnt > h.n_dynamic:
        raise DlgsError("Payload", base, "LIFE count")
    raw = zstd_exact(r.d[4:], 8 * cnt, base + 4, "LIFE")
    ents = []
    idx = -1
    for e in range(cnt):
        gap, first, last = struct.unpack_from("<IHH", raw, 8 * e)
        idx = gap if e == 0 else idx + 1 + gap
        if idx >= h.n_dynamic:
            raise DlgsError("Payload", base + 4, f"LIFE index {idx} >= n_dynamic")
        ents.append((idx, first, last))
    return ents


def gop_dynamic(d, g):
    cache = d.__dict__.setdefault("_dyn", {})
    if g in cache:
        return cache[g]
    c = d.c
    h = d.h
    _, chunks = c.gop(g)
    ch = chunks[b"TFEA"]
    F, how = parse_tfea(c.payload(ch), ch.poff, h)
    ch = chunks[b"MLPW"]
    mlpw = parse_mlpw(c.payload(ch), ch.poff, h)
    life = None
    if b"LIFE" in chunks:
        ch = chunks[b"LIFE"]
        life = parse_life(c.payload(ch), ch.poff, h)
    cache[g] = (F, mlpw, life, how)
    return cache[g]


# ---------------------------------------------------------------- §6.4
EPS4 = fromhex32(0x38D1B717)
CL_LO = fromhex32(0xBF7FF972)
CL_HI = fromhex32(0x3F7FF972)
EPS12 = fromhex32(0x2B8CBCCC)


def locate(t, h):
    fps = h.fps_num / h.fps_den
    u = t * fps
    ru = round_away(u)
    if abs(u - ru) < 1e-6:
        u = ru
    if not (0 <= t <= h.frame_count / fps):
        raise DlgsError("Request", None, "time out of range")
    g = min(math.floor(u / h.gop_length), h.gop_count - 1)
    local = min(max(u - g * h.gop_length, 0.0), float(h.gop_length))
    k = min(math.floor(local / h.key_interval), h.K - 2)
    delta = min(max((local - k * h.key_interval) / h.key_interval, 0.0), 1.0)
    frame = min(math.floor(u), h.frame_count - 1)
    return g, k, F32(delta), frame


def normalize(q):
    n = (q[:, 0] * q[:, 0]).astype(F32)
    for i in (1, 2, 3):
        n = (n + (q[:, i] * q[:, i]).astype(F32)).astype(F32)
    n = np.sqrt(n).astype(F32)
    n = np.maximum(n, EPS12).astype(F32)
    return (q / n[:, None]).astype(F32)


def slerp(a, b, dl):
    dot = (a[:, 0] * b[:, 0]).astype(F32)
    for i in (1, 2, 3):
        dot = (dot + (a[:, i] * b[:, i]).astype(F32)).astype(F32)
    d = np.clip(dot, CL_LO, CL_HI).astype(F32)
    om = np.array([max(acos32(v), EPS4) for v in d], F32)
    sg = np.array([max(sin32(v), EPS4) for v in om], F32)
    omd = F32(F32(1) - dl)
    a0 = (omd * om).astype(F32)
    a1 = (dl * om).astype(F32)
    p0 = (np.array([sin32(v) for v in a0], F32) / sg).astype(F32)
    p1 = (np.array([sin32(v) for v in a1], F32) / sg).astype(F32)
    S = np.maximum((p0 + p1).astype(F32), EPS4).astype(F32)
    p0 = (p0 / S).astype(F32)
    p1 = (p1 / S).astype(F32)
    r = ((p0[:, None] * a).astype(F32) + (p1[:, None] * b).astype(F32)).astype(F32)
    l1 = np.abs(r[:, 0])
    for i in (1, 2, 3):
        l1 = (l1 + np.abs(r[:, i])).astype(F32)
    nr = normalize(r)
    return np.where((l1 <= EPS4)[:, None], a, nr).astype(F32)


def lerp(a, b, dl):
    omd = F32(F32(1) - dl)
    return ((a * omd).astype(F32) + (b * dl).astype(F32)).astype(F32)


def decode_frame(d, t, eye):
    h = d.h
    g, k, dl, frame = locate(t, h)
    st = d.state(g).sets[1]
    F, mlpw, life, _ = gop_dynamic(d, g)
    M = mlpw["mlps"]
    so = mlpw["scale_offsets"]
    Fk = F[:, k, :]
    Fk1 = F[:, k + 1, :]
    xc, sc, qc = st.pos, st.ls, st.rot
    if h.deform_model == 0:
        ok = run_mlp(M[0], Fk[:, 0:12])
        ok1 = run_mlp(M[0], Fk1[:, 0:12])
        pk = (xc + ok[:, 0:3]).astype(F32)
        pk1 = (xc + ok1[:, 0:3]).astype(F32)
        d2 = F32(dl * dl)
        d3 = F32(d2 * dl)
        h00 = F32(F32(F32(F32(2) * d3) - F32(F32(3) * d2)) + F32(1))
        h10 = F32(F32(d3 - F32(F32(2) * d2)) + dl)
        h01 = F32(F32(F32(-2) * d3) + F32(F32(3) * d2))
        h11 = F32(d3 - d2)
        x = (h00 * pk).astype(F32)
        x = (x + (h10 * ok[:, 3:6]).astype(F32)).astype(F32)
        x = (x + (h01 * pk1).astype(F32)).astype(F32)
        x = (x + (h11 * ok1[:, 3:6]).astype(F32)).astype(F32)
        ck = run_mlp(M[1], Fk[:, 0:12])
        ck1 = run_mlp(M[1], Fk1[:, 0:12])
        qa = normalize((qc + ck[:, 3:7]).astype(F32))
        qb = normalize((qc + ck1[:, 3:7]).astype(F32))
        q = slerp(qa, qb, dl)
        s = (sc + ck[:, 0:3]).astype(F32) if so else sc.copy()
    else:
        Fl = lerp(Fk, Fk1, dl)
        cc = run_mlp(M[1], Fl[:, 0:12])
        x = (xc + run_mlp(M[0], Fl[:, 0:12])[:, 0:3]).astype(F32)
        q = normalize((qc + cc[:, 3:7]).astype(F32))
        s = (sc + cc[:, 0:3]).astype(F32) if so else sc.copy()
    e = np.asarray(eye, dtype=F32)
    v = (xc - e).astype(F32)
    dist = (v[:, 0] * v[:, 0]).astype(F32)
    dist = (dist + (v[:, 1] * v[:, 1]).astype(F32)).astype(F32)
    dist = (dist + (v[:, 2] * v[:, 2]).astype(F32)).astype(F32)
    dist = np.sqrt(dist).astype(F32)
    with np.errstate(divide="ignore"):
        inv = np.where(dist > 0, (F32(1) / dist).astype(F32), F32(0)).astype(F32)
    dirv = (v * inv[:, None]).astype(F32)
    Fl = lerp(Fk, Fk1, dl)
    y = np.concatenate([Fl[:, 4:12], dirv, dist[:, None]], axis=1).astype(F32)
    do = run_mlp(M[2], y, last_tanh=True)
    o = (st.op + do[:, 0]).astype(F32)
    lop = None
    if h.L:
        lop = (st.lop + (do[:, 1] if do.shape[1] > 1 else F32(0))).astype(F32)
    col = run_mlp(M[3], y)
    sh = st.sh.copy()
    m3 = col.shape[1]
    sh[:, :m3] = (sh[:, :m3] + col).astype(F32)
    lang = None
    if h.L:
        lang = (st.lang + run_mlp(M[4], Fl[:, 8:16])).astype(F32)
    if life is not None:
        loc = frame - g * h.gop_length
        for idx, first, last in life:
            if not (first <= loc <= last):
                o[idx] = fromhex32(0xC61C4000)
                if h.L:
                    lop[idx] = fromhex32(0xC61C4000)
    return dict(pos=x, ls=s, rot=q, op=o, lop=lop, sh=sh, lang=lang)


TIMES = [0.0, 0.5, 1.2345, 2.0, 3.95]
EYE = [0.3, -0.2, -2.5]


def compare_frames(d, path):
    ref = np.fromfile(path, "<f4")
    outs = []
    for t in TIMES:
        fr = decode_frame(d, t, EYE)
        parts = [fr["pos"], fr["ls"], fr["rot"], fr["op"]]
        if fr["lop"] is not None:
            parts.append(fr["lop"])
        parts.append(fr["sh"])
        if fr["lang"] is not None:
            parts.append(fr["lang"])
        outs.append(np.concatenate([np.ravel(p) for p in parts]).astype(F32))
    got = np.concatenate(outs)
    if got.shape != ref.shape:
        return f"frames: size {got.shape} vs {ref.shape}"
    same = np.sum(got.view(np.uint32) == ref.view(np.uint32))
    mx = float(np.max(np.abs(got.astype(np.float64) - ref)))
    how = d._dyn[0][3]
    return f"frames[{how}]: {same}/{len(ref)} bit-identical, max |diff| {mx:.3g}"
