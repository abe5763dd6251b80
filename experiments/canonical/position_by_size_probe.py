#!/usr/bin/env python3
"""Probe (docs/benchmarks/canonical-probes.md "Probes toward half of SPZ (2026-11-26, later; not kept)"): should a Gaussian's
position precision follow its size?

Quantises only the positions of an INRIA PLY (float properties only; every other attribute
exact) on the scene's min/max grid, with per-Gaussian bits per axis
`clip(round(BASE + A * (log2(s_max) - median log2(s_max))), 8, 18)`, `s_max` the largest scale:
A > 0 gives large Gaussians finer positions, A < 0 coarser, A = 0 is uniform at BASE bits.
Prints the mean bits over the drawn Gaussians (opacity >= 1/255) and the mean PSNR of
`dlgs compare` (the benchmark's orbit, ORBIT views, default 8).
Usage: ORBIT=32 python3 experiments/canonical/position_by_size_probe.py SCENE.ply BASE:A [BASE:A ...]
(needs numpy and a release build)
"""
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from position_offset_probe import DLGS, read_ply


def main():
    scene = sys.argv[1]
    header, rows = read_ply(scene)
    names = [l.split()[2] for l in header.splitlines() if l.startswith("property")]
    col = {n: i for i, n in enumerate(names)}
    log_scales = rows[:, [col["scale_0"], col["scale_1"], col["scale_2"]]].astype(np.float64)
    opacity = 1 / (1 + np.exp(-rows[:, col["opacity"]].astype(np.float64)))
    drawn = opacity >= 1 / 255
    size = log_scales.max(1) / np.log(2)  # log2 of the largest scale
    median = np.median(size[drawn])
    lo = rows[:, :3].min(0).astype(np.float64)
    hi = rows[:, :3].max(0).astype(np.float64)
    orbit = os.environ.get("ORBIT", "8")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "positions.ply")
        for spec in sys.argv[2:]:
            base, a = map(float, spec.split(":"))
            bits = np.clip(np.round(base + a * (size - median)), 8, 18)
            out = rows.copy()
            for axis in range(3):
                x = rows[:, axis].astype(np.float64)
                step = (hi[axis] - lo[axis]) / (2.0 ** bits - 1)
                out[:, axis] = (lo[axis] + np.round((x - lo[axis]) / step) * step).astype(np.float32)
            with open(path, "wb") as f:
                f.write(header.encode() + out.astype("<f4").tobytes())
            res = subprocess.run([DLGS, "compare", scene, path, "--orbit", orbit, "--json"],
                                 check=True, capture_output=True, text=True)
            print("BASE %g A %g: mean bits %.2f, PSNR %.2f dB on %s views"
                  % (base, a, bits[drawn].mean(), json.loads(res.stdout)["mean_psnr"], orbit),
                  flush=True)


if __name__ == "__main__":
    main()
