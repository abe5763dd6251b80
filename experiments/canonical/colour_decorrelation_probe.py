#!/usr/bin/env python3
"""Probe (docs/benchmarks/canonical.md "What half of SPZ would take"): how many bits per Gaussian would a
colour transform save on SH DC (and the same on log-scales)? Order-0 entropy estimates from an
INRIA PLY, each channel quantised to BITS on its own range (as the coder does), against:
the channels alone; each given the previous channel's top 2 or 4 bits (like codec 5's contexts);
G, R-G, B-G on one shared range; and the same with G's top 3 bits (and R-G) as context.
Model costs are ignored, so these are lower than what an adaptive coder reaches.
Usage: python3 experiments/canonical/colour_decorrelation_probe.py SCENE.ply:BITS [SCENE.ply:BITS ...]
"""
import sys

import numpy as np

from position_offset_probe import read_ply


def entropy(x):
    _, counts = np.unique(x, return_counts=True, axis=0)
    p = counts / counts.sum()
    return -(p * np.log2(p)).sum()


def conditional(x, context):
    return entropy(np.stack([x, context], 1)) - entropy(context)


def main():
    for arg in sys.argv[1:]:
        scene, bits = arg.rsplit(":", 1)
        bits = int(bits)
        header, rows = read_ply(scene)
        names = [l.split()[2] for l in header.splitlines() if l.startswith("property")]
        col = {n: i for i, n in enumerate(names)}
        for group, keys in [("sh_dc", ["f_dc_0", "f_dc_1", "f_dc_2"]),
                            ("log_scale", ["scale_0", "scale_1", "scale_2"])]:
            v = rows[:, [col[k] for k in keys]].astype(np.float64)
            top_level = 2 ** bits - 1
            own = np.round((v - v.min(0)) / (v.max(0) - v.min(0)) * top_level).astype(np.int64)
            shared = np.round((v - v.min()) / (v.max() - v.min()) * top_level).astype(np.int64)
            r, g, b = own.T
            R, G, B = shared.T

            def top(x, k):
                return x >> (bits - k)

            alone = entropy(r) + entropy(g) + entropy(b)
            prev2 = entropy(g) + conditional(r, top(g, 2)) + conditional(b, top(r, 2))
            prev4 = entropy(g) + conditional(r, top(g, 4)) + conditional(b, top(r, 4) * 16 + top(g, 4))
            diff = entropy(G) + entropy(R - G) + entropy(B - G)
            diff_ctx = (entropy(G) + conditional(R - G, top(G, 3))
                        + conditional(B - G, np.clip(R - G, -8, 8) + 100 * top(G, 3)))
            print(f"{scene.split('/')[-1]} {group} at {bits} bits, {len(r)} Gaussians, bits per Gaussian: "
                  f"alone {alone:.2f}, previous top 2 {prev2:.2f}, previous top 4 {prev4:.2f}, "
                  f"G,R-G,B-G {diff:.2f}, with context {diff_ctx:.2f}")


if __name__ == "__main__":
    main()
