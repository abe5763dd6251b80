#!/usr/bin/env python3
"""Probe (docs/benchmarks/canonical-probes.md "Probes toward half of SPZ (2026-11-26, later; not kept)"): would coarse rotations
(format-spec §6.5.6) save more if they followed a Gaussian's anisotropy instead of its size?

Turning a Gaussian by a small angle changes its ellipsoid by about the angle times the largest
difference of its scales (`s_max - s_min`), not its largest scale: a near-sphere turns freely.
For the drawn Gaussians (opacity >= 1/255) of an INRIA PLY, prints the mean shift `k` of §6.5.6
with `m = log(s_max)` (the format's) and with `m = log(s_max - s_min)`, the rotation bits the
second would save (one bit per halving in each of the three stored components), and quantiles
of the scale ratios (how many Gaussians are near spheres or spheroids).
Usage: python3 experiments/canonical/rotation_anisotropy_probe.py SCENE.ply POSITION_BITS ROTATION_BITS FACTOR
"""
import sys

import numpy as np

from position_offset_probe import read_ply

MAX_SHIFT = 4


def shifts(m, threshold):
    x = (threshold - m) * 1.44269504
    return np.where(x >= 1, np.minimum(np.floor(x), MAX_SHIFT), 0)


def main():
    scene = sys.argv[1]
    position_bits, rotation_bits, factor = int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    header, rows = read_ply(scene)
    names = [l.split()[2] for l in header.splitlines() if l.startswith("property")]
    col = {n: i for i, n in enumerate(names)}
    opacity = 1 / (1 + np.exp(-rows[:, col["opacity"]].astype(np.float64)))
    drawn = rows[opacity >= 1 / 255]
    log_scales = drawn[:, [col["scale_0"], col["scale_1"], col["scale_2"]]].astype(np.float64)
    positions = drawn[:, :3].astype(np.float64)
    # The reference encoder's threshold (§6.5.6, informative).
    step = ((positions.max(0) - positions.min(0)) / (2 ** position_bits - 1)).max()
    turn = 2 * np.sqrt(2) / (2 ** rotation_bits - 1)
    threshold = np.log(factor * step / turn)
    s = np.sort(np.exp(log_scales), 1)[:, ::-1]
    by_size = shifts(np.log(s[:, 0]), threshold)
    by_anisotropy = shifts(np.log(np.maximum(s[:, 0] - s[:, 2], 1e-30)), threshold)
    print("%d Gaussians: mean shift %.3f by size, %.3f by anisotropy: %.3f rotation bits per Gaussian"
          % (len(s), by_size.mean(), by_anisotropy.mean(), 3 * (by_anisotropy - by_size).mean()))
    q = [0.1, 0.25, 0.5, 0.75, 0.9]
    for name, r in [("s_mid/s_max", s[:, 1] / s[:, 0]), ("s_min/s_mid", s[:, 2] / s[:, 1]),
                    ("s_min/s_max", s[:, 2] / s[:, 0])]:
        print("%-12s quantiles %s: %s" % (name, q, np.quantile(r, q).round(3)))


if __name__ == "__main__":
    main()
