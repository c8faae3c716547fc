"""Where the time goes: wall-clock and thread-CPU seconds per named stage.

Both are kept because they answer different questions on a shared machine: wall time is
what a user waits for; the CPU time of the thread that ran a stage is the work it took,
unaffected by other threads and processes competing for the cores.
"""

from __future__ import annotations

import contextlib
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
