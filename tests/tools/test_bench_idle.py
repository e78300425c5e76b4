"""tools/bench/idle.py's CPU sampling: the scheduler's per-thread counts."""

from __future__ import annotations

import os
import threading
import time

from tools.bench.idle import spent, threads


def test_threads_reads_each_threads_cpu_time_and_wake_ups_of_a_live_process() -> None:
    stop = threading.Event()
    sleeper = threading.Thread(target=lambda: [stop.wait(0.01) for _ in range(20)])
    before = threads(os.getpid())
    sleeper.start()
    end = time.thread_time() + 0.05
    while time.thread_time() < end:  # the main thread works 50 ms
        pass
    sleeper.join()
    after = threads(os.getpid())
    used = spent(before, after)
    cpu, slices = used[os.getpid()]
    assert 0.04 <= cpu < 5.0 and slices >= 1
    assert after[os.getpid()][0]  # a name
    assert all(c >= 0.0 and n >= 0 for c, n in used.values())


def test_spent_counts_a_thread_born_meanwhile_from_zero() -> None:
    t0 = {1: ("main", 2.0, 10)}
    t1 = {1: ("main", 2.5, 14), 7: ("rx-0", 0.1, 3)}
    assert spent(t0, t1) == {1: (0.5, 4), 7: (0.1, 3)}
