"""The encoder disk: a stationary ring of binary-labelled sectors around the scanner axis.

The disk is fixed to the robot (`base_link`), centred on the head's axis, face up, and
seen at the bottom of every camera frame as the head turns above it. Its single track
carries a de Bruijn sequence B(2, 5): every run of 5 consecutive sectors is unique, so
any visible run of 5 sectors fixes the heading absolutely (DESIGN.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CalibrationError


def de_bruijn(order: int = 5) -> str:
    """The lexicographically least binary de Bruijn sequence of the given order, as '0'/'1'.

    Every binary word of length `order` appears exactly once as a cyclic window.
    Built by concatenating the Lyndon words whose length divides `order` (FKM algorithm).
    """
    if order < 1:
        raise ValueError("order must be >= 1")
    word = [0] * (order + 1)
    out: list[int] = []

    def extend(t: int, p: int) -> None:
        if t > order:
            if order % p == 0:
                out.extend(word[1:p + 1])
            return
        word[t] = word[t - p]
        extend(t + 1, p)
        for bit in range(word[t - p] + 1, 2):
            word[t] = bit
            extend(t + 1, t)

    extend(1, 1)
    return "".join(map(str, out))


def window_is_unique(code: str, window: int) -> bool:
    """True if every cyclic run of `window` sectors of `code` occurs once."""
    doubled = code + code[: window - 1]
    runs = {doubled[i:i + window] for i in range(len(code))}
    return len(runs) == len(code)


@dataclass(frozen=True)
class EncoderDisk:
    """Geometry and code of the disk, in `base_link`.

    height: z of the disk's printed face above the floor (m).
    inner_radius, outer_radius: the code ring (m).
    code: one '0'/'1' per sector, counter-clockwise from `zero_offset`; '1' is printed white.
    zero_offset: `base_link` angle (rad) where sector 0 starts; heading 0 is defined there.
    """

    height: float
    inner_radius: float
    outer_radius: float
    code: str
    zero_offset: float = 0.0

    def __post_init__(self) -> None:
        if not (0.0 < self.inner_radius < self.outer_radius):
            raise CalibrationError(
                f"encoder: expected 0 < inner_radius < outer_radius, got "
                f"{self.inner_radius}, {self.outer_radius}")
        if len(self.code) < 2 or set(self.code) - {"0", "1"}:
            raise CalibrationError(f"encoder.code: expected a string of '0'/'1', got {self.code!r}")

    @property
    def sectors(self) -> int:
        """Number of sectors on the ring."""
        return len(self.code)

    @property
    def sector_angle(self) -> float:
        """Angular width of one sector (rad)."""
        return 2.0 * np.pi / self.sectors

    def bits(self) -> np.ndarray:
        """The code as an int8 array, sector 0 first."""
        return np.frombuffer(self.code.encode(), dtype=np.uint8).astype(np.int8) - ord("0")

    def value_at(self, angle: np.ndarray) -> np.ndarray:
        """Printed value (0 or 1) of the ring at `base_link` angles (rad)."""
        index = np.floor((np.asarray(angle) - self.zero_offset) / self.sector_angle)
        return self.bits()[index.astype(np.int64) % self.sectors]
