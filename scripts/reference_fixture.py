#!/usr/bin/env python3
"""Build a small DLGStream "fdsd" (3DGS-variant) trained-model fixture in the reference
implementation's exact output layout, with the libraries the reference uses:
PyTorch `torch.save`, `imagecodecs` JPEG XL (`level=101` lossless float, `level=100` for SH DC),
`torchac` for the latent residuals, pandas for `compression_info.csv`, and the ffmpeg command
line with the reference's exact arguments for the 12-bit HEVC feature video.

SYNTHETIC CONTENT: no trained DLGStream model exists here. Geometry, colour and opacity come
from a REAL scene (../shared/data/ply/supersplat_fruit_drops_minimal_4721_sh3.ply, MIT,
PlayCanvas) and the language features from its REAL per-Gaussian labels; the dynamic split,
time features, deformation MLPs, GOP-1 position refinement and residual latents/decoders are
GENERATED with the reference's shapes (see gen_* below). Grids are sorted by a Morton order,
not PLAS (the order only changes compression, not the format).

Also writes `reference_decode/gop{g}.safetensors`: the tensors the reference's test-time decoder
(test_fdsd.py: decompress_attr_3, load_compressed_offset, get_*_ori) produces from these files,
computed with the same libraries (NumPy 1.x, which that code needs: it calls
`ndarray.newbyteorder`), for the Rust tests to compare against; and
`reference_decode/gop{g}_checkpoint.safetensors`: what `torch.load` reads from GOP 0's
`model.pth` and GOP 1's `model_offset.pth` (the values a checkpoint-only run must give).

Run by hand (CI does not): needs torch, numpy<2, imagecodecs, pandas, torchac (+ ninja, a C++
compiler), safetensors and the ffmpeg CLI with libx265.
    python scripts/reference_fixture.py tests/fixtures/reference_run
"""
import io
import json
import os
import pickle
import subprocess
import sys
import types
from collections import OrderedDict

import imagecodecs
import numpy as np
import pandas as pd
import torch
import torch.nn as nn
from safetensors.torch import save_file

assert np.__version__.startswith("1."), "the reference decoder needs NumPy 1.x"

DATA = os.environ.get("DLGS_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
SCENE = os.path.join(DATA, "ply", "supersplat_fruit_drops_minimal_4721_sh3.ply")
LABELS = os.path.join(DATA, "ply", "supersplat_fruit_drops_minimal.annotations.json")
S_SIDE, D_SIDE = 48, 24  # static 2304, dynamic 576 Gaussians: perfect squares as the reference needs
KEYS, FEAT = 7, 16
QP = 6
SEED = 6666


# ---------------------------------------------------------------- the reference's classes
# pickle records `compression.decoders.CompressedLatents`; make that path importable.
class CompressedLatents(object):
    """Same attributes and compress() rule as compression/decoders.py (torchac, tail 1e-4)."""

    def compress(self, latent):
        import torchac
        self.num_latents, self.latent_dim = latent.shape
        flattened = latent.flatten() * 1
        weight = torch.round(flattened).int()
        unique_vals, counts = torch.unique(weight, return_counts=True)
        probs = counts / torch.sum(counts)
        tail_idx = torch.where(probs <= 1.0e-4)[0]
        tail_vals = unique_vals[tail_idx]
        self.tail_locs = {}
        for val in tail_vals:
            self.tail_locs[val.item()] = torch.where(weight == val)[0].detach().cpu()
            weight[weight == val] = unique_vals[counts.argmax()]
        unique_vals, counts = torch.unique(weight, return_counts=True)
        probs = counts / torch.sum(counts)
        weight = weight.detach().cpu()
        cdf = torch.cumsum(probs, dim=0)
        cdf = torch.cat((torch.Tensor([0.0]).to(cdf), cdf))
        cdf = cdf / cdf[-1:]
        cdf = cdf.unsqueeze(0).repeat(flattened.size(0), 1)
        mapping = {val.item(): idx.item() for val, idx in zip(unique_vals, torch.arange(unique_vals.shape[0]))}
        weight.apply_(mapping.get)
        byte_stream = torchac.encode_float_cdf(cdf.detach().cpu(), weight.to(torch.int16))
        self.byte_stream, self.mapping, self.cdf = byte_stream, mapping, cdf[0].detach().cpu().numpy()

    def uncompress(self):
        import torchac
        cdf = torch.tensor(self.cdf).unsqueeze(0).repeat(self.num_latents * self.latent_dim, 1)
        weight = torchac.decode_float_cdf(cdf, self.byte_stream).to(torch.float32)
        inverse_mapping = {v: k for k, v in self.mapping.items()}
        weight.apply_(inverse_mapping.get)
        for val, locs in self.tail_locs.items():
            weight[locs] = val
        return weight.view(self.num_latents, self.latent_dim)


_pkg = types.ModuleType("compression")
_mod = types.ModuleType("compression.decoders")
_mod.CompressedLatents = CompressedLatents
CompressedLatents.__module__ = "compression.decoders"
_pkg.decoders = _mod
sys.modules["compression"] = _pkg
sys.modules["compression.decoders"] = _mod

# (name, normalize, quantize bits in GOP 0, JXL level) in fsd_gop60.yaml order
ATTRS = [
    ("_xyz", True, None, 101), ("_features_dc", True, None, 100), ("_features_rest", True, None, 101),
    ("_scaling", False, None, 101), ("_rotation", True, None, 101), ("_opacity", True, 6, 101),
    ("_language_feature", True, None, 101),
    ("_xyz_dynamic", True, None, 101), ("_features_dc_dynamic", True, None, 100),
    ("_features_rest_dynamic", True, 6, 101), ("_point_feats", None, None, None),
    ("_scaling_dynamic", False, 6, 101), ("_rotation_dynamic", True, 7, 101),
    ("_opacity_dynamic", True, 6, 101), ("_language_feature_dynamic", True, None, 101),
]
OFFSETS = [("_xyz_dynamic_offset", True, None, 101), ("_xyz_offset", True, None, 101)]
# latent decoders: (attribute, latent dim) in quat_attrbutes order, then the static ones
LATENT_DIMS = {"features_dc": 8, "features_rest": 4, "scaling": 8, "rotation": 6, "opacity": 4, "language_feature": 6}
FEATURE_DIMS = {"features_dc": 3, "features_rest": 9, "scaling": 3, "rotation": 4, "opacity": 2, "language_feature": 9}
MLP_SHAPES = {"mlp_deform": (12, 6, False), "mlp_cov": (12, 7, False), "mlp_opacity": (12, 2, True),
              "mlp_color": (12, 12, False), "mlp_lang": (8, 9, False)}


# ---------------------------------------------------------------- inputs
def read_ply(path):
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        n = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
        props = [(l.split()[2], l.split()[1]) for l in header if l.startswith("property")]
        dt = np.dtype([(name, {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4"}[t]) for name, t in props])
        return np.frombuffer(f.read(n * dt.itemsize), dtype=dt, count=n)


def morton_order(xyz):
    q = ((xyz - xyz.min(0)) / (np.ptp(xyz, 0) + 1e-9) * 1023).astype(np.uint64)
    code = np.zeros(len(xyz), np.uint64)
    for b in range(10):
        for a in range(3):
            code |= ((q[:, a] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + a)
    return np.argsort(code, kind="stable")


def build_model(rng):
    v = read_ply(SCENE)
    ann = json.load(open(LABELS))["dataset"]["samples"][0]["labels"]
    labels = np.array(next(iter(ann.values()))["attributes"]["point_annotations"], dtype=np.int64)
    xyz = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float32)
    # dynamic = the 576 Gaussians nearest a moving "object" centre (the largest labelled part)
    cat = np.bincount(labels[labels > 0]).argmax()  # 0 = unlabelled
    centre = xyz[labels == cat].mean(0)
    dist = np.linalg.norm(xyz - centre, axis=1)
    dyn = np.argsort(dist)[: D_SIDE * D_SIDE]
    rest = np.setdiff1d(np.arange(len(xyz)), dyn)
    stat = np.sort(rng.choice(rest, S_SIDE * S_SIDE, replace=False))
    codes = rng.normal(size=(int(labels.max()) + 2, 9)).astype(np.float32)
    codes /= np.linalg.norm(codes.reshape(-1, 3, 3), axis=2).repeat(3, 1).reshape(-1, 9)

    def gaussians(idx):
        idx = idx[morton_order(xyz[idx])]
        n = len(idx)
        dc = np.stack([v[f"f_dc_{c}"] for c in range(3)], 1)[idx]
        rest = np.stack([v[f"f_rest_{c * 15 + k}"] for k in range(3) for c in range(3)], 1)[idx]  # (coef, rgb)
        op = v["opacity"][idx]
        lang = codes[labels[idx] + 1] + 0.05 * rng.normal(size=(n, 9)).astype(np.float32)
        return {
            "xyz": xyz[idx],
            "features_dc": dc.reshape(n, 1, 3).astype(np.float32),
            "features_rest": rest.reshape(n, 3, 3).astype(np.float32),
            "scaling": np.stack([v[f"scale_{a}"] for a in range(3)], 1)[idx].astype(np.float32),
            "rotation": np.stack([v[f"rot_{a}"] for a in range(4)], 1)[idx].astype(np.float32),
            "opacity": np.stack([op, op + 0.3 * rng.normal(size=n)], 1).astype(np.float32),
            "language_feature": lang.astype(np.float32),
        }

    return gaussians(stat), gaussians(dyn)


def gen_time_features(xyz_dyn, rng, prev_last=None):
    """Smooth (N, 7, 16) features: low-frequency functions of position and key, as trained
    features of neighbouring (PLAS-sorted) Gaussians are."""
    n = len(xyz_dyn)
    p = (xyz_dyn - xyz_dyn.mean(0)) / (xyz_dyn.std(0) + 1e-9)
    w = rng.normal(size=(3, FEAT)).astype(np.float32)
    ph = rng.uniform(0, 6.28, size=FEAT).astype(np.float32)
    f = np.zeros((n, KEYS, FEAT), np.float32)
    for k in range(KEYS):
        f[:, k, :] = 0.6 * np.sin(p @ w + ph + 0.5 * k) + 0.02 * rng.normal(size=(n, FEAT))
    if prev_last is not None:  # temporal loss: key 0 of GOP g+1 close to key 6 of GOP g
        f[:, 0, :] = prev_last + 0.01 * rng.normal(size=(n, FEAT))
    return f.astype(np.float32)


def gen_mlps(seed, scale=0.15):
    torch.manual_seed(seed)
    mlps = {}
    for name, (i, o, tanh) in MLP_SHAPES.items():
        layers = [nn.Linear(i, 64, bias=False), nn.ReLU(), nn.Linear(64, o, bias=False)]
        if tanh:
            layers.append(nn.Tanh())
        m = nn.Sequential(*layers)
        with torch.no_grad():
            m[2].weight.mul_(scale)
        mlps[name] = m
    return mlps


# ---------------------------------------------------------------- the reference's encode rules
def grid(a, side):
    return a.reshape(side, side, -1)


def frame_maker(img, side):
    frame = np.zeros((side * 4, side * 4), np.float32)
    for c in range(img.shape[2]):
        frame[(c // 4) * side:(c // 4 + 1) * side, (c % 4) * side:(c % 4 + 1) * side] = img[:, :, c]
    return frame


def compress_attr(name, img, normalize, quantize, level, out, gop0):
    if quantize is not None and gop0:
        mn, mx = img.min(), img.max()
        r = mx - mn
        if r == 0:
            r = 1
        qpow = 2 ** quantize
        img = (np.round((img - mn) / r * qpow) / qpow * r + mn).astype(np.float32)
    if normalize:
        lo, hi = img.min(), img.max()
        img = (img.clip(lo, hi) - lo) / (hi - lo)
    imagecodecs.imwrite(os.path.join(out, f"{name}.jxl"), img, level=level)
    return (lo, hi) if normalize else (None, None)


def write_features(feats, side, out):
    fdir = os.path.join(out, "feat_images")
    os.makedirs(fdir, exist_ok=True)
    lo, hi = np.min(feats), np.max(feats)
    for k in range(KEYS):
        img = frame_maker(grid(feats[:, k, :], side), side)
        img = (img.clip(lo, hi) - lo) / (hi - lo)
        imagecodecs.imwrite(os.path.join(fdir, f"_point_feats_{k}.png"), (img * 65535).astype("uint16"), level=0)
    subprocess.run(f"ffmpeg -y -loglevel error -framerate 30 -i {fdir}/_point_feats_%d.png -c:v libx265 "
                   f"-pix_fmt gray12le -color_range pc -crf {QP} {out}/_point_feats.mp4", shell=True, check=True)
    return lo, hi


def write_csv(rows, out):
    mins = {k: v[0] for k, v in rows.items()}
    maxs = {k: v[1] for k, v in rows.items()}
    files = {k: v[2] for k, v in rows.items()}
    pd.DataFrame([mins, maxs, files], index=["min", "max", "file"]).T.to_csv(os.path.join(out, "compression_info.csv"))


def save_mlps(mlps, out):
    for name, m in mlps.items():
        torch.save(m.state_dict(), os.path.join(out, f"{name}.pth"))


# ---------------------------------------------------------------- the reference's decode rules
def decode_features(out, lo, hi):
    """measure_decode_latency + decompress_attr_3: gray16be pipe, /65535*(max-min)+min."""
    mp4 = os.path.join(out, "_point_feats.mp4")
    probe = json.loads(subprocess.run(["ffprobe", "-v", "error", "-show_streams", "-of", "json", mp4],
                                      capture_output=True, check=True).stdout)
    w, h = probe["streams"][0]["width"], probe["streams"][0]["height"]
    raw = subprocess.run(["ffmpeg", "-v", "error", "-i", mp4, "-f", "rawvideo", "-pix_fmt", "gray16be", "pipe:"],
                         capture_output=True, check=True).stdout
    frames = np.frombuffer(raw, dtype=np.uint16).newbyteorder(">").reshape(-1, w, h)
    side = w // 4
    feats = np.zeros((side * side, KEYS, FEAT), np.float32)
    for k in range(KEYS):
        img = frames[k] / 65535 * (hi - lo) + lo
        for c in range(FEAT):
            feats[:, k, c] = img[(c // 4) * side:(c // 4 + 1) * side, (c % 4) * side:(c % 4 + 1) * side].reshape(-1)
    return feats


def decode_attr(out, name, lo, hi, shape):
    img = imagecodecs.imread(os.path.join(out, f"{name}.jxl"))
    if lo is not None and not (isinstance(lo, float) and np.isnan(lo)):
        img = img * (hi - lo) + lo
    return torch.tensor(img.reshape(-1, *shape), dtype=torch.float)


SHAPES = {"xyz": (3,), "features_dc": (1, 3), "features_rest": (3, 3), "scaling": (3,), "rotation": (4,),
          "opacity": (2,), "language_feature": (9,)}


def decode_gop0(out):
    info = pd.read_csv(os.path.join(out, "compression_info.csv"), index_col=0)
    t = {}
    for name, normalize, _, _ in ATTRS:
        if name == "_point_feats":
            continue
        base = name[1:].replace("_dynamic", "")
        t[name] = decode_attr(out, name, info.loc[name, "min"], info.loc[name, "max"], SHAPES[base])
    t["_point_feats"] = torch.tensor(decode_features(out, info.loc["_point_feats", "min"], info.loc["_point_feats", "max"]))
    return t


class LatentDecoder(nn.Module):
    """compression/decoders.py LatentDecoder with num_layers_dec = 0: round(z)/div @ scale + shift."""

    def __init__(self, latent_dim, feature_dim, ldecode_matrix="learnable"):
        super().__init__()
        self.div = nn.Parameter(torch.ones(latent_dim), requires_grad=False)
        self.layers = nn.Sequential(nn.Module())
        self.layers[0].scale = nn.Parameter(torch.zeros(latent_dim, feature_dim))
        self.layers[0].shift = nn.Parameter(torch.zeros(1, feature_dim))

    def forward(self, z):
        return torch.matmul(torch.round(z) / self.div, self.layers[0].scale) + self.layers[0].shift


def decode_gop1(out, prev):
    info = pd.read_csv(os.path.join(out, "compression_info.csv"), index_col=0)
    with open(os.path.join(out, "offset_compressed.pkl"), "rb") as f:
        data = pickle.load(f)
    t = {}
    for key, lat in data["latents"].items():  # '_features_dc_dynamic_offset', ...
        args = data["decoder_args"][key]
        dec = LatentDecoder(args["latent_dim"], args["feature_dim"])
        dec.load_state_dict(data["decoder_state_dict"][key])
        delta = dec(lat.uncompress())
        base = key[1:].replace("_offset", "")  # 'features_dc_dynamic'
        attr = "_" + base
        t[attr] = (prev[attr] + delta.reshape(prev[attr].shape)).detach()
    t["_xyz"] = decode_attr(out, "_xyz_offset", info.loc["_xyz_offset", "min"], info.loc["_xyz_offset", "max"], (3,))
    t["_xyz_dynamic"] = decode_attr(out, "_xyz_dynamic_offset", info.loc["_xyz_dynamic_offset", "min"],
                                    info.loc["_xyz_dynamic_offset", "max"], (3,))
    t["_point_feats"] = torch.tensor(decode_features(out, info.loc["_point_feats", "min"], info.loc["_point_feats", "max"]))
    return t


# ---------------------------------------------------------------- GOP 1 generators
def gen_latents(n, dim, init, moving, rng):
    """Trained-looking latents: most stay at their initial value, some are pulled to 0 by the
    L1 rate term, Gaussians in `moving` (a mask) take spatially coherent small integers."""
    z = np.full((n, dim), init, np.float32)
    pull = rng.random((n, dim)) < 0.3
    z[pull] = 0.0
    mv = moving[:, None] & (rng.random((n, dim)) < 0.8)
    z[mv] = np.round(rng.normal(0, 2.0, size=mv.sum()))
    z += rng.uniform(-0.3, 0.3, size=z.shape).astype(np.float32)  # STE-trained latents are not integers
    # a few outliers become torchac "tail" values
    tail = rng.random((n, dim)) < 5e-5
    z[tail] = 40.0
    return torch.tensor(z)


def main(root):
    rng = np.random.default_rng(SEED)
    stat, dyn = build_model(rng)
    os.makedirs(root, exist_ok=True)
    provenance = {
        "what": "SYNTHETIC DLGStream fdsd fixture in the reference layout (scripts/reference_fixture.py)",
        "scene": "supersplat_fruit_drops_minimal_4721_sh3.ply (MIT, PlayCanvas) + its labels",
        "generated": "dynamic split, time features, MLPs, GOP-1 refinement and latents",
        "versions": {"torch": torch.__version__, "numpy": np.__version__, "imagecodecs": imagecodecs.__version__,
                     "pandas": pd.__version__,
                     "ffmpeg": subprocess.run(["ffmpeg", "-version"], capture_output=True, text=True).stdout.split("\n")[0]},
        "n_static": S_SIDE ** 2, "n_dynamic": D_SIDE ** 2, "qp": QP, "seed": SEED,
    }
    dec_dir = os.path.join(root, "reference_decode")
    os.makedirs(dec_dir, exist_ok=True)

    # ---------------- GOP 0
    out0 = os.path.join(root, "gop0_fixture", "compression", "best", "jxl_quant")
    os.makedirs(out0, exist_ok=True)
    feats0 = gen_time_features(dyn["xyz"], rng)
    mlps0 = gen_mlps(SEED)
    rows = {}
    for name, normalize, quantize, level in ATTRS:
        if name == "_point_feats":
            lo, hi = write_features(feats0, D_SIDE, out0)
            rows[name] = (lo, hi, f"{name}_{KEYS - 1}.png")
            continue
        base = name[1:].replace("_dynamic", "")
        src, side = (dyn, D_SIDE) if name.endswith("_dynamic") else (stat, S_SIDE)
        lo, hi = compress_attr(name, grid(src[base].reshape(side * side, -1), side), normalize, quantize, level, out0, True)
        rows[name] = (lo, hi, f"{name}.jxl")
    write_csv(rows, out0)
    save_mlps(mlps0, out0)
    sd = OrderedDict()
    for base in SHAPES:
        sd[f"_{base}"] = torch.tensor(stat[base])
        sd[f"_{base}_dynamic"] = torch.tensor(dyn[base])
    sd["_point_feats"] = torch.tensor(feats0)
    sd["_lang_temp_feats"] = torch.tensor(feats0[:, :, 12:16])
    for name, m in mlps0.items():
        for k, v in m.state_dict().items():
            sd[f"{name}.{k}"] = v
    torch.save(sd, os.path.join(out0, "model.pth"))
    dec0 = decode_gop0(out0)
    for name, m in mlps0.items():
        for k, v in m.state_dict().items():
            dec0[f"{name}.{k}"] = v.contiguous()
    save_file({k: v.contiguous() for k, v in dec0.items()}, os.path.join(dec_dir, "gop0.safetensors"))

    # ---------------- GOP 1 (offset_mode 22), trained from the decoded GOP 0
    out1 = os.path.join(root, "gop1_fixture", "compression", "best", "jxl_quant")
    os.makedirs(out1, exist_ok=True)
    torch.manual_seed(SEED + 1)
    ext = float(np.ptp(dec0["_xyz"].numpy(), 0).max())
    xyz_s = dec0["_xyz"].numpy().copy()
    moved = rng.random(len(xyz_s)) < 0.7
    xyz_s[moved] += rng.normal(0, 2e-4 * ext, size=(moved.sum(), 3)).astype(np.float32)
    xyz_d = dec0["_xyz_dynamic"].numpy() + rng.normal(0, 1e-3 * ext, size=dec0["_xyz_dynamic"].shape).astype(np.float32)
    feats1 = gen_time_features(dyn["xyz"], rng, prev_last=dec0["_point_feats"].numpy()[:, KEYS - 1, :])
    mlps1 = gen_mlps(SEED + 1)
    latents, dec_sd, dec_args = OrderedDict(), OrderedDict(), OrderedDict()
    for suffix, n, side in (("_dynamic_offset", D_SIDE ** 2, D_SIDE), ("_offset", S_SIDE ** 2, S_SIDE)):
        pos = (dec0["_xyz_dynamic"] if "dynamic" in suffix else dec0["_xyz"]).numpy()
        moving = pos[:, 0] > np.median(pos[:, 0]) if "dynamic" in suffix else rng.random(n) < 0.1
        for attr, ldim in LATENT_DIMS.items():
            init = 1.5 if (attr == "opacity" and suffix == "_offset") else 1.0
            z = gen_latents(n, ldim, init, moving, rng)
            obj = CompressedLatents()
            obj.compress(z)
            key = f"_{attr}{suffix}"
            latents[key] = obj
            dec = LatentDecoder(ldim, FEATURE_DIMS[attr])
            with torch.no_grad():
                dec.layers[0].scale.normal_(0, 0.01)
                dec.layers[0].shift.normal_(0, 0.005)
            dec_sd[key] = dec.state_dict().copy()
            dec_args[key] = {"latent_dim": ldim, "feature_dim": FEATURE_DIMS[attr], "ldecode_matrix": "learnable"}
    with open(os.path.join(out1, "offset_compressed.pkl"), "wb") as f:
        pickle.dump({"latents": latents, "decoder_state_dict": dec_sd, "decoder_args": dec_args}, f)
    rows = {}
    lo, hi = write_features(feats1, D_SIDE, out1)
    rows["_point_feats"] = (lo, hi, f"_point_feats_{KEYS - 1}.png")
    for (name, normalize, quantize, level), (arr, side) in zip(OFFSETS, [(xyz_d, D_SIDE), (xyz_s, S_SIDE)]):
        lo, hi = compress_attr(name, grid(arr, side), normalize, quantize, level, out1, False)
        rows[name] = (lo, hi, f"{name}.jxl")
    write_csv(rows, out1)
    save_mlps(mlps1, out1)
    sd = OrderedDict([("_xyz_offset", torch.tensor(xyz_s)), ("_xyz_dynamic_offset", torch.tensor(xyz_d)),
                      ("_point_feats", torch.tensor(feats1)), ("offset_mode", 22)])
    torch.save(sd, os.path.join(out1, "model.pth"))
    dec1 = decode_gop1(out1, dec0)
    # model_offset.pth as GaussianModel.save() writes it (offset_mode 22): the state dict (base
    # attributes = the decoded GOP 0, new features, MLPs), then every attribute accumulated
    # under `_<attr>[_dynamic]_offset` (get_*_ori: base + latent decoder output; the latents
    # are rounded in the decoder, so these equal the decoded values) and the absolute refined
    # positions as trained (before their JPEG XL normalisation).
    sd = OrderedDict()
    for base in SHAPES:
        for suffix in ("", "_dynamic"):
            sd[f"_{base}{suffix}"] = dec0[f"_{base}{suffix}"].clone()
    sd["_point_feats"] = torch.tensor(feats1)
    for name, m in mlps1.items():
        for k, v in m.state_dict().items():
            sd[f"{name}.{k}"] = v
    sd["_xyz_dynamic_offset"] = torch.tensor(xyz_d)
    sd["_xyz_offset"] = torch.tensor(xyz_s)
    for base in SHAPES:
        if base != "xyz":
            for suffix in ("_dynamic", ""):
                sd[f"_{base}{suffix}_offset"] = dec1[f"_{base}{suffix}"].clone()
    sd["offset_mode"] = 22
    torch.save(sd, os.path.join(out1, "model_offset.pth"))
    # What torch.load reads from the checkpoints: the expected values of a checkpoint-only run.
    for g, (d, f) in enumerate(((out0, "model.pth"), (out1, "model_offset.pth"))):
        ck = torch.load(os.path.join(d, f), weights_only=True)
        # (GOP 1: only what a reader takes from model_offset.pth, not the base attributes)
        keep = lambda k: g == 0 or k.endswith("_offset") or k.startswith("mlp_") or k == "_point_feats"
        save_file({k: v.contiguous() for k, v in ck.items() if torch.is_tensor(v) and keep(k)},
                  os.path.join(dec_dir, f"gop{g}_checkpoint.safetensors"))
    for name, m in mlps1.items():
        for k, v in m.state_dict().items():
            dec1[f"{name}.{k}"] = v.contiguous()
    save_file({k: v.contiguous() for k, v in dec1.items()}, os.path.join(dec_dir, "gop1.safetensors"))
    for d in (out0, out1):
        for f in os.listdir(os.path.join(d, "feat_images")):
            os.remove(os.path.join(d, "feat_images", f))
        os.rmdir(os.path.join(d, "feat_images"))
    json.dump(provenance, open(os.path.join(root, "PROVENANCE.json"), "w"), indent=1)
    print("wrote", root)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tests/fixtures/reference_run")
