"""CARMEN robot logs (gzipped or plain text): laser scans, corrected poses, raw odometry.

Lines used (others are skipped):
  FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp host logger_ts
  ODOM x y theta tv rv accel timestamp host logger_ts

In the "corrected" logs (Intel, ACES), FLASER's x y theta is the corrected laser pose
(the reference), and the wheel odometry is stored re-anchored: the ODOM line right after
each FLASER repeats the corrected pose, and the following ODOM lines carry the wheel
odometry from there. `CarmenLog.odometry` undoes that: it chains the odometry
increments between consecutive scans into one raw odometry trajectory, the prior a
registration may use. In a log without anchors, the increments are simply those
between the ODOM readings last before each scan.

A 2-D scan becomes a 3-D one by giving its points one height (`carmen_scan_points`).
"""

from __future__ import annotations

import gzip
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanmap_driver.errors import RecordingError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose

BEAM_STEP = np.deg2rad(1.0)
FIRST_BEAM = np.deg2rad(-90.0)
DEFAULT_MAX_RANGE = 40.0  # m; below the logs' "no return" values (Intel 81.83, ACES 50)
_ANCHOR_TOLERANCE = 1e-5  # the anchor repeats the FLASER pose, up to printing


@dataclass(frozen=True, eq=False)
class CarmenLog:
    """The FLASER scans of a CARMEN log with their reference poses and raw odometry.

    ranges: (M, n) metres. times: (M,) s (FLASER timestamp). poses: (M, 3) corrected laser
    (x, y, theta) in the log's world. odometry: (M, 3) raw wheel odometry at each scan,
    chained from the ODOM lines (the prior). max_range: the largest reading in the log,
    the laser's "no return" value.
    """

    path: Path
    ranges: np.ndarray
    times: np.ndarray
    poses: np.ndarray
    odometry: np.ndarray
    max_range: float

    def __len__(self) -> int:
        return int(self.ranges.shape[0])

    def scan_points(self, index: int, height: float = 0.3) -> np.ndarray:
        """(N, 3) points of scan `index` in base_link, dropping this log's no-return readings."""
        return carmen_scan_points(self.ranges[index], height=height,
                                  max_range=min(DEFAULT_MAX_RANGE, self.max_range))


def carmen_scan_points(ranges: np.ndarray, height: float = 0.3,
                       max_range: float = DEFAULT_MAX_RANGE) -> np.ndarray:
    """(N, 3) float64 points in base_link of one CARMEN scan, all at z = `height`.

    Beam i looks at -90 deg + i * 1 deg (counter-clockwise from x forward). Readings that
    are not finite, not positive, or at/over `max_range` (no return) are dropped.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    if ranges.ndim != 1:
        raise RecordingError(f"carmen_scan_points: ranges must be 1-D, got shape {ranges.shape}")
    angles = FIRST_BEAM + BEAM_STEP * np.arange(ranges.size)
    keep = np.isfinite(ranges) & (ranges > 0.0) & (ranges < max_range)
    r, a = ranges[keep], angles[keep]
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.full(r.size, float(height))])


def read_carmen(path: str | os.PathLike[str]) -> CarmenLog:
    """Read a CARMEN log (`.gz` or plain); RecordingError names the file and line at fault."""
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt") as fh:
            lines = fh.readlines()
    except FileNotFoundError:
        raise RecordingError(f"{path}: file not found") from None
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: not a readable CARMEN log ({exc})") from None
    parser = _Parser(path)
    for number, line in enumerate(lines, start=1):
        parser.feed(number, line.split())
    return parser.result()


class _Parser:
    """Collects FLASER scans and the odometry increments between them, line by line."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.ranges: list[np.ndarray] = []
        self.times: list[float] = []
        self.poses: list[np.ndarray] = []
        self.flaser_odometry: list[np.ndarray] = []
        self.increments: list[np.ndarray] = []  # odometry motion from scan k-1 to scan k
        self.last_odom: np.ndarray | None = None  # latest ODOM pose (4x4)
        self.segment_start: np.ndarray | None = None  # odometry pose at the previous scan
        self.expect_anchor = False
        self.odom_lines = 0

    def _numbers(self, number: int, tokens: list[str], start: int, count: int) -> np.ndarray:
        """`count` numbers from tokens[start:], or RecordingError naming file, line and kind."""
        where = f"{self.path}:{number}: {tokens[0]}"
        try:
            values = np.array(tokens[start:start + count], dtype=np.float64)
        except ValueError:
            raise RecordingError(f"{where} has a non-numeric field") from None
        if values.size != count:
            raise RecordingError(f"{where} needs {count} numbers, got {values.size}")
        return values

    def feed(self, number: int, tokens: list[str]) -> None:
        if not tokens:
            return
        if tokens[0] == "ODOM":
            self._odom(number, tokens)
        elif tokens[0] == "FLASER":
            self._flaser(number, tokens)

    def _odom(self, number: int, tokens: list[str]) -> None:
        x, y, theta = self._numbers(number, tokens, 1, 7)[:3]
        pose = se2_to_pose(x, y, theta)
        self.odom_lines += 1
        if self.expect_anchor:
            self.expect_anchor = False
            if np.allclose([x, y, theta], self.poses[-1], atol=_ANCHOR_TOLERANCE, rtol=0.0):
                self.segment_start = pose  # re-anchored odometry restarts here
        self.last_odom = pose

    def _flaser(self, number: int, tokens: list[str]) -> None:
        try:
            n = int(tokens[1])
        except (IndexError, ValueError):
            raise RecordingError(f"{self.path}:{number}: FLASER needs a beam count") from None
        if n <= 0:
            raise RecordingError(f"{self.path}:{number}: FLASER beam count {n} is not positive")
        values = self._numbers(number, tokens, 2, n + 7)
        if self.ranges and n != self.ranges[0].size:
            raise RecordingError(f"{self.path}:{number}: FLASER has {n} beams, the log's first "
                                 f"scan has {self.ranges[0].size}")
        self.ranges.append(values[:n])
        self.poses.append(values[n:n + 3])
        self.flaser_odometry.append(values[n + 3:n + 6])
        self.times.append(float(values[n + 6]))
        here = self.last_odom if self.last_odom is not None else se2_to_pose(*values[n + 3:n + 6])
        if self.segment_start is not None:
            self.increments.append(invert_pose(self.segment_start) @ here)
        self.segment_start = here
        self.expect_anchor = True

    def result(self) -> CarmenLog:
        if not self.ranges:
            raise RecordingError(f"{self.path}: no FLASER lines")
        ranges = np.vstack(self.ranges)
        poses = np.vstack(self.poses)
        if self.odom_lines:
            chain = [se2_to_pose(*self.flaser_odometry[0])]
            for step in self.increments:
                chain.append(chain[-1] @ step)
            odometry = np.array([pose_to_se2(p) for p in chain])
        else:
            odometry = np.vstack(self.flaser_odometry)
        return CarmenLog(path=self.path, ranges=ranges, times=np.array(self.times),
                         poses=poses, odometry=odometry, max_range=float(ranges.max()))
