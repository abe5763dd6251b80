"""Golden values for the SOG reader, from splat-transform's own decoder.

Usage: python3 scripts/sog_golden.py NAME SCENE.sog > entry.json
Runs `npx @playcanvas/splat-transform@2.7.1 SCENE.sog OUT.ply`, reads the PLY and prints, in the
order of dlgs's in-memory model (positions, log-scales, w-first rotations, opacity logits, SH
coefficient-major with RGB inside), the count, SH degree, the SHA-256 of every float as
little-endian f32 and the full values of 8 Gaussians spread over the file. tests/tests/interop.rs
checks `dlgs::interop::sog::read_sog` against these (tests/fixtures/sog_goldens.json).
"""

import hashlib
import json
import subprocess
import sys
import tempfile

import numpy as np


def read_ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    assert "format binary_little_endian 1.0" in header, "binary little-endian PLY expected"
    count, props = 0, []
    for line in header:
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            count = int(parts[2])
        elif parts[:2] == ["property", "float"]:
            props.append(parts[2])
    rows = np.frombuffer(data[end:], dtype="<f4", count=count * len(props)).reshape(count, len(props))
    return {name: rows[:, i] for i, name in enumerate(props)}, count


def model_arrays(cols, n):
    rest = sorted((k for k in cols if k.startswith("f_rest_")), key=lambda k: int(k[7:]))
    k = 1 + len(rest) // 3
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[k]
    sh = np.zeros((n, k, 3), dtype="<f4")
    for ch in range(3):
        sh[:, 0, ch] = cols[f"f_dc_{ch}"]
        for coef in range(1, k):
            sh[:, coef, ch] = cols[f"f_rest_{ch * (k - 1) + coef - 1}"]
    arrays = {
        "positions": np.stack([cols[a] for a in "xyz"], 1),
        "log_scales": np.stack([cols[f"scale_{a}"] for a in range(3)], 1),
        "rotations": np.stack([cols[f"rot_{a}"] for a in range(4)], 1),
        "opacity": cols["opacity"],
        "sh": sh.reshape(n, k * 3),
    }
    return {k: np.ascontiguousarray(v, dtype="<f4") for k, v in arrays.items()}, degree


def main():
    name, sog = sys.argv[1], sys.argv[2]
    with tempfile.TemporaryDirectory() as tmp:
        out = f"{tmp}/decoded.ply"
        subprocess.run(
            ["npx", "-y", "@playcanvas/splat-transform@2.7.1", "-q", sog, out], check=True
        )
        cols, n = read_ply(out)
    arrays, degree = model_arrays(cols, n)
    digest = hashlib.sha256()
    for key in ["positions", "log_scales", "rotations", "opacity", "sh"]:
        digest.update(arrays[key].tobytes())
    samples = sorted({round(i * (n - 1) / 7) for i in range(8)})
    print(
        json.dumps(
            {
                "name": name,
                "decoder": "@playcanvas/splat-transform 2.7.1",
                "count": n,
                "sh_degree": degree,
                "sha256_f32": digest.hexdigest(),
                "samples": {
                    str(i): {k: np.atleast_1d(v[i]).astype(float).tolist() for k, v in arrays.items()}
                    for i in samples
                },
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
