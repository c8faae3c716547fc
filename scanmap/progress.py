"""A plain-text progress bar: `[######........] 12/20 scans  4.1/s  ETA 2 s  note`.

On a terminal it is redrawn in place; into a file or pipe it writes a line at every
tenth of the way (and at the end), so logs stay short.
"""

from __future__ import annotations

import math
import sys
import time
from typing import TextIO


class ProgressBar:
    """Progress through `total` items (see the module docstring)."""

    def __init__(self, total: int, unit: str = "scans", stream: TextIO | None = None,
                 width: int = 24) -> None:
        self.total = max(int(total), 0)
        self.unit = unit
        self.stream = stream or sys.stderr
        self.width = width
        self._start = time.perf_counter()
        self._printed_tenth = -1
        self._live = bool(getattr(self.stream, "isatty", lambda: False)())

    def line(self, done: int, note: str = "") -> str:
        """The bar's text after `done` items."""
        fraction = done / self.total if self.total else 1.0
        filled = round(self.width * fraction)
        elapsed = time.perf_counter() - self._start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else float("nan")
        text = (f"[{'#' * filled}{'.' * (self.width - filled)}] {done}/{self.total} "
                f"{self.unit}  {rate:.1f}/s")
        if done < self.total and math.isfinite(eta):
            text += f"  ETA {eta:.0f} s"
        return text + (f"  {note}" if note else "")

    def update(self, done: int, note: str = "") -> None:
        """Show progress after `done` items."""
        if self._live:
            self.stream.write("\r" + self.line(done, note) + "\x1b[K")
            if done >= self.total:
                self.stream.write("\n")
        else:
            tenth = 10 * done // self.total if self.total else 10
            if tenth == self._printed_tenth:
                return
            self._printed_tenth = tenth
            self.stream.write(self.line(done, note) + "\n")
        self.stream.flush()
