"""Lossless image coders beside dlgs's grid codecs on the same quantised grids (issue 5).

Reads the OUT_DIR written by `cargo run --release -p dlgs-encoder --example grid_candidates --
SCENE OUT_DIR` and prints one markdown row per attribute group: our stored bytes (best codec per
channel, as `dlgs encode` picks), the best of codecs 0-4 alone (format 1.8, before the adaptive
codec 5), zstd -19, PNG (level 9, 8- or
16-bit grey per channel), lossless WebP (level 100, method 6; 8-bit only, so channels over 8 bits
are split into a high-byte and a low-byte image as PlayCanvas SOG does for positions), lossless
WebP with the group's channels in one RGB(A) image (SOG's packing, cross-channel transforms
allowed), and lossless JPEG XL (effort 9, per channel and grouped).
Needs numpy and imagecodecs (PyPI). Usage: python3 experiments/canonical/grid_candidates.py OUT_DIR
"""

import json
import sys
from pathlib import Path

import imagecodecs
import numpy as np

GROUPS = [
    ("position", lambda n: n in ("x", "y", "z")),
    ("log-scale", lambda n: n.startswith("ls")),
    ("rotation", lambda n: n == "rot_index" or n in ("r0", "r1", "r2")),
    ("opacity", lambda n: n == "opacity"),
    ("SH DC", lambda n: n in ("sh0", "sh1", "sh2")),
    ("SH rest", lambda n: n.startswith("sh") and n not in ("sh0", "sh1", "sh2")),
]


def planes8(grid, bits):
    """8-bit planes of a grid: itself, or its high and low bytes."""
    if bits <= 8:
        return [grid.astype(np.uint8)]
    return [(grid >> 8).astype(np.uint8), (grid & 0xFF).astype(np.uint8)]


def webp(img):
    if img.ndim == 2:
        img = np.stack([img] * 3, axis=-1)
    return len(imagecodecs.webp_encode(img, level=100, lossless=True, method=6))


def png(grid, bits):
    img = grid.astype(np.uint8) if bits <= 8 else grid.astype(np.uint16)
    return len(imagecodecs.png_encode(img, level=9))


def jxl(img):
    return len(imagecodecs.jpegxl_encode(img, lossless=True, effort=9))


def jxl_grid(grid, bits):
    img = grid.astype(np.uint8) if bits <= 8 else grid.astype(np.uint16)
    return jxl(img)


def grouped(grids, bits, coder):
    """The group's channels as one RGB(A) image per 8-bit plane (or 16-bit for JPEG XL);
    a fourth channel only for four channels, two channels padded with a zero plane."""
    total = 0
    if coder == "jxl":
        chans = [g.astype(np.uint8 if bits <= 8 else np.uint16) for g in grids]
        for start in range(0, len(chans), 3):
            part = chans[start : start + 3]
            while len(part) == 2:
                part.append(np.zeros_like(part[0]))
            img = part[0] if len(part) == 1 else np.stack(part, axis=-1)
            total += jxl(img)
        return total
    per_plane = list(zip(*[planes8(g, bits) for g in grids]))
    for plane in per_plane:
        plane = list(plane)
        for start in range(0, len(plane), 4 if len(plane) == 4 else 3):
            part = plane[start : start + (4 if len(plane) == 4 else 3)]
            while 1 < len(part) < 3:
                part.append(np.zeros_like(part[0]))
            img = part[0] if len(part) == 1 else np.stack(part, axis=-1)
            total += webp(img)
    return total


def main():
    out = Path(sys.argv[1])
    m = json.loads((out / "manifest.json").read_text())
    w = m["width"]
    print(f"{m['scene']} ({m['n']} Gaussians, `{m['quality']}`, grid {w}x{w}), bytes:")
    print()
    print("| group | dlgs stored | dlgs codecs 0-4 | zstd -19 | PNG | WebP | WebP grouped | JPEG XL | JPEG XL grouped |")
    print("|---|---|---|---|---|---|---|---|---|")
    totals = np.zeros(8, dtype=np.int64)
    for name, member in GROUPS:
        chans = [c for c in m["channels"] if member(c["name"])]
        if not chans:
            continue
        grids = [
            np.fromfile(out / c["file"], dtype="<u2").reshape(w, w) for c in chans
        ]
        row = [
            sum(c["best"] for c in chans),
            sum(c["tabled"] for c in chans),
            sum(c["zstd19"] for c in chans),
            sum(png(g, c["bits"]) for g, c in zip(grids, chans)),
            sum(webp(p) for g, c in zip(grids, chans) for p in planes8(g, c["bits"])),
            0,
            sum(jxl_grid(g, c["bits"]) for g, c in zip(grids, chans)),
            0,
        ]
        # Grouping needs one bit depth; the rotation index (2 bits) goes on its own.
        by_bits = {}
        for g, c in zip(grids, chans):
            by_bits.setdefault(c["bits"], []).append(g)
        row[5] = sum(grouped(gs, b, "webp") for b, gs in by_bits.items())
        row[7] = sum(grouped(gs, b, "jxl") for b, gs in by_bits.items())
        totals += np.array(row)
        print(f"| {name} | " + " | ".join(f"{v:,}" for v in row) + " |")
    print("| **total** | " + " | ".join(f"**{v:,}**" for v in totals) + " |")
    best = totals[0]
    print()
    print(
        "relative to dlgs stored: "
        + ", ".join(
            f"{k} {100 * v / best:.0f} %"
            for k, v in zip(
                ["codecs 0-4", "zstd", "PNG", "WebP", "WebP grouped", "JPEG XL", "JPEG XL grouped"],
                totals[1:],
            )
        )
    )


if __name__ == "__main__":
    main()
