"""Heading decoders for the scanning loop: a frame -> the head's heading (rad), or None.

`Scanner` takes any such callable; `encoder_headings` is the encoder disk's.
"""

from __future__ import annotations

from collections.abc import Callable

from .camera import CameraFrame
from .scanner_model import ScannerModel

HeadingDecoder = Callable[[CameraFrame], "float | None"]


def encoder_headings(model: ScannerModel) -> HeadingDecoder:
    """The heading decoder of the encoder disk (`encoder.decode_heading`), each frame
    decoded near the previous heading."""
    from .encoder import decode_heading

    previous: float | None = None

    def decode(frame: CameraFrame) -> float | None:
        nonlocal previous
        result = decode_heading(frame.image, model, previous=previous)
        if not result.ok:
            return None
        previous = float(result.heading)
        return previous

    return decode
