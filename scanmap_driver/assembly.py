"""Scan assembly: a stream of frames becomes one 360 deg `Scan` with colour and a summary.

Per frame: the laser stripe (one subpixel peak per image line) and the heading from the
encoder disk. At the end of the scan, frames whose disk could not be read take their
heading from their neighbours (and are counted), the coverage of the headings is checked
(a scan short of 360 deg is reported, never padded), every peak is triangulated, and
each point takes its colour from the scene beside the stripe, where the laser does not
tint it (the paper's textured scans).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from . import _laser_kernels as lk
from .encoder import coverage, decode_heading, fill_unreadable, laser_line_range
from .errors import ScanError
from .laser import LaserConfig, extract_stripe
from .scan import Scan
from .scanner_model import ScannerModel
from .triangulation import Reason, triangulate

COLOUR_OFFSET_PX = 6.0  # beside the stripe: 4 sigma of a 1.5 px Gaussian line


@dataclass
class ScanSummary:
    """What went into a scan and what was rejected, for `scanmap process` and reports."""

    index: int
    frames: int = 0
    points: int = 0
    unreadable_frames: int = 0
    headings_covered_deg: float = 0.0
    complete: bool = False
    lines_rejected: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain JSON-able dict."""
        return dict(self.__dict__)


@dataclass
class _FrameData:
    timestamp: float
    heading: float
    heading_ok: bool
    lines: np.ndarray  # image line index u of each peak
    peaks: np.ndarray  # subpixel v
    colours: np.ndarray  # (n, 3) RGB beside the stripe
    missing_lines: int


def colour_beside_stripe(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """RGB colour (n, 3) of the scene beside the stripe on each line, laser excluded.

    Samples COLOUR_OFFSET_PX either side of the peak along the line (the image column)
    and keeps the side whose red excess is smaller: the side away from a red object or
    from the laser's own glow.
    """
    out = np.empty((len(u), 3), np.uint8)
    lk.colour_beside(image, np.ascontiguousarray(u, np.float64),
                     np.ascontiguousarray(v, np.float64), COLOUR_OFFSET_PX, out)
    return out


class ScanAssembler:
    """Collects frames of one scan, then builds the `Scan` (see the module docstring)."""

    def __init__(self, model: ScannerModel, laser: LaserConfig | None = None) -> None:
        self.model = model
        self.laser = laser or LaserConfig(line_range=laser_line_range(model))
        self._frames: list[_FrameData] = []
        self._previous_heading: float | None = None

    @property
    def headings(self) -> np.ndarray:
        """Headings of the frames so far (unreadable frames are NaN)."""
        return np.array([f.heading if f.heading_ok else np.nan for f in self._frames])

    def add_frame(self, image: np.ndarray, timestamp: float) -> float | None:
        """Process one frame; returns its heading (rad) or None when the disk is unreadable."""
        cam = self.model.camera
        if image.shape != (cam.height, cam.width, 3) or image.dtype != np.uint8:
            raise ScanError(f"frame {len(self._frames)}: expected a {cam.height}x{cam.width}x3 "
                            f"uint8 BGR image, got {image.shape} {image.dtype}")
        stripe = extract_stripe(image, self.laser)
        found = np.isfinite(stripe.peak)
        lines = np.flatnonzero(found).astype(np.float64)
        peaks = stripe.peak[found]
        result = decode_heading(image, self.model, previous=self._previous_heading)
        if result.ok:
            self._previous_heading = result.heading
        self._frames.append(_FrameData(
            timestamp=float(timestamp), heading=float(result.heading) if result.ok else np.nan,
            heading_ok=bool(result.ok), lines=lines, peaks=peaks,
            colours=colour_beside_stripe(image, lines, peaks),
            missing_lines=int(stripe.peak.size - found.sum())))
        return float(result.heading) if result.ok else None

    def observations(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every peak so far as (u, v, heading), unreadable frames' headings filled (or NaN).

        The raw material of calibration: pixels and headings before triangulation.
        """
        if not self._frames:
            empty = np.zeros(0)
            return empty, empty, empty
        headings = self._filled_headings()
        counts = [f.lines.size for f in self._frames]
        return (np.concatenate([f.lines for f in self._frames]),
                np.concatenate([f.peaks for f in self._frames]),
                np.repeat(headings, counts))

    def _filled_headings(self) -> np.ndarray:
        times = np.array([f.timestamp for f in self._frames])
        ok = np.array([f.heading_ok for f in self._frames])
        return fill_unreadable(self.headings, ok, times)

    def finish(self, index: int = 0, odom_start: np.ndarray | None = None,
               odom_end: np.ndarray | None = None) -> tuple[Scan, ScanSummary]:
        """The scan of the frames added so far, and its summary."""
        summary = ScanSummary(index=index, frames=len(self._frames))
        if not self._frames:
            return Scan.empty(index=index), summary
        times = np.array([f.timestamp for f in self._frames])
        ok = np.array([f.heading_ok for f in self._frames])
        summary.unreadable_frames = int((~ok).sum())
        if not ok.any():
            raise ScanError(f"scan {index}: the encoder disk was unreadable in all "
                            f"{len(self._frames)} frames")
        headings = self._filled_headings()
        covered = coverage(headings)
        summary.headings_covered_deg = float(np.degrees(covered.covered))
        summary.complete = bool(covered.complete)

        counts = [f.lines.size for f in self._frames]
        frame_index = np.repeat(np.arange(len(self._frames), dtype=np.int32), counts)
        u = np.concatenate([f.lines for f in self._frames])
        v = np.concatenate([f.peaks for f in self._frames])
        colours = np.concatenate([f.colours for f in self._frames]).reshape(-1, 3)
        point_heading = headings[frame_index]
        result = triangulate(self.model, u, v, point_heading)
        valid = result.valid
        no_heading = ~np.isfinite(point_heading)
        rejected = Counter(Reason(r).name.lower() for r in result.reason[~valid & ~no_heading])
        rejected["no_heading"] = int(no_heading.sum())
        rejected["no_stripe"] = sum(f.missing_lines for f in self._frames)
        summary.lines_rejected = dict(sorted(rejected.items()))
        summary.points = int(valid.sum())
        nan_pose = np.full((4, 4), np.nan)
        scan = Scan(points=result.points_base[valid], colors=colours[valid],
                    time=times[frame_index][valid], heading=point_heading[valid],
                    frame_index=frame_index[valid], range_sigma=result.range_sigma[valid],
                    index=index, stamp=float(times[0]),
                    odom_start=nan_pose if odom_start is None else odom_start,
                    odom_end=nan_pose if odom_end is None else odom_end)
        return scan, summary
