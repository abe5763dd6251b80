#!/usr/bin/env python3
"""Probe (docs/benchmarks/canonical-probes.md "Probes toward half of SPZ (2026-11-26, not kept)"): does a position grid shifted
by a fraction of a step break depth ties the same way on every set of views?

Quantises only the positions of an INRIA PLY (float properties only) at BITS per axis on a grid
whose origin is shifted by (dx, dy, dz) steps, every other attribute exact, and prints the mean
PSNR of `dlgs compare` on four view sets for each shift.
Usage: python3 experiments/canonical/position_offset_probe.py SCENE.ply [BITS]   (needs numpy and a release build)
"""
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

SHIFTS = [(0, 0, 0), (0.5, 0.5, 0.5), (0.25, 0.75, 0.5), (0.75, 0.25, 0.25),
          (0.5, 0, 0.25), (0, 0.5, 0.75), (0.25, 0.25, 0), (0.75, 0.75, 0.75)]
VIEW_SETS = [("benchmark orbit, 32 views", ["--orbit", "32"]),
             ("up x, 16", ["--orbit", "16", "--up", "x"]),
             ("up z, 16", ["--orbit", "16", "--up", "z"]),
             ("distance 2.5, 16", ["--orbit", "16", "--distance", "2.5"])]
DLGS = os.path.join(os.path.dirname(__file__), "..", "..", "target", "release", "dlgs")


def read_ply(path):
    raw = open(path, "rb").read()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode()
    props = [l.split() for l in header.splitlines() if l.startswith("property")]
    if any(p[1] != "float" for p in props) or [p[2] for p in props[:3]] != ["x", "y", "z"]:
        sys.exit(f"{path}: expected float properties starting with x, y, z")
    n = int(next(l for l in header.splitlines() if l.startswith("element vertex")).split()[-1])
    rows = np.frombuffer(raw[end:end + n * 4 * len(props)], dtype="<f4").reshape(n, len(props))
    return header, rows.copy()


def quantise(rows, bits, shift):
    out = rows.copy()
    top = (1 << bits) - 1
    for axis, d in enumerate(shift):
        x = rows[:, axis].astype(np.float64)
        lo, hi = x.min(), x.max()
        step = (hi - lo) / (top - 1)  # one spare level so the shifted grid still covers [lo, hi]
        origin = lo - d * step
        out[:, axis] = (origin + np.clip(np.round((x - origin) / step), 0, top) * step).astype(np.float32)
    return out


def mean_psnr(a, b, view_args):
    res = subprocess.run([DLGS, "compare", a, b, *view_args, "--json"], check=True,
                         capture_output=True, text=True)
    return json.loads(res.stdout)["mean_psnr"]


def main():
    scene = sys.argv[1]
    bits = int(sys.argv[2]) if len(sys.argv) > 2 else 14
    header, rows = read_ply(scene)
    print("| shift | " + " | ".join(name for name, _ in VIEW_SETS) + " |")
    print("|---" * (len(VIEW_SETS) + 1) + "|")
    with tempfile.TemporaryDirectory() as tmp:
        for shift in SHIFTS:
            path = os.path.join(tmp, "shifted.ply")
            with open(path, "wb") as f:
                f.write(header.encode() + quantise(rows, bits, shift).astype("<f4").tobytes())
            cells = ["%.2f" % mean_psnr(scene, path, args) for _, args in VIEW_SETS]
            print("| %s | %s |" % (", ".join(str(v) for v in shift), " | ".join(cells)))


if __name__ == "__main__":
    main()
