"""Where the time goes: wall-clock and thread-CPU seconds per named stage.

Both are kept because they answer different questions on a shared machine: wall time is
what a user waits for; the CPU time of the thread that ran a stage is the work it took,
unaffected by other threads and processes competing for the cores.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator


class StageClock:
    """Accumulates seconds per stage: `with clock.stage("register"): ...`."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the block as `name` (added to what `name` already took)."""
        wall, cpu = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - wall, time.thread_time() - cpu)

    def add(self, name: str, wall: float, cpu: float) -> None:
        """Add seconds to a stage."""
        self.wall[name] = self.wall.get(name, 0.0) + wall
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu


def process_seconds() -> float:
    """Wall seconds since this process started (interpreter start-up and imports
    included), what a user waits for; since this module was imported where /proc is
    not available."""
    try:
        with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
            # Field 22 is the start time in clock ticks after boot; the command name
            # (field 2) may hold spaces, so count fields after its closing parenthesis.
            start_ticks = int(stat.read().rpartition(")")[2].split()[19])
            now = float(uptime.read().split()[0])
        return max(now - start_ticks / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return time.perf_counter() - _IMPORTED


_IMPORTED = time.perf_counter()
