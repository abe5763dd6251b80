"""Measure: N frame decodes + renders (320x240) in one thread, against N/2 in each of two
threads. Every reader has one worker thread of its own (`threads=1`), so the two Python
threads are the only parallelism: with the GIL held the speed-up would be about 1.
Prints the times and the speed-up (tests/test_threads.py, docs/benchmarks/python.md)."""

import sys
import threading
import time

import dlgs

path = sys.argv[1]
N = int(sys.argv[2]) if len(sys.argv) > 2 else 24
readers = [dlgs.open(path, threads=1), dlgs.open(path, threads=1)]
cam = readers[0].cameras(count=1, width=320, height=240)[0]
times = [0.6 * i / N for i in range(N)]


def work(r, ts):
    for t in ts:
        r.frame(t, camera=cam, language=True)
        r.render(t, cam)


work(readers[0], times[:2])  # warm up (GOP decode)
work(readers[1], times[:2])
t0 = time.perf_counter()
work(readers[0], times)
serial = time.perf_counter() - t0
threads = [threading.Thread(target=work, args=(readers[i], times[i::2])) for i in range(2)]
t0 = time.perf_counter()
for th in threads:
    th.start()
for th in threads:
    th.join()
parallel = time.perf_counter() - t0
print(f"{N} frames+renders: one thread {serial:.3f} s, two threads {parallel:.3f} s, "
      f"speed-up {serial / parallel:.2f}")
