"""Timing helpers for the benchmarks: medians over repeats, compile time apart."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


def median_time(func: Callable[[], Any], repeats: int = 20, warmup: int = 1,
                clock: Callable[[], float] = time.perf_counter) -> float:
    """Median time (s) of `func()` over `repeats` runs after `warmup` runs.

    clock: wall time by default; `time.thread_time` gives what one core spends, whatever
    else shares the machine.
    """
    for _ in range(warmup):
        func()
    times = []
    for _ in range(repeats):
        start = clock()
        func()
        times.append(clock() - start)
    times.sort()
    return times[len(times) // 2]


def first_call_time(func: Callable[[], Any]) -> float:
    """Wall time (s) of one call: with Numba this is the compile (or cache load) time."""
    start = time.perf_counter()
    func()
    return time.perf_counter() - start
