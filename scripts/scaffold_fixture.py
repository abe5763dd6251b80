#!/usr/bin/env python3
"""Build a small DLGStream "hac" (Scaffold-GS + HAC-coding) model fixture in the reference
implementation's exact on-disk layout for 2 GOPs, with the libraries the reference uses:
PyTorch `torch.save`, torchac's range coder (the reference's `submodules/arithmetic` CUDA coder is
a port of it), OpenCV 16-bit PNG, pandas `compression_info.csv` and the ffmpeg command line with the
reference's exact arguments for the 12-bit HEVC time-feature video.

WHAT IS REAL, FITTED, GENERATED
* REAL: the scene, ../shared/data/ply/supersplat_fruit_drops_minimal_4721_sh3.ply (MIT, PlayCanvas):
  anchors are its Gaussian centres voxelised as Scaffold-GS initialises from points
  (`unique(round(p / voxel)) * voxel`), and the targets of the fit are its Gaussians (position, DC
  colour, opacity, scale, rotation) and its REAL per-Gaussian labels (annotations.json).
* GENERATED: the 9-d language code of each label (3 unit 3-vectors, seeded, like the autoencoder's
  L2-normalised outputs), the choice of the dynamic anchors (those of one labelled object), a smooth
  rigid motion of that object over the 2 GOPs (no real motion exists for this scene), and GOP 1's
  change (that object's colour shifts and its children move 15 % towards their anchor).
* FITTED (Adam on the CPU, see fit_*): anchor features, offsets, scalings and the four decoding
  MLPs (mlp_opacity/color/cov/language) to the scene's Gaussians near each anchor, seen from 8 ring
  cameras, under HAC's noise quantisation, jointly with the context model (mlp_grid + binary 3D hash
  grid + three binary 2D planes) trained with the reference's rate terms; then per GOP the 7-key
  16-channel time features and the 4 bias-free deform MLPs to the generated motion; in GOP 1 the NTC
  (binary tri-plane + 3D gate + ntc_mlp) to the generated change with its rate term. The loss is a
  per-child attribute loss, not a rendering loss (see child_loss).
* The reference's CUDA `gridencoder` (missing from its public copy) is replaced by `grid_lookup`,
  a torch implementation of the HAC++ kernel's forward pass (reference-implementation.md §3.5).

Bitstreams are written with torchac's CPU coder: per 10,000-symbol chunk one independent
`encode_int16_normalized_cdf` stream with the CUDA kernel's integer CDF rule
c(s) = rint(float32(cdf[s] * (65536 - (Lp-1)))) + s, the float32 erfc CDF table of
`calculate_cdf_kernel`, and the `min|max|nbytes_cnt|cnt[]|payload` file layout. Every chunk is also
checked to equal `torchac.encode_float_cdf` of the float table, and every file is decoded back with
`torchac.decode_float_cdf` from the decoder's side (CDFs recomputed from the decoded anchors and
grid), which must give the encoded symbols.

Also writes `reference_decode/`: gop{g}.safetensors with the tensors the reference's decoder
(conduct_decoding_from_files, conduct_decoding_for_ntc, decompress_attr_hac) gets from the files,
and neural_f64.safetensors + cameras.json, an independent float64 NumPy evaluation of §5.2.

Run by hand (CI does not): needs torch, numpy, pandas, torchac (+ ninja on PATH and a C++ compiler),
opencv-python-headless, safetensors and the ffmpeg CLI with libx265. About 9.5 minutes on one core (564 s measured):
    PATH=/work/venv-scaffold/bin:$PATH nice -n 5 python scripts/scaffold_fixture.py tests/fixtures/scaffold_run
"""
import json
import math
import os
import subprocess
import sys
import time
from collections import OrderedDict

import cv2
import numpy as np
import pandas as pd
import torch
import torch.nn as nn
import torchac
from safetensors.numpy import save_file as save_np
from safetensors.torch import save_file

torch.set_num_threads(1)

DATA = os.environ.get("DLGS_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
# DLGS_FIXTURE_SCENE: another INRIA PLY (default the fruit scene). DLGS_FIXTURE_LABELS: its
# annotations json (default: the fruit labels for the default scene, none for another scene; set but
# empty: none). Without labels, the labels are GENERATED: the octant of each Gaussian centre about
# the per-axis median (1..8), see load_scene. DLGS_FIXTURE_ANCHORS: target anchor count (2400).
SCENE = os.environ.get("DLGS_FIXTURE_SCENE") or os.path.join(DATA, "ply", "supersplat_fruit_drops_minimal_4721_sh3.ply")
LABELS = os.environ.get("DLGS_FIXTURE_LABELS", None if os.environ.get("DLGS_FIXTURE_SCENE")
                        else os.path.join(DATA, "ply", "supersplat_fruit_drops_minimal.annotations.json")) or None
SEED = 6666
# `model.pth` (the reference's training checkpoint, 25 MB here: its grids as float32) is not
# what the reference's decoder reads and is not committed; DLGS_FIXTURE_MODEL_PTH=1 writes it.
WRITE_MODEL_PTH = os.environ.get("DLGS_FIXTURE_MODEL_PTH") == "1"
QP = 6
FAST = os.environ.get("FIXTURE_FAST") == "1"  # quick fit for development

# ---- the reference's constants (train_hac.py / scaffold_gaussian_model.py)
FEAT_DIM, N_OFF, TF_DIM = 50, 10, 16
TIME_LINE, INTERVAL = 60, 10
KEYS = TIME_LINE // INTERVAL + 1  # 7
RES_3D, LOG2_3D = (18, 24, 33, 44, 59, 80, 108, 148, 201, 275, 376, 514), 13
RES_2D, LOG2_2D = (130, 258, 514, 1026), 15
N_FEAT_LEVEL = 4
NTC_RES_2D, NTC_LOG2_2D, NTC_RES_3D, NTC_LOG2_3D = (512, 1024, 2048, 4096), 15, (514,), 15
Q_ANCHOR = 1 / (2 ** 16 - 1)
BATCH = 1000  # MAX_batch_size
CHUNK = 10000  # chunk_size_cuda
Q_BASE = {"feat": 1.0, "scaling": 0.001, "offsets": 0.2}
PRIMES = (1, 2654435761, 805459861)
TARGET_ANCHORS = int(os.environ.get("DLGS_FIXTURE_ANCHORS", "2400"))
SUBSET_STEP = 32  # neural_f64 stores the children of every 32nd anchor


# =====================================================================================
# binary hash grids (GridEncoder with ste_binary) and the torch replacement of the CUDA kernel
# =====================================================================================
class STEBinary(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x):
        ctx.save_for_backward(x)
        return torch.where(x.clamp(-1, 1) >= 0, 1.0, -1.0).to(x.dtype)

    @staticmethod
    def backward(ctx, g):
        (x,) = ctx.saved_tensors
        return g * ((x >= -1) & (x <= 1)).to(g.dtype)


def level_sizes(res, num_dim, log2):
    """GridEncoder.__init__: entries per level = ceil(min(2^log2, R^D) / 8) * 8."""
    sizes = [int(math.ceil(min(2 ** log2, r ** num_dim) / 8) * 8) for r in res]
    return sizes, np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


class BinaryGrid(nn.Module):
    def __init__(self, num_dim, res, log2, n_features):
        super().__init__()
        self.num_dim, self.res, self.n_features = num_dim, tuple(res), n_features
        sizes, offs = level_sizes(res, num_dim, log2)
        self.register_buffer("offsets_list", torch.tensor(offs, dtype=torch.int32))
        self.register_buffer("resolutions_list", torch.tensor(res, dtype=torch.int32))
        self.params = nn.Parameter(torch.empty(int(offs[-1]), n_features).uniform_(-1e-4, 1e-4))

    def forward(self, x, emb=None):
        return grid_lookup(x, STEBinary.apply(self.params) if emb is None else emb,
                           self.offsets_list.long().tolist(), self.res, self.num_dim)


def grid_index(loc, R, size, num_dim):
    """get_grid_index: dense row-major (x fastest) while the stride stays <= size, else the XOR
    hash with primes (1, 2654435761, 805459861) in uint32 arithmetic; then % size."""
    stride, index = 1, torch.zeros_like(loc[0])
    for d in range(num_dim):
        if stride > size:
            break
        index = index + loc[d] * stride
        stride *= R
    if stride > size:
        h = torch.zeros_like(loc[0])
        for d in range(num_dim):
            h = h ^ ((loc[d] * PRIMES[d]) & 0xFFFFFFFF)
        index = h
    return index % size


def grid_lookup(x, emb, offsets, res, num_dim):
    """Forward pass of HAC++'s gridencoder.cu kernel (binary_vxl = None, all levels), float32:
    pos = x*(R-2)+0.5; g = floor(pos); f = pos-g; corner idx bit d: 0 -> g_d, weight (1-f_d);
    1 -> min(g_d+1, R-1), weight f_d (weights multiplied over d = 0..D-1 from 1.0); a corner with
    any coordinate 0 or R-1 is dropped; wn = sum of kept weights (1e-9 if 0), wn_re = 1.0/wn in
    double then float; out = sum over kept corners in corner order of (w * wn_re) * emb.
    Any coordinate outside [0,1] -> zeros for all levels. Output [N, L*F], level-major."""
    x = x.float()
    oob = ((x < 0) | (x > 1)).any(dim=1)
    outs = []
    for lvl, R in enumerate(res):
        size = offsets[lvl + 1] - offsets[lvl]
        pos = x * float(R - 2) + 0.5
        g = torch.floor(pos)
        f = pos - g
        g = g.long()
        ws, idxs, keeps = [], [], []
        for c in range(1 << num_dim):
            w = torch.ones_like(x[:, 0])
            loc = []
            for d in range(num_dim):
                if (c >> d) & 1 == 0:
                    w = w * (1 - f[:, d])
                    loc.append(g[:, d])
                else:
                    w = w * f[:, d]
                    loc.append(torch.clamp(g[:, d] + 1, max=R - 1))
            keep = torch.ones_like(oob)
            for d in range(num_dim):
                keep = keep & (loc[d] != 0) & (loc[d] != R - 1)
            loc = [l.clamp(0, R - 1) for l in loc]
            ws.append(torch.where(keep, w, torch.zeros_like(w)))
            idxs.append(grid_index(loc, R, size, num_dim) + offsets[lvl])
            keeps.append(keep)
        wn = torch.zeros_like(x[:, 0])
        for w in ws:
            wn = wn + w
        wn = torch.where(wn == 0, torch.full_like(wn, 1e-9), wn)
        wn_re = (1.0 / wn.double()).float()
        out = torch.zeros(x.shape[0], emb.shape[1], dtype=emb.dtype)
        for w, idx in zip(ws, idxs):
            out = out + (w * wn_re)[:, None] * emb[idx]
        outs.append(out)
    out = torch.cat(outs, dim=1)
    return torch.where(oob[:, None], torch.zeros_like(out), out)


class Mix3D2D(nn.Module):
    """mix_3D2D_encoding: [3D(12x4), xy(4x4), xz(4x4), yz(4x4)] = 96."""

    def __init__(self):
        super().__init__()
        self.encoding_xyz = BinaryGrid(3, RES_3D, LOG2_3D, N_FEAT_LEVEL)
        self.encoding_xy = BinaryGrid(2, RES_2D, LOG2_2D, N_FEAT_LEVEL)
        self.encoding_xz = BinaryGrid(2, RES_2D, LOG2_2D, N_FEAT_LEVEL)
        self.encoding_yz = BinaryGrid(2, RES_2D, LOG2_2D, N_FEAT_LEVEL)

    def forward(self, x):
        return torch.cat([self.encoding_xyz(x), self.encoding_xy(x[:, [0, 1]]),
                          self.encoding_xz(x[:, [0, 2]]), self.encoding_yz(x[:, [1, 2]])], dim=1)

    def binary_params(self):
        return torch.cat([self.encoding_xyz.params, self.encoding_xy.params,
                          self.encoding_xz.params, self.encoding_yz.params], 0)


class NTC(nn.Module):
    """NTC_encoding: tri-plane (4 levels x 4 features, 2^15) * sigmoid(3D gate 514, 2^15, 1)."""

    def __init__(self):
        super().__init__()
        self.encoding_xyz = BinaryGrid(3, NTC_RES_3D, NTC_LOG2_3D, 1)
        self.encoding_xy = BinaryGrid(2, NTC_RES_2D, NTC_LOG2_2D, 4)
        self.encoding_xz = BinaryGrid(2, NTC_RES_2D, NTC_LOG2_2D, 4)
        self.encoding_yz = BinaryGrid(2, NTC_RES_2D, NTC_LOG2_2D, 4)

    def forward(self, x):
        tri = torch.cat([self.encoding_xy(x[:, [0, 1]]), self.encoding_xz(x[:, [0, 2]]),
                         self.encoding_yz(x[:, [1, 2]])], dim=1)
        return tri * torch.sigmoid(self.encoding_xyz(x))


def mlp(i, h, o, bias=True, act=None):
    layers = [nn.Linear(i, h, bias=bias), nn.ReLU(True), nn.Linear(h, o, bias=bias)]
    if act is not None:
        layers.append(act)
    return nn.Sequential(*layers)


class Model(nn.Module):
    """The trainable parts of scaffold_gaussian_model.GaussianModel (hybrid, language)."""

    def __init__(self):
        super().__init__()
        self.encoding_xyz = Mix3D2D()
        self.mlp_opacity = mlp(FEAT_DIM + 4, FEAT_DIM, 2 * N_OFF, act=nn.Tanh())
        self.mlp_cov = mlp(FEAT_DIM + 4, FEAT_DIM, 7 * N_OFF)
        self.mlp_color = mlp(FEAT_DIM + 4, FEAT_DIM, 3 * N_OFF, act=nn.Sigmoid())
        self.mlp_grid = mlp(96, 2 * FEAT_DIM, (FEAT_DIM + 6 + 3 * N_OFF) * 2 + 3)
        self.mlp_language = mlp(FEAT_DIM + 4, FEAT_DIM, 9 * N_OFF)
        self.new_deform()

    def new_deform(self):
        self.mlp_deform_xyz = mlp(TF_DIM + 3, 64, 3, bias=False)
        self.mlp_deform_cov = mlp(TF_DIM, 128, FEAT_DIM, bias=False)
        self.mlp_deform_opacity = mlp(TF_DIM, 64, 3 * N_OFF, bias=False)
        self.mlp_deform_color = mlp(TF_DIM, 64, 6, bias=False)


# =====================================================================================
# scene, anchors, targets, motion
# =====================================================================================
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


def load_scene(rng):
    v = read_ply(SCENE)
    xyz = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)
    if LABELS:
        ann = json.load(open(LABELS))["dataset"]["samples"][0]["labels"]
        labels = np.array(next(iter(ann.values()))["attributes"]["point_annotations"], dtype=np.int64)
    else:  # no labels: GENERATED label = 1 + octant of the centre about the per-axis median
        labels = 1 + ((xyz > np.median(xyz, 0)) * np.array([1, 2, 4])).sum(1).astype(np.int64)
    rgb = np.clip(0.5 + 0.28209479177387814 * np.stack([v[f"f_dc_{c}"] for c in range(3)], 1), 0, 1)
    alpha = 1 / (1 + np.exp(-v["opacity"].astype(np.float64)))
    scale = np.exp(np.stack([v[f"scale_{a}"] for a in range(3)], 1).astype(np.float64))
    rot = np.stack([v[f"rot_{a}"] for a in range(4)], 1).astype(np.float64)
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    codes = rng.normal(size=(int(labels.max()) + 1, 3, 3))
    codes /= np.linalg.norm(codes, axis=2, keepdims=True)
    return dict(xyz=xyz, rgb=rgb, alpha=alpha, scale=scale, rot=rot, label=labels,
                lang=codes.reshape(-1, 9)[labels])


def voxelise(xyz, rng):
    """create_from_pcd: shuffle, unique(round(p/voxel))*voxel; voxel chosen for ~TARGET_ANCHORS."""
    lo, hi = 1e-4, 0.1
    count = lambda vs: len(np.unique(np.round(xyz / vs), axis=0))
    while count(hi) > TARGET_ANCHORS and hi < 1e6:  # widen the bracket for other scene sizes
        hi *= 10
    while count(lo) <= TARGET_ANCHORS and lo > 1e-9:
        lo /= 10
    for _ in range(40):
        vs = math.sqrt(lo * hi)
        n = len(np.unique(np.round(xyz / vs), axis=0))
        lo, hi = (vs, hi) if n > TARGET_ANCHORS else (lo, vs)
    pts = xyz.copy()
    rng.shuffle(pts)
    return np.unique(np.round(pts / hi), axis=0) * hi, hi


def assign_targets(anchors, scene, voxel):
    """Child k of an anchor targets the k-th nearest scene Gaussian within 2.5 voxels; slots with
    none are 'off' (target colour opacity -0.5, so the decoder drops them)."""
    order, dk = [], []
    step = max(1, int(2e7 // len(scene["xyz"])))  # rows per block (one block for the default scene)
    for i in range(0, len(anchors), step):
        d = np.linalg.norm(anchors[i:i + step, None, :] - scene["xyz"][None, :, :], axis=2)
        order.append(np.argsort(d, axis=1)[:, :N_OFF])
        dk.append(np.take_along_axis(d, order[-1], 1))
    order = np.concatenate(order)
    on = np.concatenate(dk) < 2.5 * voxel
    on[:, 0] = True  # every anchor came from at least one point
    return order, on


def pick_dynamic(anchors, scene, order):
    """Dynamic anchors: those whose nearest Gaussian has the label with the anchor count nearest
    20 % of all anchors (a whole labelled object)."""
    lab = scene["label"][order[:, 0]]
    counts = np.bincount(lab, minlength=scene["label"].max() + 1)
    counts[0] = -10 ** 9  # 0 = unlabelled
    cat = int(np.argmin(np.abs(counts - 0.2 * len(anchors))))
    return lab == cat, cat


def motion(tau, centre, ext):
    """GENERATED smooth rigid motion of the dynamic object at global time tau (GOP units: GOP g,
    local frame k -> tau = g + k/60): rotation about the world y axis through its centre, angle
    0.35*sin(pi*tau/2), and translation ext*(0.10*sin(pi*tau/2), 0.05*(1-cos(pi*tau)), 0)."""
    th = 0.35 * math.sin(math.pi * tau / 2)
    c, s = math.cos(th), math.sin(th)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    T = ext * np.array([0.10 * math.sin(math.pi * tau / 2), 0.05 * (1 - math.cos(math.pi * tau)), 0.0])
    return R, centre - R @ centre + T


def ring_cameras(centre, radius, n, y_off):
    out = []
    for i in range(n):
        a = 2 * math.pi * (i + 0.5) / n
        out.append(centre + np.array([radius * math.cos(a), y_off, radius * math.sin(a)]))
    return np.array(out)


# =====================================================================================
# the reference's quantisation and entropy model
# =====================================================================================
def quantize_anchor(a, bmin, bmax):
    """Quantize_anchor (float32 torch ops as on the GPU)."""
    interval = (bmax - bmin) * Q_ANCHOR + 1e-6
    q = torch.div(a - bmin, interval, rounding_mode="floor").clamp(0, 2 ** 16 - 1)
    return q * interval + bmin, q


def dequantize_anchor(q_u16, bmin, bmax):
    """conduct_decoding_from_files: int32 q * interval + x_bound_min."""
    interval = (bmax - bmin) * Q_ANCHOR + 1e-6
    return torch.from_numpy(q_u16.astype(np.int32)) * interval + bmin


def context(model, a_hat, bmin, bmax):
    """calc_interp_feat + mlp_grid split + adaptive Q, per anchor."""
    x = (a_hat - bmin) / (bmax - bmin)
    out = model.mlp_grid(model.encoding_xyz(x))
    mean, scale, mean_s, scale_s, mean_o, scale_o, qf, qs, qo = torch.split(
        out, [FEAT_DIM, FEAT_DIM, 6, 6, 3 * N_OFF, 3 * N_OFF, 1, 1, 1], dim=-1)
    return dict(feat=(mean, scale, Q_BASE["feat"] * (1 + torch.tanh(qf))),
                scaling=(mean_s, scale_s, Q_BASE["scaling"] * (1 + torch.tanh(qs))),
                offsets=(mean_o, scale_o, Q_BASE["offsets"] * (1 + torch.tanh(qo))))


def gaussian_bits(x, mean, scale, Q):
    """Entropy_gaussian: -log2(max(|Phi(x+Q/2) - Phi(x-Q/2)|, 1e-6)), scale clamped at 1e-9."""
    scale = scale.clamp(min=1e-9)
    dist = torch.distributions.Normal(mean, scale)
    p = torch.abs(dist.cdf(x + 0.5 * Q) - dist.cdf(x - 0.5 * Q)).clamp(min=1e-6)
    return -torch.log2(p)


def binary_bits(bits01):
    """get_binary_vxl_size: sum of -log2 p over the bits with one scalar p, plus 32."""
    p = (bits01.sum() / bits01.numel()).clamp(1e-6, 1 - 1e-6)
    return -(bits01.sum() * torch.log2(p) + (bits01.numel() - bits01.sum()) * torch.log2(1 - p)) + 32


def ste_multistep(x, Q, mean):
    """STE_multistep (utils/encodings.py): clamp to mean +- 15000 Q, round(x/Q)*Q."""
    x = torch.clamp(x, min=mean - 15000 * Q, max=mean + 15000 * Q)
    return torch.round(x / Q) * Q


# =====================================================================================
# neural Gaussian generation (torch, float32) and the fitting loss
# =====================================================================================
def time_lookup(t):
    """get_time_features: t = int(timestamp*60); t_idx = t//10; delta = (t%10)/10."""
    f = int(t * TIME_LINE)
    return f // INTERVAL, (f % INTERVAL) / INTERVAL


def deform(model, tfeat, a_hat_dyn, bmin, bmax, t_idx, delta):
    lip = tfeat[:, t_idx] * (1 - delta) + tfeat[:, t_idx + 1] * delta
    norm = (a_hat_dyn - bmin) / (bmax - bmin)
    return (model.mlp_deform_xyz(torch.cat([lip, norm], 1)), model.mlp_deform_cov(lip),
            model.mlp_deform_opacity(lip).reshape(-1, N_OFF, 3), model.mlp_deform_color(lip))


def generate(model, a_hat, feat, offsets, scaling, cam, dyn_def=None, n_static=None):
    """generate_neural_gaussians without the mask: per child [N,10,...]."""
    anchor = a_hat
    view = anchor - cam
    dist = view.norm(dim=1, keepdim=True)
    view = view / dist
    if dyn_def is not None:
        da, df, do, ds = dyn_def
        s = n_static
        anchor = torch.cat([anchor[:s], anchor[s:] + da], 0)
        feat = torch.cat([feat[:s], feat[s:] + df], 0)
        offsets = torch.cat([offsets[:s], offsets[s:] + do], 0)
        scaling = torch.cat([scaling[:s], scaling[s:] + ds], 0)
    x = torch.cat([feat, view, dist], 1)
    n = x.shape[0]
    op = model.mlp_opacity(x).reshape(n, N_OFF, 2)
    col = model.mlp_color(x).reshape(n, N_OFF, 3)
    cov = model.mlp_cov(x).reshape(n, N_OFF, 7)
    lang = model.mlp_language(x).reshape(n, N_OFF, 9)
    es = torch.exp(scaling)
    xyz = anchor[:, None, :] + offsets * es[:, None, :3]
    sc = es[:, None, 3:] * torch.sigmoid(cov[..., :3])
    rot = cov[..., 3:7]
    return dict(xyz=xyz, opacity=op, color=col, scaling=sc, rot=rot, lang=lang)


def child_loss(g, tgt, voxel, w_app=1.0):
    """Per-child attribute loss (not a rendering loss): for 'on' slots, squared position error in
    voxel units, L1 colour, squared error of colour opacity vs the Gaussian's alpha and of the
    language opacity vs alpha (labelled) or -0.2 (unlabelled), squared log-scale error,
    1-|<q,q_t>|, squared language error; for 'off' slots squared error of colour opacity vs -0.5."""
    on = tgt["on"]
    pos = ((g["xyz"] - tgt["xyz"]) / voxel).pow(2).sum(-1)
    col = (g["color"] - tgt["rgb"]).abs().sum(-1)
    opc = (g["opacity"][..., 0] - tgt["alpha"]).pow(2)
    opl = (g["opacity"][..., 1] - tgt["alpha_l"]).pow(2)
    scl = (torch.log(g["scaling"] + 1e-12) - torch.log(tgt["scale"])).pow(2).sum(-1)
    q = g["rot"] / (g["rot"].norm(dim=-1, keepdim=True) + 1e-12)
    rot = 1 - (q * tgt["rot"]).sum(-1).abs()
    lang = (g["lang"] - tgt["lang"]).pow(2).sum(-1)
    off = (g["opacity"][..., 0] + 0.5).pow(2)
    per = pos + w_app * (col + 2 * opc + opl + 0.1 * scl + 0.5 * rot + 0.3 * lang)
    parts = {"pos_vox2": pos[on].mean().item(), "col_l1": col[on].mean().item() / 3,
             "opacity": opc[on].mean().item(), "off": off[~on].mean().item() if (~on).any() else 0.0}
    return torch.where(on, per, 2 * off).mean(), parts


def targets(scene, order, on, sel=None, R=None, T=None, rgb_mul=None, pull=None, anchors=None):
    xyz = scene["xyz"][order]
    if pull is not None:  # GOP-1 change: children move towards their anchor
        xyz = np.where(pull[:, None, None], anchors[:, None, :] + 0.85 * (xyz - anchors[:, None, :]), xyz)
    if R is not None:
        moved = (xyz @ R.T) + T
        xyz = np.where(sel[:, None, None], moved, xyz)
    rgb = scene["rgb"][order]
    if rgb_mul is not None:
        rgb = np.where(pull[:, None, None], np.clip(rgb * rgb_mul, 0, 1), rgb)
    lab = scene["label"][order]
    t = dict(xyz=xyz, rgb=rgb, alpha=scene["alpha"][order], alpha_l=np.where(lab > 0, scene["alpha"][order], -0.2),
             scale=scene["scale"][order], rot=scene["rot"][order], lang=scene["lang"][order])
    t = {k: torch.tensor(v, dtype=torch.float32) for k, v in t.items()}
    t["on"] = torch.tensor(on)
    return t


# =====================================================================================
# the reference's coder, on torchac
# =====================================================================================
def gaussian_cdf_table(mean, scale, Q, mn, mx):
    """calculate_cdf_kernel: cdf[i][j] = (float)(0.5 * erfcf(-(x - mu) / (max(sigma,1e-9) * sqrtf(2))))
    with x = (float)((double)(mn + j - 0.5) * (double)Q_i), j = 0..mx-mn+1 (Lp = mx-mn+2)."""
    j = torch.arange(mx - mn + 2, dtype=torch.float64)
    x = ((mn + j - 0.5)[None, :] * Q.double()[:, None]).float()
    s = torch.clamp(scale.double(), min=1e-9).float()
    z = -(x - mean[:, None]) / (s * np.float32(math.sqrt(2.0)))[:, None]
    return (0.5 * torch.special.erfc(z)).float()


def int_cdf(cdf):
    """arithmetic_kernel.cu: c(s) = __float2int_rn(cdf[s] * (float)(65536 - (Lp-1))) + s (uint16)."""
    lp = cdf.shape[1]
    v = torch.round(cdf * torch.tensor(float(65536 - (lp - 1)), dtype=torch.float32)).to(torch.int64)
    v = v + torch.arange(lp)[None, :]
    return (v & 0xFFFF).to(torch.int32).numpy().astype(np.uint16).view(np.int16)


def encode_chunks(sym, cdf):
    """One independent torchac stream per 10,000 symbols (chunk_size_cuda)."""
    cdf_i = torch.from_numpy(int_cdf(cdf))
    out, cnt = [], []
    for c in range(0, sym.shape[0], CHUNK):
        b = torchac.encode_int16_normalized_cdf(cdf_i[c:c + CHUNK], sym[c:c + CHUNK])
        assert b == torchac.encode_float_cdf(cdf[c:c + CHUNK], sym[c:c + CHUNK]), "torchac float rule differs"
        out.append(b)
        cnt.append(len(b))
    return b"".join(out), np.array(cnt, dtype=np.int32)


def decode_chunks(cdf, payload, cnt):
    syms, pos = [], 0
    for k, c in enumerate(range(0, cdf.shape[0], CHUNK)):
        syms.append(torchac.decode_float_cdf(cdf[c:c + CHUNK], payload[pos:pos + int(cnt[k])]))
        pos += int(cnt[k])
    return torch.cat(syms)


def write_gaussian_b(path, x, mean, scale, Q):
    """encoder_gaussian: xi = round(x/Q); symbols xi - min (int16); header min,max f32."""
    xi = torch.round(x / Q)
    mn, mx = int(xi.min().item()), int(xi.max().item())
    sym = (xi - mn).to(torch.int16)
    payload, cnt = encode_chunks(sym, gaussian_cdf_table(mean, scale, Q, mn, mx))
    cb = cnt.tobytes()
    with open(path, "wb") as f:
        f.write(np.float32(mn).tobytes() + np.float32(mx).tobytes() + np.array([len(cb)], np.int32).tobytes() + cb + payload)
    return sym


def read_gaussian_b(path, mean, scale, Q):
    raw = open(path, "rb").read()
    mn, mx = np.frombuffer(raw[:8], np.float32)
    nb = int(np.frombuffer(raw[8:12], np.int32)[0])
    cnt = np.frombuffer(raw[12:12 + nb], np.int32)
    sym = decode_chunks(gaussian_cdf_table(mean, scale, Q, int(mn), int(mx)), raw[12 + nb:], cnt)
    x = (sym.float() + torch.tensor(mn)) * Q
    return x, sym


def binary_cdf(p, n):
    pu = 1 - torch.full((n, 1), float(p), dtype=torch.float32)
    return torch.cat([torch.zeros_like(pu), pu, torch.ones_like(pu)], 1)


def write_binary_b(path, pm1):
    """encoder_cuda: bits = (v+1)/2; p = mean(bits) f32; CDF [0, 1-p, 1]; header p f32."""
    bits = ((pm1.reshape(-1) + 1) / 2).float()
    p = bits.sum() / bits.numel()
    sym = torch.floor(bits).to(torch.int16)
    payload, cnt = encode_chunks(sym, binary_cdf(p.item(), bits.numel()))
    cb = cnt.tobytes()
    with open(path, "wb") as f:
        f.write(np.float32(p.item()).tobytes() + np.array([len(cb)], np.int32).tobytes() + cb + payload)
    return sym


def read_binary_b(path, n):
    raw = open(path, "rb").read()
    p = np.frombuffer(raw[:4], np.float32)[0]
    nb = int(np.frombuffer(raw[4:8], np.int32)[0])
    cnt = np.frombuffer(raw[8:8 + nb], np.int32)
    sym = decode_chunks(binary_cdf(p, n), raw[8 + nb:], cnt)
    return sym.float() * 2 - 1, sym


# =====================================================================================
# time features: tiles, PNGs, video (compress_attr / frame_maker / decompress_attr_hac)
# =====================================================================================
def write_time_features(tfeat, out):
    """_temporal_feat: side = ceil(sqrt(Nd)), zero padded; channel c at block (c//4, c%4);
    one scalar min/max over all 7 tiles (incl. padding); uint16(trunc((x-min)/(max-min)*65535))
    with float32 arithmetic; cv2.imwrite PNG level 0; then the reference's ffmpeg command."""
    fdir = os.path.join(out, "feat_images")
    os.makedirs(fdir, exist_ok=True)
    nd = tfeat.shape[0]
    side = math.ceil(math.sqrt(nd))
    frames = []
    for k in range(KEYS):
        pad = np.zeros((side * side, TF_DIM), np.float32)
        pad[:nd] = tfeat[:, k]
        img = pad.reshape(side, side, TF_DIM)
        fr = np.zeros((side * 4, side * 4, 1), np.float32)
        for c in range(TF_DIM):
            fr[(c // 4) * side:(c // 4 + 1) * side, (c % 4) * side:(c % 4 + 1) * side, 0] = img[:, :, c]
        frames.append(fr)
    st = np.concatenate(frames)
    lo, hi = np.min(st), np.max(st)
    for k, fr in enumerate(frames):
        norm = (fr.clip(lo, hi) - lo) / (hi - lo)
        cv2.imwrite(os.path.join(fdir, f"_temporal_feat_{k}.png"), (norm * 65535).astype("uint16"),
                    [cv2.IMWRITE_PNG_COMPRESSION, 0])
    subprocess.run(f"ffmpeg -y -loglevel error -framerate 30 -i {fdir}/_temporal_feat_%d.png -c:v libx265 "
                   f"-pix_fmt gray12le -color_range pc -crf {QP} {out}/_temporal_feat.mp4", shell=True, check=True)
    return lo, hi


def read_time_features(out, nd):
    """decompress_attr_hac: ffmpeg -> gray16be PNGs, cv2 /65535 (float64) * (max-min) + min with the
    CSV's min/max (float64), untile, float32, truncate to N_dynamic."""
    info = pd.read_csv(os.path.join(out, "compression_info.csv"), index_col=0)
    lo, hi = float(info.loc["_temporal_feat", "min"]), float(info.loc["_temporal_feat", "max"])
    tmp = os.path.join(out, "feat_images")
    subprocess.run(f"ffmpeg -y -loglevel error -i {out}/_temporal_feat.mp4 -start_number 0 -pix_fmt gray16be "
                   f"{tmp}/_temporal_feat_%d_out.png", shell=True, check=True)
    feats = None
    for k in range(KEYS):
        f = os.path.join(tmp, f"_temporal_feat_{k}_out.png")
        img = cv2.imread(f, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) / 65535
        img = img * (hi - lo) + lo
        os.remove(f)
        side = img.shape[0] // 4
        if feats is None:
            feats = np.zeros((side * side, KEYS, TF_DIM), np.float32)
        for c in range(TF_DIM):
            feats[:, k, c] = img[(c // 4) * side:(c // 4 + 1) * side, (c % 4) * side:(c % 4 + 1) * side].reshape(-1)
    return feats[:nd], lo, hi


def write_csv(out, lo, hi):
    pd.DataFrame([{"_temporal_feat": lo}, {"_temporal_feat": hi}, {"_temporal_feat": f"_temporal_feat_{KEYS - 1}.png"}],
                 index=["min", "max", "file"]).T.to_csv(os.path.join(out, "compression_info.csv"))


# =====================================================================================
# fitting
# =====================================================================================
def fit_canonical(model, P, tg, cams, bmin, bmax, steps, log):
    """GOP 0 canonical stage: features/offsets/scalings + decoding MLPs + context model, with HAC's
    noise quantisation x + U(-1/2,1/2) Q(context) and the rate lambda*(bits/param + bits_hash/(N*86))."""
    params = [P["feat"], P["offsets"], P["scaling"]]
    opt = torch.optim.Adam([
        {"params": params, "lr": 5e-3},
        {"params": list(model.mlp_opacity.parameters()) + list(model.mlp_color.parameters())
         + list(model.mlp_cov.parameters()) + list(model.mlp_language.parameters()), "lr": 4e-3},
        {"params": list(model.mlp_grid.parameters()), "lr": 4e-3},
        {"params": list(model.encoding_xyz.parameters()), "lr": 5e-3},
    ], eps=1e-15)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: 0.05 ** (i / steps))
    lam = 0.02
    a_hat = P["a_hat"]
    n = a_hat.shape[0]
    t0 = time.time()
    for it in range(steps):
        ctx = context(model, a_hat, bmin, bmax)
        noisy, bits, cnt = {}, 0.0, 0
        for name in ("feat", "scaling", "offsets"):
            x = P[name].reshape(n, -1)
            mean, scale, Q = ctx[name]
            xn = x + (torch.rand_like(x) - 0.5) * Q
            b = gaussian_bits(xn, mean, scale, Q)
            bits, cnt = bits + b.sum(), cnt + b.numel()
            noisy[name] = xn
        hb = binary_bits((STEBinary.apply(model.encoding_xyz.binary_params()) + 1) / 2)
        cam = cams[it % len(cams)]
        g = generate(model, a_hat, noisy["feat"], noisy["offsets"].reshape(n, N_OFF, 3), noisy["scaling"], cam)
        dist, parts = child_loss(g, tg, P["voxel"])
        rate = bits / cnt + hb / (n * 86)
        loss = dist + lam * rate + 0.01 * torch.exp(P["scaling"]).prod(1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if it % max(1, steps // 8) == 0 or it == steps - 1:
            log(f"  canonical {it:5d} dist {dist.item():.4f} {parts} bits/param {(bits / cnt).item():.3f} "
                f"hash bits {hb.item():.0f} ({time.time() - t0:.0f} s)")
    return dist.item(), (bits / cnt).item(), hb.item()


def frames_for_gop(g):
    """Training frames of GOP g: local k = 0..59 (t = k/60) plus k = 60 as t_idx 5, delta 1."""
    return [(k // INTERVAL, (k % INTERVAL) / INTERVAL, g + k / 60) for k in range(60)] + [(5, 1.0, g + 1.0)]


def fit_motion(model, tfeat, D, tgs_fn, cams, bmin, bmax, g, steps, log, ntc_fn=None):
    """Per GOP: time features + the 4 deform MLPs (and in GOP 1 the NTC) to the generated motion."""
    deform_params = (list(model.mlp_deform_xyz.parameters()) + list(model.mlp_deform_cov.parameters())
                     + list(model.mlp_deform_opacity.parameters()) + list(model.mlp_deform_color.parameters()))
    groups = [{"params": [tfeat], "lr": 1e-2}, {"params": deform_params, "lr": 2e-3}]
    if ntc_fn is not None:
        groups += ntc_fn["groups"]
    opt = torch.optim.Adam(groups, eps=1e-15)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: 0.03 ** (i / steps))
    frames = frames_for_gop(g)
    s = D["n_static"]
    t0 = time.time()
    for it in range(steps):
        t_idx, delta, tau = frames[it % len(frames)] if it < len(frames) else frames[np.random.randint(len(frames))]
        feat, offsets = D["feat"], D["offsets"]
        extra = 0.0
        if ntc_fn is not None:
            d_feat, d_off, rate = ntc_fn["apply"]()
            feat, offsets = feat + d_feat, offsets + d_off
            extra = ntc_fn["lam"] * rate
        dd = deform(model, tfeat, D["a_hat"][s:], bmin, bmax, t_idx, delta)
        gen = generate(model, D["a_hat"], feat, offsets, D["scaling"], cams[it % len(cams)], dd, s)
        dist, parts = child_loss(gen, tgs_fn(tau), D["voxel"])
        loss = dist + extra + 1e-3 * tfeat.pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if it % max(1, steps // 6) == 0 or it == steps - 1:
            log(f"  gop{g} motion {it:5d} dist {dist.item():.4f} {parts} ({time.time() - t0:.0f} s)")
    return dist.item()


# =====================================================================================
# float64 NumPy evaluation of §5.2 (independent of the torch code above)
# =====================================================================================
def np_mlp(sd, x, act=None):
    h = x @ sd["0.weight"].T + (sd["0.bias"] if "0.bias" in sd else 0.0)
    h = np.maximum(h, 0.0)
    y = h @ sd["2.weight"].T + (sd["2.bias"] if "2.bias" in sd else 0.0)
    if act == "tanh":
        y = np.tanh(y)
    elif act == "sigmoid":
        y = 1.0 / (1.0 + np.exp(-y))
    return y


def neural_f64(W, a, feat, offsets, scaling, tfeat, n_static, bmin, bmax, t, cam):
    f = int(t * TIME_LINE)
    t_idx, delta = f // INTERVAL, (f % INTERVAL) / INTERVAL
    lip = tfeat[:, t_idx] * (1 - delta) + tfeat[:, t_idx + 1] * delta
    ad = a[n_static:]
    norm = (ad - bmin) / (bmax - bmin)
    view = a - cam  # pre-deformation anchor
    dist = np.sqrt((view ** 2).sum(1, keepdims=True))
    view = view / dist
    anchor = a.copy()
    anchor[n_static:] += np_mlp(W["mlp_deform_xyz"], np.concatenate([lip, norm], 1))
    feat = feat.copy()
    feat[n_static:] += np_mlp(W["mlp_deform_cov"], lip)
    offsets = offsets.copy()
    offsets[n_static:] += np_mlp(W["mlp_deform_opacity"], lip).reshape(-1, N_OFF, 3)
    scaling = scaling.copy()
    scaling[n_static:] += np_mlp(W["mlp_deform_color"], lip)
    x = np.concatenate([feat, view, dist], 1)
    n = x.shape[0]
    op = np_mlp(W["mlp_opacity"], x, "tanh").reshape(n * N_OFF, 2)
    col = np_mlp(W["mlp_color"], x, "sigmoid").reshape(n * N_OFF, 3)
    cov = np_mlp(W["mlp_cov"], x).reshape(n * N_OFF, 7)
    lang = np_mlp(W["mlp_language"], x).reshape(n * N_OFF, 9)
    es = np.exp(scaling)
    es_r = np.repeat(es, N_OFF, axis=0)
    an_r = np.repeat(anchor, N_OFF, axis=0)
    mask = op[:, 0] > 0
    sc = es_r[:, 3:] * (1.0 / (1.0 + np.exp(-cov[:, :3])))
    xyz = an_r + offsets.reshape(-1, 3) * es_r[:, :3]
    rot = cov[:, 3:7] / np.maximum(np.sqrt((cov[:, 3:7] ** 2).sum(1, keepdims=True)), 1e-12)
    return dict(mask=mask.astype(np.uint8), xyz=xyz[mask], color=col[mask], opacity=op[mask], scaling=sc[mask],
                rot=rot[mask], language=lang[mask], anchor_deformed=anchor, feat_deformed=feat,
                offsets_deformed=offsets, scaling_deformed=scaling), (t_idx, delta)


# =====================================================================================
def sd_np(m):
    return {k: v.detach().double().numpy() for k, v in m.state_dict().items()}


def main(root):
    t_start = time.time()
    os.makedirs(root, exist_ok=True)
    logf = open(os.path.join(root, "fit_log.txt") if os.path.isdir(root) else os.devnull, "w")

    def log(s):
        print(s, flush=True)
        logf.write(s + "\n")

    torch.manual_seed(SEED)
    np.random.seed(SEED)
    rng = np.random.default_rng(SEED)
    scene = load_scene(rng)
    anchors, voxel = voxelise(scene["xyz"], rng)
    order, on = assign_targets(anchors, scene, voxel)
    dyn, dyn_label = pick_dynamic(anchors, scene, order)
    # hybrid model: static anchors first, then dynamic
    perm = np.concatenate([np.where(~dyn)[0], np.where(dyn)[0]])
    anchors, order, on, dyn = anchors[perm], order[perm], on[perm], dyn[perm]
    n, ns = len(anchors), int((~dyn).sum())
    nd = n - ns
    log(f"anchors {n} (static {ns}, dynamic {nd}, label {dyn_label}), voxel {voxel:.6f}, children on {on.sum()}")
    centre = scene["xyz"].mean(0)
    ext = float(np.ptp(scene["xyz"], 0).max())
    obj_centre = anchors[ns:].mean(0)
    cams_train = ring_cameras(centre, 1.6 * ext, 8, 0.5 * ext)
    cams_eval = ring_cameras(centre, 1.9 * ext, 3, 0.7 * ext)
    cams_t = [torch.tensor(c, dtype=torch.float32) for c in cams_train]

    # bounds from the static anchors (update_anchor_bound); quantised anchors of all anchors
    a32 = torch.tensor(anchors, dtype=torch.float32)
    bmin = a32[:ns].min(0, keepdim=True)[0]
    bmax = a32[:ns].max(0, keepdim=True)[0]
    a_hat, q = quantize_anchor(a32, bmin, bmax)

    model = Model()
    # mlp_grid's output biases start at the data's scale (not HAC's default init): mean_scaling at
    # the initial log-scale and the sigmas at 0.5, so that no likelihood starts below the 1e-6 floor,
    # where the reference's rate loss has no gradient.
    with torch.no_grad():
        bias = model.mlp_grid[2].bias
        o = np.cumsum([0, FEAT_DIM, FEAT_DIM, 6, 6, 3 * N_OFF, 3 * N_OFF])
        bias[o[1]:o[2]] += 0.5
        bias[o[2]:o[3]] += math.log(voxel)
        bias[o[3]:o[4]] += 0.5
        bias[o[5]:o[6]] += 0.5
    # Scaffold-GS initialisation: offsets 0, features 0, scaling log(voxel) (we use small noise)
    P = {"feat": nn.Parameter(0.1 * torch.randn(n, FEAT_DIM)),
         "offsets": nn.Parameter(0.1 * torch.randn(n, N_OFF, 3)),
         "scaling": nn.Parameter(torch.full((n, 6), math.log(voxel))),
         "a_hat": a_hat, "voxel": float(voxel)}
    tg0 = targets(scene, order, on)
    steps_c = 60 if FAST else 1100
    log("fit canonical (GOP 0)")
    t0 = time.time()
    dist_c, bpp, hbits = fit_canonical(model, P, tg0, cams_t, bmin, bmax, steps_c, log)
    fit_times = {"canonical_s": round(time.time() - t0, 1)}

    # ------------------------------------------------------------ GOP 0 encode
    out0 = os.path.join(root, "gop0_fixture", "compression", "best")
    png0, bs0 = os.path.join(out0, "png_quant"), os.path.join(out0, "bitstreams")
    os.makedirs(png0, exist_ok=True)
    os.makedirs(bs0, exist_ok=True)
    with torch.no_grad():
        feat_all, off_all, sc_all = P["feat"].detach(), P["offsets"].detach(), P["scaling"].detach()
        np.save(os.path.join(bs0, "anchor.npy"), q.numpy().astype(np.uint16))
        hash_pm1 = STEBinary.apply(model.encoding_xyz.binary_params())
        quant = {"feat": [], "scaling": [], "offsets": []}
        means_enc = {"feat": [], "scaling": [], "offsets": []}
        for s in range(math.ceil(n / BATCH)):
            sl = slice(s * BATCH, min((s + 1) * BATCH, n))
            ctx = context(model, a_hat[sl], bmin, bmax)
            for name, full in (("feat", feat_all), ("scaling", sc_all), ("offsets", off_all)):
                mean, scale, Q = ctx[name]
                k = mean.shape[1]
                Qr = Q.repeat(1, k).reshape(-1)
                x = ste_multistep(full[sl].reshape(-1), Qr, full.mean())
                write_gaussian_b(os.path.join(bs0, f"{name}_{s}_0.b"), x, mean.reshape(-1),
                                 torch.clamp(scale.reshape(-1), min=1e-9), Qr)
                quant[name].append(x.reshape(sl.stop - sl.start, -1))
        write_binary_b(os.path.join(bs0, "hash.b"), hash_pm1)
        np.save(os.path.join(bs0, "patched_infos.npy"),
                np.asarray([ns, n, n, BATCH, bmax.numpy(), bmin.numpy()], dtype=object))

    # ------------------------------------------------------------ GOP 0 decode (from the files)
    def decode_gop0():
        pi = np.load(os.path.join(bs0, "patched_infos.npy"), allow_pickle=True)
        n_s, n_full, n_all, mb, xmax, xmin = pi
        xmax, xmin = torch.from_numpy(xmax).float(), torch.from_numpy(xmin).float()
        a_dec = dequantize_anchor(np.load(os.path.join(bs0, "anchor.npy")), xmin, xmax)
        dec_model = Model()
        dec_model.load_state_dict(model.state_dict())
        nh = model.encoding_xyz.binary_params().numel()
        hpm1, hsym = read_binary_b(os.path.join(bs0, "hash.b"), nh)
        assert torch.equal(hsym, ((hash_pm1.reshape(-1) + 1) / 2).to(torch.int16)), "hash.b round trip"
        hpm1 = hpm1.reshape(-1, N_FEAT_LEVEL)
        e = dec_model.encoding_xyz
        l3, l2 = e.encoding_xyz.params.shape[0], e.encoding_xy.params.shape[0]
        for i, grid in enumerate((e.encoding_xyz, e.encoding_xy, e.encoding_xz, e.encoding_yz)):
            start = 0 if i == 0 else l3 + (i - 1) * l2
            grid.params = nn.Parameter(hpm1[start:start + grid.params.shape[0]].clone())
        res = {k: [] for k in ("feat", "scaling", "offsets", "Q_feat", "Q_scaling", "Q_offsets",
                               "mean_feat", "scale_feat", "mean_scaling", "scale_scaling", "mean_offsets", "scale_offsets")}
        for s in range(math.ceil(n_all / mb)):
            sl = slice(s * mb, min((s + 1) * mb, n_all))
            m = sl.stop - sl.start
            ctx = context(dec_model, a_dec[sl], xmin, xmax)
            for name in ("feat", "scaling", "offsets"):
                mean, scale, Q = ctx[name]
                k = mean.shape[1]
                Qr = Q.repeat(1, k).reshape(-1)
                x, sym = read_gaussian_b(os.path.join(bs0, f"{name}_{s}_0.b"), mean.reshape(-1),
                                         torch.clamp(scale.reshape(-1), min=1e-9), Qr)
                assert torch.equal(x.reshape(m, -1), quant[name][s]), f"{name}_{s} round trip"
                res[name].append(x.reshape(m, -1))
                res["Q_" + name].append(Q.reshape(m))
                res["mean_" + name].append(mean)
                res["scale_" + name].append(scale)
        r = {k: torch.cat(v) for k, v in res.items()}
        r["offsets"] = r["offsets"].reshape(n_all, N_OFF, 3)
        r["anchor"] = a_dec
        r["hash_pm1"] = hpm1
        return r, dec_model

    with torch.no_grad():
        dec0, dec_model = decode_gop0()
    log(f"GOP 0 bitstreams decoded back: all symbols equal; anchors {n}")

    # ------------------------------------------------------------ GOP 0 motion
    D = {"a_hat": dec0["anchor"], "feat": dec0["feat"], "offsets": dec0["offsets"], "scaling": dec0["scaling"],
         "n_static": ns, "voxel": float(voxel)}
    for p in model.parameters():
        p.requires_grad_(False)
    model.load_state_dict(dec_model.state_dict())

    def motion_targets(tau, extra=None):
        R, T = motion(tau, obj_centre, ext)
        return targets(scene, order, on, sel=dyn, R=R, T=T, **(extra or {}))

    def deform_trainable():
        for m in (model.mlp_deform_xyz, model.mlp_deform_cov, model.mlp_deform_opacity, model.mlp_deform_color):
            for p in m.parameters():
                p.requires_grad_(True)

    cache = {}

    def tg_cached(tau, extra_key=None, extra=None):
        key = (round(tau, 6), extra_key)
        if key not in cache:
            cache[key] = motion_targets(tau, extra)
        return cache[key]

    deform_trainable()
    tfeat0 = nn.Parameter(0.1 * torch.randn(nd, KEYS, TF_DIM))
    steps_m = 60 if FAST else 1500
    log("fit motion (GOP 0)")
    t0 = time.time()
    dist_m0 = fit_motion(model, tfeat0, D, lambda tau: tg_cached(tau), cams_t, bmin, bmax, 0, steps_m, log)
    fit_times["gop0_motion_s"] = round(time.time() - t0, 1)

    with torch.no_grad():
        write_csv(png0, *write_time_features(tfeat0.detach().numpy(), png0))
    deform0 = {k: OrderedDict((kk, vv.clone()) for kk, vv in getattr(model, k).state_dict().items())
               for k in ("mlp_deform_xyz", "mlp_deform_cov", "mlp_deform_color", "mlp_deform_opacity")}

    def mlps_dict(with_ntc=None):
        d = OrderedDict([("x_bound_min", bmin.clone()), ("x_bound_max", bmax.clone())])
        for k in ("mlp_deform_xyz", "mlp_deform_cov", "mlp_deform_color", "mlp_deform_opacity", "mlp_language"):
            d[k] = getattr(model, k).state_dict()
        if with_ntc is not None:
            d["ntc_mlp"] = with_ntc.state_dict()
        else:
            for k in ("mlp_opacity", "mlp_cov", "mlp_color", "mlp_grid"):
                d[k] = getattr(model, k).state_dict()
        return d

    def model_pth(train_vals, tfeat, ntc=None, ntc_mlp=None, extra=None):
        """GaussianModel.save: state_dict without 'mlp' keys (parameters first, then
        encoding_xyz.* [and ntc.*] submodule tensors), then the nested MLP dicts."""
        sd = OrderedDict()
        for suf, sl in (("", slice(0, ns)), ("_dynamic", slice(ns, n))):
            sd["_anchor" + suf] = train_vals["anchor"][sl].clone()
            sd["_offset" + suf] = train_vals["offsets"][sl].clone()
            sd["_anchor_feat" + suf] = train_vals["feat"][sl].clone()
            sd["_scaling" + suf] = train_vals["scaling"][sl].clone()
            sd["_rotation" + suf] = torch.tensor([[1.0, 0, 0, 0]]).repeat(sl.stop - sl.start, 1)
            sd["_opacity" + suf] = torch.full((sl.stop - sl.start, 1), math.log(0.1 / 0.9))
        sd["_temporal_feat"] = torch.tensor(tfeat)
        # raw grid parameters are stored as their binarised value (+-1, = STE_binary(x)), not the
        # trained floats, so that the file compresses (see README); one storage per tensor, shared
        # by the flat keys and the nested dict as torch.save does for a state_dict.
        enc = OrderedDict((k, STEBinary.apply(v) if k.endswith("params") else v)
                          for k, v in model.encoding_xyz.state_dict().items())
        for k, v in enc.items():
            sd["encoding_xyz." + k] = v
        if ntc is not None:
            for k, v in ntc.state_dict().items():
                sd["ntc." + k] = STEBinary.apply(v) if k.endswith("params") else v
        for k in ("mlp_opacity", "mlp_cov", "mlp_color"):
            sd[k] = getattr(model, k).state_dict()
        sd["encoding_xyz"] = enc
        sd["mlp_grid"] = model.mlp_grid.state_dict()
        sd["x_bound_min"], sd["x_bound_max"] = bmin.clone(), bmax.clone()
        for k in ("mlp_deform_xyz", "mlp_deform_cov", "mlp_deform_color", "mlp_deform_opacity", "mlp_language"):
            sd[k] = getattr(model, k).state_dict()
        if ntc_mlp is not None:
            sd["ntc_mlp"] = ntc_mlp.state_dict()
            sd.update(extra)
        return sd

    train0 = {"anchor": a32, "offsets": off_all, "feat": feat_all, "scaling": sc_all}
    torch.save(mlps_dict(), os.path.join(png0, "mlps.pth"))
    if WRITE_MODEL_PTH:
        torch.save(model_pth(train0, tfeat0.detach().numpy()), os.path.join(png0, "model.pth"))
    tf0_dec, lo0, hi0 = read_time_features(png0, nd)

    # ------------------------------------------------------------ GOP 1: NTC + new motion
    log("fit GOP 1 (NTC + motion)")
    torch.manual_seed(SEED + 1)
    ntc, ntc_mlp = NTC(), mlp(48, 2 * FEAT_DIM, FEAT_DIM + 3 * N_OFF)
    with torch.no_grad():
        ntc_mlp[2].weight.mul_(0.1)
        ntc_mlp[2].bias.zero_()
    change = np.zeros(n, bool)
    lab0 = scene["label"][order[:, 0]]
    counts = np.bincount(lab0[:ns], minlength=scene["label"].max() + 1)
    counts[0] = 0
    counts[dyn_label] = 0
    change_label = int(np.argmax(counts))
    change[:ns] = lab0[:ns] == change_label  # a static object changes colour and shape in GOP 1
    log(f"  GOP-1 change: static label {change_label}, {change.sum()} anchors")
    xn = (D["a_hat"] - bmin) / (bmax - bmin)
    in_dom = ((xn >= 0) & (xn <= 1)).all(1)

    def ntc_apply(ntc_, mlp_, with_rate=True):
        d_feat = torch.zeros(n, FEAT_DIM)
        d_off = torch.zeros(n, N_OFF * 3)
        h = ntc_(xn[in_dom])
        o = mlp_(h)
        d_feat = d_feat.index_put((torch.where(in_dom)[0],), o[:, :FEAT_DIM])
        d_off = d_off.index_put((torch.where(in_dom)[0],), o[:, FEAT_DIM:])
        rate = None
        if with_rate:
            b2 = (STEBinary.apply(torch.cat([ntc_.encoding_xy.params, ntc_.encoding_xz.params,
                                              ntc_.encoding_yz.params], 0)) + 1) / 2
            rate = binary_bits(b2) / (n * 80)
        return d_feat, d_off.reshape(n, N_OFF, 3), rate

    ntc_spec = {"groups": [{"params": list(ntc.parameters()), "lr": 1e-2}, {"params": list(ntc_mlp.parameters()), "lr": 1e-3}],
                "apply": lambda: ntc_apply(ntc, ntc_mlp), "lam": 0.02}
    extra1 = {"rgb_mul": np.array([1.25, 0.8, 0.8]), "pull": change, "anchors": anchors}
    model.new_deform()  # deform MLPs: warm start from GOP 0 (the reference re-trains them per GOP)
    for k, v in deform0.items():
        getattr(model, k).load_state_dict(v)
    deform_trainable()
    tfeat1 = nn.Parameter(torch.tensor(tf0_dec[:, KEYS - 1:KEYS].repeat(KEYS, 1)) + 0.05 * torch.randn(nd, KEYS, TF_DIM))
    steps_1 = 60 if FAST else 1200
    t0 = time.time()
    dist_m1 = fit_motion(model, tfeat1, D, lambda tau: tg_cached(tau, "g1", extra1), cams_t, bmin, bmax, 1,
                         steps_1, log, ntc_spec)
    fit_times["gop1_ntc_motion_s"] = round(time.time() - t0, 1)

    out1 = os.path.join(root, "gop1_fixture", "compression", "best")
    png1, bs1 = os.path.join(out1, "png_quant"), os.path.join(out1, "bitstreams")
    os.makedirs(png1, exist_ok=True)
    os.makedirs(bs1, exist_ok=True)
    with torch.no_grad():
        ntc2d_pm1 = STEBinary.apply(torch.cat([ntc.encoding_xy.params, ntc.encoding_xz.params, ntc.encoding_yz.params], 0))
        ntc3d_pm1 = STEBinary.apply(ntc.encoding_xyz.params)
        write_binary_b(os.path.join(bs1, "ntc_2D.b"), ntc2d_pm1)
        write_binary_b(os.path.join(bs1, "ntc_3D.b"), ntc3d_pm1)
        write_csv(png1, *write_time_features(tfeat1.detach().numpy(), png1))
        torch.save(mlps_dict(with_ntc=ntc_mlp), os.path.join(png1, "mlps.pth"))
        d_feat, d_off, _ = ntc_apply(ntc, ntc_mlp, with_rate=False)
        extra = OrderedDict([("d_feat", d_feat[:ns]), ("d_offsets", d_off[:ns]), ("d_feat_dynamic", d_feat[ns:]),
                             ("d_offsets_dynamic", d_off[ns:]), ("feat", D["feat"][:ns] + d_feat[:ns]),
                             ("offsets", D["offsets"][:ns] + d_off[:ns]), ("feat_dynamic", D["feat"][ns:] + d_feat[ns:]),
                             ("offsets_dynamic", D["offsets"][ns:] + d_off[ns:])])
        train1 = {"anchor": D["a_hat"], "offsets": D["offsets"], "feat": D["feat"], "scaling": D["scaling"]}
        if WRITE_MODEL_PTH:
            torch.save(model_pth(train1, tfeat1.detach().numpy(), ntc, ntc_mlp, extra), os.path.join(png1, "model.pth"))

        # decode GOP 1 from its files (+ GOP 0's decode)
        ntc_d = NTC()
        p2, s2 = read_binary_b(os.path.join(bs1, "ntc_2D.b"), ntc2d_pm1.numel())
        p3, s3 = read_binary_b(os.path.join(bs1, "ntc_3D.b"), ntc3d_pm1.numel())
        assert torch.equal(s2, ((ntc2d_pm1.reshape(-1) + 1) / 2).to(torch.int16)), "ntc_2D.b round trip"
        assert torch.equal(s3, ((ntc3d_pm1.reshape(-1) + 1) / 2).to(torch.int16)), "ntc_3D.b round trip"
        p2 = p2.reshape(-1, N_FEAT_LEVEL)  # view(-1, n_features_per_level)
        l2 = ntc_d.encoding_xy.params.shape[0]
        ntc_d.encoding_xy.params = nn.Parameter(p2[:l2].clone())
        ntc_d.encoding_xz.params = nn.Parameter(p2[l2:2 * l2].clone())
        ntc_d.encoding_yz.params = nn.Parameter(p2[2 * l2:].clone())
        ntc_d.encoding_xyz.params = nn.Parameter(p3.reshape(-1, 1).clone())
        m1 = torch.load(os.path.join(png1, "mlps.pth"), weights_only=True)
        ntc_mlp_d = mlp(48, 2 * FEAT_DIM, FEAT_DIM + 3 * N_OFF)
        ntc_mlp_d.load_state_dict(m1["ntc_mlp"])
        dfd, dod, _ = ntc_apply(ntc_d, ntc_mlp_d, with_rate=False)
        tf1_dec, lo1, hi1 = read_time_features(png1, nd)
    log("GOP 1 bitstreams decoded back: all symbols equal")
    with torch.no_grad():  # what the NTC does: colour error of the changed anchors' children at t = 0
        tg = tg_cached(1.0, "g1", extra1)
        dd = deform(model, torch.from_numpy(tf1_dec), D["a_hat"][ns:], bmin, bmax, 0, 0.0)
        ntc_eval = {}
        for name, (df, do) in (("without_ntc", (0, 0)), ("with_ntc", (dfd, dod))):
            gen = generate(model, D["a_hat"], D["feat"] + df, D["offsets"] + do, D["scaling"], cams_t[0], dd, ns)
            sel = torch.tensor(change)[:, None] & tg["on"]
            ntc_eval[name] = {"col_l1": ((gen["color"] - tg["rgb"]).abs().mean(-1))[sel].mean().item(),
                              "pos_vox2": (((gen["xyz"] - tg["xyz"]) / voxel).pow(2).sum(-1))[sel].mean().item()}
        log(f"  changed anchors at GOP-1 t=0: {ntc_eval}")

    # ------------------------------------------------------------ reference_decode/*.safetensors
    ddir = os.path.join(root, "reference_decode")
    os.makedirs(ddir, exist_ok=True)
    g0 = {"anchor": dec0["anchor"], "feat": dec0["feat"], "scaling": dec0["scaling"], "offsets": dec0["offsets"],
          "anchor_quantized": torch.from_numpy(np.load(os.path.join(bs0, "anchor.npy")).astype(np.int32)),
          "x_bound_min": bmin, "x_bound_max": bmax,
          "hash_bits_packed": torch.from_numpy(np.packbits(((dec0["hash_pm1"].reshape(-1) + 1) / 2).to(torch.uint8).numpy())),
          "temporal_feat": torch.from_numpy(tf0_dec)}
    for k in ("Q_feat", "Q_scaling", "Q_offsets", "mean_feat", "scale_feat", "mean_scaling", "scale_scaling",
              "mean_offsets", "scale_offsets"):
        g0[k] = dec0[k]
    save_file({k: v.contiguous().float() if v.dtype == torch.float64 else v.contiguous() for k, v in g0.items()},
              os.path.join(ddir, "gop0.safetensors"),
              metadata={"n_static": str(ns), "n_anchor": str(n), "temporal_feat_min": repr(lo0), "temporal_feat_max": repr(hi0)})
    g1 = {"d_feat": dfd, "d_offsets": dod, "feat": dec0["feat"] + dfd, "offsets": dec0["offsets"] + dod,
          "ntc_2D_bits_packed": torch.from_numpy(np.packbits(((p2.reshape(-1) + 1) / 2).to(torch.uint8).numpy())),
          "ntc_3D_bits_packed": torch.from_numpy(np.packbits(((p3.reshape(-1) + 1) / 2).to(torch.uint8).numpy())),
          "temporal_feat": torch.from_numpy(tf1_dec)}
    save_file({k: v.contiguous() for k, v in g1.items()}, os.path.join(ddir, "gop1.safetensors"),
              metadata={"n_static": str(ns), "n_anchor": str(n), "temporal_feat_min": repr(lo1), "temporal_feat_max": repr(hi1)})

    # ------------------------------------------------------------ neural_f64 + cameras.json
    m0 = torch.load(os.path.join(png0, "mlps.pth"), weights_only=True)
    W0 = {k: {kk: vv.double().numpy() for kk, vv in v.items()} for k, v in m0.items() if k.startswith("mlp_")}
    W1 = dict(W0)
    W1.update({k: {kk: vv.double().numpy() for kk, vv in v.items()} for k, v in m1.items() if k.startswith("mlp_")})
    times = [0.0, 25.5 / 60, 59 / 60]
    out64, meta, full = {}, {}, {}
    sub = np.arange(0, n, SUBSET_STEP)
    sub_mask = np.zeros(n, bool)
    sub_mask[sub] = True
    out64["subset_anchor_index"] = sub.astype(np.int64)
    a64 = dec0["anchor"].double().numpy()
    bmin64, bmax64 = bmin.double().numpy(), bmax.double().numpy()
    for g, (W, feat, offs, tfd) in enumerate(((W0, dec0["feat"], dec0["offsets"], tf0_dec),
                                              (W1, dec0["feat"] + dfd, dec0["offsets"] + dod, tf1_dec))):
        for ti, t in enumerate(times):
            for ci, cam in enumerate(cams_eval):
                r, (t_idx, delta) = neural_f64(W, a64, feat.double().numpy(), offs.double().numpy(),
                                               dec0["scaling"].double().numpy(), tfd.astype(np.float64), ns,
                                               bmin64, bmax64, t, cam)
                meta[f"g{g}_t{ti}"] = json.dumps({"t": t, "t_idx": t_idx, "delta": delta})
                full[(g, ti, ci)] = r
                # children of the subset anchors, in anchor-major order (only kept children)
                kept = r["mask"].reshape(n, N_OFF).astype(bool)
                child_rows = np.cumsum(r["mask"]) - 1
                rows = child_rows[(kept & sub_mask[:, None]).reshape(-1)]
                for k in ("xyz", "color", "opacity", "scaling", "rot", "language"):
                    out64[f"g{g}_t{ti}_c{ci}_{k}"] = np.ascontiguousarray(r[k][rows])
                out64[f"g{g}_t{ti}_c{ci}_mask"] = r["mask"]
                if ci == 0:
                    out64[f"g{g}_t{ti}_anchor_deformed_dynamic"] = np.ascontiguousarray(r["anchor_deformed"][ns:])
                    for k in ("feat_deformed", "offsets_deformed", "scaling_deformed"):
                        out64[f"g{g}_t{ti}_{k}"] = np.ascontiguousarray(r[k][sub])
    save_np(out64, os.path.join(ddir, "neural_f64.safetensors"), metadata=meta)
    cam_json = []
    for i, c in enumerate(cams_eval):
        fwd = centre - c
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, np.array([0.0, -1.0, 0.0]))
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        c2w = np.stack([right, down, fwd], 1)  # columns: camera x, y, z axes in world (OpenCV/COLMAP)
        cam_json.append({"id": i, "img_name": f"eval_cam{i:02d}", "width": 800, "height": 600,
                         "position": c.tolist(), "rotation": [list(r) for r in c2w.tolist()], "fy": 700.0, "fx": 700.0})
    json.dump(cam_json, open(os.path.join(ddir, "cameras.json"), "w"), indent=1)

    # sanity check: the float32 torch generator on the same decoded GOP-1 inputs agrees with float64
    with torch.no_grad():
        t_idx, delta = time_lookup(times[1])
        dd = deform(model, torch.from_numpy(tf1_dec), dec0["anchor"][ns:], bmin, bmax, t_idx, delta)
        gen = generate(model, dec0["anchor"], dec0["feat"] + dfd, dec0["offsets"] + dod, dec0["scaling"],
                       torch.tensor(cams_eval[0], dtype=torch.float32), dd, ns)
        mask32 = (gen["opacity"][..., 0] > 0).reshape(-1).numpy()
        m64 = full[(1, 1, 0)]["mask"].astype(bool)
        same = mask32 == m64
        both = mask32 & m64
        x32 = gen["xyz"].reshape(-1, 3).numpy()[both]
        x64 = full[(1, 1, 0)]["xyz"][both[m64]]
        log(f"f32 torch vs f64 numpy (GOP 1, t={times[1]:.4f}, cam 0): mask agree {same.mean():.6f}, "
            f"max |xyz diff| {np.abs(x32 - x64).max():.3e}")
    sizes = {}
    for d in (out0, out1, ddir):
        for dp, _, fs in os.walk(d):
            for f in fs:
                sizes[os.path.relpath(os.path.join(dp, f), root)] = os.path.getsize(os.path.join(dp, f))
    total = time.time() - t_start
    prov = {
        "what": "FITTED DLGStream hac (Scaffold-GS + HAC) fixture in the reference layout (scripts/scaffold_fixture.py)",
        "scene": ("supersplat_fruit_drops_minimal_4721_sh3.ply (MIT, PlayCanvas) + its per-Gaussian labels"
                  if not os.environ.get("DLGS_FIXTURE_SCENE") and "DLGS_FIXTURE_LABELS" not in os.environ
                  else os.path.basename(SCENE) + (" + labels " + os.path.basename(LABELS) if LABELS else " (no labels)")),
        "generated": "language code per label, choice of dynamic object, its rigid motion, GOP-1 colour/shape change"
                     + ("" if LABELS else "; labels = 1 + octant of the Gaussian centre about the per-axis median"),
        "fitted": "features/offsets/scalings, decoding MLPs, context model (mlp_grid + binary hash grids), "
                  "time features, deform MLPs, NTC",
        "versions": {"torch": torch.__version__, "numpy": np.__version__, "pandas": pd.__version__,
                     "torchac": "0.9.3", "opencv": cv2.__version__,
                     "ffmpeg": subprocess.run(["ffmpeg", "-version"], capture_output=True, text=True).stdout.split("\n")[0]},
        "seed": SEED, "qp": QP, "fast": FAST,
        "voxel_size": voxel, "n_anchor": n, "n_static": ns, "n_dynamic": nd, "dynamic_label": dyn_label,
        "gop1_change_label": change_label, "gop1_changed_anchors": int(change.sum()),
        "fit": {"canonical_dist": dist_c, "canonical_bits_per_param_noisy": bpp, "hash_bits_estimate": hbits,
                "gop0_motion_dist": dist_m0, "gop1_dist": dist_m1, "gop1_changed_anchors_t0": ntc_eval, "seconds": fit_times, "script_seconds": round(total, 1)},
        "eval_times": times, "sizes_bytes": sizes,
    }
    json.dump(prov, open(os.path.join(root, "PROVENANCE.json"), "w"), indent=1)
    log(f"wrote {root} in {total:.0f} s")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tests/fixtures/scaffold_run")
