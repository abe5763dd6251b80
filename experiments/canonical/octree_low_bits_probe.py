#!/usr/bin/env python3
"""Probe (docs/benchmarks/canonical-probes.md "Probes toward half of SPZ (2026-11-26, not kept)"): could a lone point's low position bits be predicted?

The octree (format-spec section 6.5.5) isolates each point after a few levels and codes the rest of
its bits as uniform symbols. This estimates what a model built from the points decoded before it
(the points earlier in Morton order: all of their bits are known when a lone point is decoded)
could save, with two density models truncated to the lone point's octree cell:
  - kernels: an isotropic Gaussian of width h steps around each of the K nearest earlier points;
  - plane: a plane fitted through the K nearest earlier points, the offset along its normal
    Gaussian (width a multiple of the neighbours' own spread), uniform within the plane;
each mixed with a uniform share eps over the cell. Cost: -log2 of the point's voxel's probability.
Exact duplicates (a voxel holding several points) are left out; the real coder counts them apart.

Usage: python3 experiments/canonical/octree_low_bits_probe.py SCENE.ply|SCENE.splat BITS [SAMPLE]
Needs numpy and scipy (pip install numpy scipy). About 30 s on a 45k scene.
"""
import sys

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erf

PLY_TYPES = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}


def read_positions(path):
    if path.endswith(".splat"):  # antimatter15: 32 bytes per Gaussian, position f32 x3 first
        raw = np.fromfile(path, dtype=np.uint8).reshape(-1, 32)
        return raw[:, :12].copy().view("<f4").reshape(-1, 3).astype(np.float64)
    with open(path, "rb") as f:
        props, n = [], 0
        while True:
            line = f.readline().decode().strip()
            if line.startswith("element vertex"):
                n = int(line.split()[2])
            elif line.startswith("property"):
                _, kind, name = line.split()
                props.append((name, PLY_TYPES[kind]))
            elif line == "end_header":
                break
        dt = np.dtype(props)
        a = np.frombuffer(f.read(n * dt.itemsize), dtype=dt, count=n)
    return np.stack([a["x"], a["y"], a["z"]], 1).astype(np.float64)


def morton_keys(q, bits):
    key = np.zeros(len(q), dtype=np.uint64)
    for level in range(bits - 1, -1, -1):
        d = ((q[:, 0] >> level) & 1) << 2 | ((q[:, 1] >> level) & 1) << 1 | ((q[:, 2] >> level) & 1)
        key = (key << np.uint64(3)) | d.astype(np.uint64)
    return key


def common_levels(a, b, bits):
    """Tree levels two Morton keys share."""
    x = a ^ b
    out = np.full(len(x), bits)
    nz = x != 0
    top = np.floor(np.log2(x[nz].astype(np.float64))).astype(int)
    out[nz] = bits - 1 - top // 3
    return out


def main():
    path, bits = sys.argv[1], int(sys.argv[2])
    sample = int(sys.argv[3]) if len(sys.argv) > 3 else 8000
    p = read_positions(path)
    lo, hi = p.min(0), p.max(0)
    q = np.round((p - lo) / np.where(hi > lo, hi - lo, 1) * (2**bits - 1)).astype(np.int64)
    key = morton_keys(q, bits)
    order = np.argsort(key, kind="stable")
    q, key = q[order], key[order]
    unique = np.ones(len(q), bool)
    unique[1:] = key[1:] != key[:-1]
    q, key = q[unique], key[unique]
    n = len(q)
    shared = np.zeros(n, int)
    shared[1:] = np.maximum(shared[1:], common_levels(key[1:], key[:-1], bits))
    shared[:-1] = np.maximum(shared[:-1], common_levels(key[:-1], key[1:], bits))
    low = bits - np.minimum(shared + 1, bits)  # low bits per axis under the lone node
    uniform = 3 * low
    _, near = cKDTree(q).query(q, k=48)
    rng = np.random.default_rng(0)
    picked = rng.choice(n, min(sample, n), replace=False)
    grid = (np.arange(8) + 0.5) / 8
    cell_samples = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)

    def cost(i, model, width, eps, k=12):
        if low[i] == 0:
            return 0.0
        earlier = [j for j in near[i] if j < i][:k]
        side = 2 ** low[i]
        corner = (q[i] >> low[i]) << low[i]
        if len(earlier) < 3:
            return float(uniform[i])
        c = q[earlier].astype(np.float64)
        x = q[i].astype(np.float64)
        if model == "kernels":
            dens = np.exp(-((c - x) ** 2).sum(1) / (2 * width**2)) / (2 * np.pi * width**2) ** 1.5
            lo_, hi_ = corner - 0.5, corner + side - 0.5
            s = np.sqrt(2) * width
            mass = np.prod(0.5 * (erf((hi_ - c) / s) - erf((lo_ - c) / s)), axis=1)
            share = (1 - eps) / len(c)
            return float(-np.log2((eps / side**3 + share * dens.sum()) / (eps + share * mass.sum())))
        mean = c.mean(0)
        w, v = np.linalg.eigh(np.cov((c - mean).T))
        normal = v[:, 0]
        sig = max(np.sqrt(max(w[0], 0.0)) * width, 0.5)

        def density(y):
            return np.exp(-(((y - mean) @ normal) ** 2) / (2 * sig * sig)) / (np.sqrt(2 * np.pi) * sig)

        z = density(cell_samples * side + corner - 0.5).mean() * side**3
        return float(-np.log2(eps / side**3 + (1 - eps) * density(x) / max(z, 1e-300)))

    print(f"{path}: {n} distinct points at {bits} bits, lone node depth {bits - low.mean():.2f} on average")
    print(f"uniform low bits (what the octree codes): {uniform[picked].mean():.2f} bits per point")
    for model, widths in (("kernels", (8.0, 32.0)), ("plane", (1.0, 2.0, 4.0))):
        for width in widths:
            for eps in (0.2, 0.5):
                mean = np.mean([cost(i, model, width, eps) for i in picked])
                print(f"{model:8s} width {width:5.1f} eps {eps}: {mean:.2f} bits per point")


if __name__ == "__main__":
    main()
