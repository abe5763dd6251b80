#!/usr/bin/env python3
"""Bytes per frame against mean PSNR for the real-motion table (docs/benchmarks/sequences.md).

Usage: scripts/sequence_plot.py RD_CSV OUT_SVG [PEERS_CSV]
RD_CSV is scripts/sequence_rd.sh's rd.csv; PEERS_CSV has the same columns (setting,
bytes_per_frame, mean_psnr_db, ...) for other codecs. Standard library only.
"""
import csv
import math
import sys


def rows(path):
    with open(path) as f:
        return [r for r in csv.DictReader(f) if r.get("mean_psnr_db")]


def main():
    ours = rows(sys.argv[1])
    peers = rows(sys.argv[3]) if len(sys.argv) > 3 else []
    pts = [(r["setting"], float(r["bytes_per_frame"]), float(r["mean_psnr_db"])) for r in ours + peers]
    w, h, m = 760, 460, 70
    xs = [math.log10(p[1]) for p in pts]
    ys = [p[2] for p in pts]
    x0, x1 = math.floor(min(xs) * 4) / 4, math.ceil(max(xs) * 4) / 4
    y0, y1 = math.floor(min(ys) / 5) * 5, math.ceil(max(ys) / 5) * 5
    sx = lambda v: m + (math.log10(v) - x0) / (x1 - x0) * (w - 2 * m)
    sy = lambda v: h - m - (v - y0) / (y1 - y0) * (h - 2 * m)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="11">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{m}" y1="{h-m}" x2="{w-m}" y2="{h-m}" stroke="black"/>',
           f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h-m}" stroke="black"/>']
    for d in range(int(math.floor(x0)), int(math.ceil(x1)) + 1):
        for k in (1, 2, 5):
            v = k * 10 ** d
            if 10 ** x0 <= v <= 10 ** x1:
                out.append(f'<line x1="{sx(v):.1f}" y1="{h-m}" x2="{sx(v):.1f}" y2="{m}" stroke="#ddd"/>')
                out.append(f'<text x="{sx(v):.1f}" y="{h-m+15}" text-anchor="middle">{v:,}</text>')
    y = y0
    while y <= y1:
        out.append(f'<line x1="{m}" y1="{sy(y):.1f}" x2="{w-m}" y2="{sy(y):.1f}" stroke="#ddd"/>')
        out.append(f'<text x="{m-6}" y="{sy(y)+4:.1f}" text-anchor="end">{y}</text>')
        y += 5
    out.append(f'<text x="{w/2}" y="{h-25}" text-anchor="middle">bytes per frame (log)</text>')
    out.append(f'<text x="18" y="{h/2}" transform="rotate(-90 18 {h/2})" text-anchor="middle">mean PSNR over the 200 source frames (dB)</text>')
    # One line through the crf settings of each residual kind: fields (`crfN_k10`, the
    # default) and intra GOPs (`crfN_k10_intra`, dashed).
    for suffix, dash in (("_k10", ""), ("_k10_intra", ' stroke-dasharray="5,4"')):
        crf = sorted([p for p in pts if p[0].endswith(suffix) and p[0].startswith("crf")], key=lambda p: p[1])
        if len(crf) > 1:
            path = " ".join(f"{sx(b):.1f},{sy(q):.1f}" for _, b, q in crf)
            out.append(f'<polyline points="{path}" fill="none" stroke="#1f77b4" stroke-width="2"{dash}/>')
    ours_names = {r["setting"] for r in ours}
    for name, b, q in pts:
        colour = "#1f77b4" if name in ours_names and not name.startswith("perframe") else "#d62728"
        out.append(f'<circle cx="{sx(b):.1f}" cy="{sy(q):.1f}" r="4" fill="{colour}"/>')
        out.append(f'<text x="{sx(b)+6:.1f}" y="{sy(q)-6:.1f}">{name}</text>')
    out.append("</svg>")
    open(sys.argv[2], "w").write("\n".join(out))


main()
