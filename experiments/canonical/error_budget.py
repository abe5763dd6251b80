#!/usr/bin/env python3
"""Which attribute's quantisation costs how much PSNR in a lossy .dlgs file.

Usage: python3 experiments/canonical/error_budget.py SOURCE.ply CODED.dlgs [--views 8]
(needs numpy and scipy: `pip install numpy scipy`; builds nothing, runs target/release/dlgs).

Decodes CODED.dlgs to a PLY, matches every decoded Gaussian to its source Gaussian (nearest
position: the positions moved by under half a quantiser step), and writes hybrids: the decoded
scene with one attribute group put back to the source's values ("all but X quantised"), and with
every group but one put back ("only X quantised": the error of X alone). The groups are position,
shape, opacity and SH DC; SH bands above the DC stay as decoded in both. Scale
and rotation are one group (shape): the encoder may write a Gaussian's axes in another order
(`encoder/src/orientation.rs`), so one without the other is not the same ellipsoid. Prints the
PSNR of each over `dlgs compare`'s orbit views. Without a refit the "only X" errors add up to
about the whole file's; a refit moves values away from the nearest level on purpose, so its
file's budget is no longer separable.
"""
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.spatial import cKDTree

GROUPS = {
    "position": ["x", "y", "z"],
    "shape": ["scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"],
    "opacity": ["opacity"],
    "sh_dc": ["f_dc_0", "f_dc_1", "f_dc_2"],
}


def read_ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    if "format binary_little_endian 1.0" not in header:
        sys.exit(f"{path}: only binary little-endian PLYs")
    props = [line.split()[-1] for line in header if line.startswith("property")]
    if any(line.startswith("property") and line.split()[1] != "float" for line in header):
        sys.exit(f"{path}: only float properties")
    n = int(next(line for line in header if line.startswith("element vertex")).split()[-1])
    rows = np.frombuffer(data[end : end + n * 4 * len(props)], dtype="<f4")
    return data[:end], props, rows.reshape(n, len(props)).copy()


def psnr(dlgs, source, scene, views):
    out = subprocess.run(
        [dlgs, "compare", source, scene, "--orbit", str(views), "--json"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(out)["mean_psnr"]


def main():
    args = sys.argv[1:]
    views = 8
    if "--views" in args:
        i = args.index("--views")
        views = int(args[i + 1])
        del args[i : i + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    source, coded = args
    dlgs = os.path.join(os.path.dirname(__file__), "..", "..", "target", "release", "dlgs")
    with tempfile.TemporaryDirectory() as tmp:
        decoded = os.path.join(tmp, "decoded.ply")
        subprocess.run([dlgs, "decode", coded, "-o", decoded], check=True, capture_output=True)
        _, sp, src = read_ply(source)
        head, dp, dec = read_ply(decoded)
        s_ix = lambda names: [sp.index(p) for p in names]
        d_ix = lambda names: [dp.index(p) for p in names]
        dist, match = cKDTree(src[:, s_ix(GROUPS["position"])]).query(dec[:, d_ix(GROUPS["position"])])
        if len(set(match)) != len(match):
            sys.exit("two decoded Gaussians matched one source Gaussian: positions too coarse")
        src = src[match]
        print(f"{len(dec)} Gaussians matched (largest position move {dist.max():.3g})")
        print(f"decoded file: {psnr(dlgs, source, decoded, views):.2f} dB over {views} views")
        for name, props in GROUPS.items():
            only = dec.copy()
            for group, gprops in GROUPS.items():
                if group != name:
                    only[:, d_ix(gprops)] = src[:, s_ix(gprops)]
            exact = dec.copy()
            exact[:, d_ix(props)] = src[:, s_ix(props)]
            paths = []
            for tag, rows in (("only", only), ("exact", exact)):
                path = os.path.join(tmp, f"{tag}_{name}.ply")
                open(path, "wb").write(head + rows.astype("<f4").tobytes())
                paths.append(path)
            print(
                f"{name:9s} only it quantised: {psnr(dlgs, source, paths[0], views):6.2f} dB   "
                f"all but it quantised: {psnr(dlgs, source, paths[1], views):6.2f} dB"
            )


if __name__ == "__main__":
    main()
