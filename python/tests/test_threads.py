"""Long calls release the GIL: Python runs during them, and two threads decode in parallel."""

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import dlgs

SCRIPT = Path(__file__).with_name("parallel_speedup.py")


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


def test_two_threads_speed_up(dyn_exact):
    busy = os.getloadavg()[0]
    p = subprocess.run([sys.executable, str(SCRIPT), str(dyn_exact)], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    print(p.stdout)
    speedup = float(p.stdout.split("speed-up")[1].split()[0])
    # 2 cores: two threads with one worker each; with the GIL held it would be about 1.0.
    # Other work on the machine takes the second core away (load average before the run):
    # then the speed-up cannot show, and the GIL is checked by the test above alone.
    if busy > 1.0 and speedup <= 1.3:
        pytest.skip(f"machine busy (load {busy:.1f}): {p.stdout.strip()}")
    assert speedup > 1.3, p.stdout


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
