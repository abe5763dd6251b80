"""Long calls release the GIL: Python runs during them, and two threads decode at the same
time (the speed-up this gives: parallel_speedup.py, docs/benchmarks/python.md)."""

import os
import threading
import time

import dlgs


def test_python_runs_during_a_decode(dyn_exact):
    """While one thread is inside a long decode call, the main thread keeps running Python
    (with the GIL held it would not run until the call returned)."""
    r = dlgs.open(dyn_exact)
    r.frame(0.0)
    times = [0.6 * i / 400 for i in range(400)] * 5
    started = threading.Event()
    took = []

    def worker():
        started.set()
        t0 = time.perf_counter()
        r.time_frame_at(times, True)  # one call, about a second
        took.append(time.perf_counter() - t0)

    th = threading.Thread(target=worker)
    th.start()
    started.wait()
    time.sleep(0.05)  # the worker is inside the call by now
    n = 0
    while th.is_alive():
        n += 1
    th.join()
    print(f"main thread: {n} loop iterations during a {took[0]:.2f} s call")
    assert took[0] > 0.2 and n > 10_000


def test_two_threads_decode_at_the_same_time(dyn_exact):
    """Two threads, each with its own reader, are inside a decode call at the same time: each
    call reads a process-wide clock when it starts and ends decoding, with the GIL released.
    With the GIL held the second call could only start after the first returned (no overlap),
    whatever the load; on a busy machine the OS still interleaves the two threads, so the
    check does not depend on having both cores (the speed-up printed by
    parallel_speedup.py, in docs/benchmarks/python.md, does)."""
    readers = [dlgs.open(dyn_exact, threads=1) for _ in range(2)]
    for r in readers:
        r.frame(0.0)  # GOP 0 decoded: the calls below only decode frames
    times = [0.6 * i / 400 for i in range(400)]
    barrier = threading.Barrier(2)
    spans = [None, None]

    def work(i):
        barrier.wait()
        spans[i] = readers[i].time_frame_span(times, True)

    cpu0, wall0 = time.process_time(), time.perf_counter()
    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    (a0, a1, ta), (b0, b1, tb) = spans
    overlap = min(a1, b1) - max(a0, b0)
    shorter = min(a1 - a0, b1 - b0)
    print(f"calls {a1 - a0:.3f} s and {b1 - b0:.3f} s, overlapping {overlap:.3f} s; "
          f"process CPU {cpu:.3f} s in {wall:.3f} s wall (load {os.getloadavg()[0]:.1f})")
    assert len(ta) == len(tb) == len(times)
    assert shorter > 0.1, "calls too short to show anything"
    # Each call starts before the other ends, and they share most of their time.
    assert overlap > 0.5 * shorter, (spans[0][:2], spans[1][:2])


def test_one_reader_shared_by_threads(dyn_exact):
    """Threads sharing one reader take turns (no deadlock, the same results as one thread)."""
    r = dlgs.open(dyn_exact)
    times = [0.05 * i for i in range(24)]
    want = {t: r.render(t, 1, width=64, height=48) for t in times}
    got, errors = {}, []

    def work(ts):
        try:
            for t in ts:
                r.frame(t, camera=0, split=True)
                got[t] = r.render(t, 1, width=64, height=48)
        except Exception as e:  # surfaced below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(times[i::3],)) for i in range(3)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=120)
    assert not any(th.is_alive() for th in threads) and not errors
    for t in times:
        assert (got[t] == want[t]).all()
