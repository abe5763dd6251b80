"""SOG-style palette (k-means codebook) for SH bands 1-3 beside dlgs's scalar SH rest (issue 5).

Usage: python sh_palette.py DLGS SOURCE DECODED_PLY SH0_BYTES OUT_PREFIX K[,K..]
       python sh_palette.py strip SOURCE OUT_PLY   (SOURCE without its SH bands 1-3)

DECODED_PLY is `dlgs decode` of the scene coded at some preset; SH0_BYTES the size of the same
scene coded at that preset with its SH bands 1-3 removed (everything but the bands). For each K
the bands of the decoded Gaussians are replaced by the nearest of K k-means centroids (scipy,
k-means++), written as OUT_PREFIX_K.ply and compared with SOURCE by `dlgs compare`. The printed
bytes are an estimate in the palette's favour: SH0_BYTES + the indices at their order-0 entropy
+ the codebook at one byte per value, uncompressed. Needs numpy and scipy.
"""

import json
import subprocess
import sys

import numpy as np
from scipy.cluster.vq import kmeans2


def read_ply(path):
    with open(path, "rb") as f:
        header, props, n = [], [], 0
        while True:
            line = f.readline()
            header.append(line)
            s = line.decode().strip()
            if s.startswith("element vertex"):
                n = int(s.split()[-1])
            if s.startswith("property"):
                props.append(s.split()[-1])
            if s == "end_header":
                break
        data = np.frombuffer(f.read(n * 4 * len(props)), dtype="<f4").reshape(n, len(props))
    return header, props, data.copy()


def psnr(dlgs, source, path):
    out = subprocess.run([dlgs, "compare", source, path, "--json"], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)["mean_psnr"]


def strip(source, out):
    header, props, d = read_ply(source)
    keep = [i for i, p in enumerate(props) if not p.startswith("f_rest_")]
    lines = [h for h in header if not h.decode().strip().startswith("property float f_rest_")]
    with open(out, "wb") as f:
        f.writelines(lines)
        f.write(np.ascontiguousarray(d[:, keep]).astype("<f4").tobytes())


def main():
    if sys.argv[1] == "strip":
        strip(sys.argv[2], sys.argv[3])
        return
    dlgs, source, decoded, sh0_bytes, prefix, ks = sys.argv[1:7]
    header, props, d = read_ply(decoded)
    rest = [i for i, p in enumerate(props) if p.startswith("f_rest_")]
    x = d[:, rest].astype(np.float64)
    n = len(d)
    print(f"decoded file as it is: PSNR {psnr(dlgs, source, decoded):.2f} dB")
    for k in (int(v) for v in ks.split(",")):
        centroids, idx = kmeans2(x, k, minit="++", iter=30, seed=1)
        e = d.copy()
        e[:, rest] = centroids[idx].astype(np.float32)
        out = f"{prefix}_{k}.ply"
        with open(out, "wb") as f:
            f.writelines(header)
            f.write(e.astype("<f4").tobytes())
        p = np.bincount(idx, minlength=k) / n
        p = p[p > 0]
        index_bytes = n * float(-(p * np.log2(p)).sum()) / 8
        codebook_bytes = k * len(rest)
        total = int(sh0_bytes) + index_bytes + codebook_bytes
        print(
            f"K={k}: indices {index_bytes:.0f} B + codebook {codebook_bytes} B + rest of the file {sh0_bytes} B"
            f" = {total:.0f} B; PSNR {psnr(dlgs, source, out):.2f} dB",
            flush=True,
        )


if __name__ == "__main__":
    main()
