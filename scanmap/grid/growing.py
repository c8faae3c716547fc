"""An array that grows by appended rows at amortised constant cost (`GrowingArray`).

A grid keeps what grows with the run, not with the area seen: each scan's time and the
places the robot stood. Kept in Python lists, every window read (`HeightGrid.layers`,
once a scan) copied them whole into arrays: 1.3 ms after 1,000 scans of a robot
driving, 16 ms after 10,000. Here they live in a buffer that doubles when full, and a
read is a view.
"""

from __future__ import annotations

import numpy as np


class GrowingArray:
    """Rows of one shape and dtype, appended in place; `array` views the rows so far."""

    def __init__(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows)
        if rows.ndim == 0:
            raise ValueError("GrowingArray: expected rows, got a scalar")
        self._buffer = np.array(rows, copy=True)
        self._count = len(rows)

    @property
    def array(self) -> np.ndarray:
        """The rows so far, read-only (a view; later appends do not change it)."""
        view = self._buffer[:self._count]
        view.flags.writeable = False
        return view

    def __len__(self) -> int:
        return self._count

    def extend(self, rows: np.ndarray) -> None:
        """Append `rows` (their shape past the first axis must match)."""
        rows = np.asarray(rows, dtype=self._buffer.dtype)
        if rows.shape[1:] != self._buffer.shape[1:]:
            raise ValueError(f"GrowingArray: rows of shape {rows.shape[1:]} appended to rows "
                             f"of shape {self._buffer.shape[1:]}")
        end = self._count + len(rows)
        if end > len(self._buffer):
            grown = np.empty((max(end, 2 * len(self._buffer), 16), *self._buffer.shape[1:]),
                             self._buffer.dtype)
            grown[:self._count] = self._buffer[:self._count]
            self._buffer = grown
        self._buffer[self._count:end] = rows
        self._count = end

    def append(self, row: object) -> None:
        """Append one row."""
        self.extend(np.asarray(row, dtype=self._buffer.dtype)[None])

    def copy(self) -> GrowingArray:
        """An independent copy of the rows."""
        return GrowingArray(self.array)
