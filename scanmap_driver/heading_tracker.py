"""Decoded headings unwrapped into a sweep's progress, robust to undecoded frames and outliers."""

from __future__ import annotations

import collections
import math

from .transforms import wrap_angle


class HeadingTracker:
    """Unwraps decoded headings into progress (rad) along the sweep direction.

    Each new heading is unwrapped around the heading predicted from the recent angular
    speed, so a few undecoded frames in a row do not lose a turn. A heading far from the
    prediction is an outlier and skipped, unless three in a row agree (a real jump).
    """

    OUTLIER = math.radians(60.0)

    def __init__(self, sign: float) -> None:
        self.sign = sign
        self.start: float | None = None
        self.unwrapped = 0.0
        self.speed = 0.0
        self.time = 0.0
        self.outliers = 0
        self._rejected = 0
        self._history: collections.deque[tuple[float, float]] = collections.deque()

    @property
    def progress(self) -> float:
        """Heading turned since the first decoded frame, in the sweep direction (rad)."""
        return 0.0 if self.start is None else self.sign * (self.unwrapped - self.start)

    def update(self, t: float, heading: float) -> bool:
        """Take the heading of a frame at time t; False if it was rejected as an outlier."""
        if self.start is None:
            self.start = self.unwrapped = heading
            self.time = t
            self._history.append((t, 0.0))
            return True
        dt = max(t - self.time, 0.0)
        predicted = self.speed * dt
        delta = float(wrap_angle(heading - self.unwrapped - predicted)) + predicted
        if abs(delta - predicted) > self.OUTLIER and self._rejected < 2:
            self._rejected += 1
            self.outliers += 1
            return False
        self._rejected = 0
        self.unwrapped += delta
        if dt > 0.0:
            self.speed = 0.5 * self.speed + 0.5 * delta / dt
        self.time = t
        self._history.append((t, self.progress))
        return True

    def advance_within(self, window: float, now: float) -> float | None:
        """Progress over the last `window` s (None until the history spans it)."""
        while len(self._history) > 1 and self._history[1][0] <= now - window:
            self._history.popleft()
        t0, p0 = self._history[0] if self._history else (now, 0.0)
        if now - t0 < window:
            return None
        return self.progress - p0

    def heading_now(self) -> float:
        """The last unwrapped heading (rad)."""
        return self.unwrapped
