"""Overhead of `Reader.frame(t)` over the Rust decoder's `frame_at(t)` on the same file, in
the same process and decoder (docs/benchmarks/python.md).

    python python/bench/frame_overhead.py MODEL.dlgs [REPEATS]

MODEL: the frame_at bench's model, e.g.
    dlgs synth ../shared/data/splat/marcelpadilla_plant.splat -o bench80k.dlgs \
        --dynamic-fraction 0.75 --max-dynamic 80000 --language --exact-features
Each row: median seconds per call over REPEATS x 30 times inside GOP 0 (no GOP decode in the
timed calls), interleaving the Rust baseline and the Python call per t so that machine noise
hits both alike.
"""

import statistics
import sys
import time

import dlgs

path = sys.argv[1]
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 5
r = dlgs.open(path)
info = r.info
gop_seconds = info["gop_length"] / info["fps"]
times = [gop_seconds * 0.95 * i / 30 for i in range(30)]
r.frame(0.0)  # decode GOP 0 once


def interleaved(language, split, keep=False):
    """Per t: the Rust call (timed inside Rust), then the Python call (timed here). Both
    exclude freeing the frame (Rust drops it after its clock stops; here after ours). With
    `keep` the last 3 frames stay referenced (so `frame` cannot decode into released arrays
    and allocates new ones); otherwise each frame is released before the next call."""
    rust, py, kept = [], [], []
    for t in times:
        rust += r.time_frame_at([t], language)
        t0 = time.perf_counter()
        res = r.frame(t, language=language, split=split)
        py.append(time.perf_counter() - t0)
        if keep:
            kept = kept[-2:] + [res]
        del res
    return rust, py


print(f"{path}: {info['n_static']} static + {info['n_dynamic']} dynamic, SH {info['sh_degree']}, "
      f"language {info['lang_width']}")
print("| what | Rust frame_at | Python frame(t) | overhead |")
print("|---|---|---|---|")
for language in (False, True):
    for split, keep in ((False, False), (False, True), (True, False)):
        rust, py = [], []
        for _ in range(repeats):
            a, b = interleaved(language, split, keep)
            rust += a
            py += b
        a, b = statistics.median(rust), statistics.median(py)
        what = ("colour" if language is False else "colour + language") + (
            ", split (static shared)" if split else
            ", merged, last 3 frames kept (new arrays)" if keep else
            ", merged, each frame released (its arrays decoded into again)")
        print(f"| {what} | {a * 1e3:.2f} ms | {b * 1e3:.2f} ms | {100 * (b / a - 1):+.1f} % |")
