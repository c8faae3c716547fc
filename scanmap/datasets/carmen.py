"""CARMEN robot logs (gzipped or plain text): laser scans, corrected poses, raw odometry.

Lines used (formats as CARMEN's logger writes them; angles in radians):
  FLASER / RLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp host logger_ts
  ROBOTLASER1 / ROBOTLASER2 laser_type start_angle field_of_view angular_resolution
      maximum_range accuracy remission_mode n r1..rn m remission1..m
      laser_x laser_y laser_theta robot_x robot_y robot_theta
      tv rv forward_safety side_safety turn_axis timestamp host logger_ts
  RAWLASER1..4 laser_type start_angle field_of_view angular_resolution maximum_range
      accuracy remission_mode n r1..rn m remission1..m timestamp host logger_ts
  ODOM x y theta tv rv accel timestamp host logger_ts
  PARAM name value ...
Other lines (NEFF, SYNC, comments...) are ignored.

One laser is read (`read_carmen(..., laser=)`): "front" (FLASER and ROBOTLASER1), "rear"
(RLASER and ROBOTLASER2) or "raw1".."raw4" (RAWLASERk). The other lasers' lines are
counted in `CarmenLog.skipped`. RAWLASER lines carry no pose: their pose and odometry are
the latest ODOM reading (the laser's mounting offset is not applied).

Beam layout (beam i looks at first + i * step, counter-clockwise from x forward): taken
from the line when it states one (ROBOTLASER, RAWLASER); else from the `PARAM` lines of
that laser (`laser_front_laser_resolution`, `laser_front_laser_fov`, also spelled
`laser_frontlaser_...` or `robot_front_laser_...`; degrees; fov 180 when absent); else
from the beam count, as CARMEN's own reader guesses it: 180 or 181 beams of 1 deg, 360 or
361 beams of 0.5 deg, all from -90 deg. So 181 and 361 beams include both ends (-90 and
+90 deg) and 180 and 360 beams stop one step short of +90. Any other count with no stated
layout is a RecordingError naming the file and line: a wrong step smears every wall.

Bad input never yields a silently wrong map. A RecordingError names the file and line for:
a non-numeric field, a line cut short (except the file's last line, which a logger killed
mid-write leaves: skipped and counted), a change of beam count or layout within the log,
a layout the PARAM lines contradict, a pose that is not finite. Skipped and counted in
`CarmenLog.skipped`: readings that are NaN/infinite or negative (dropped by
`scan_points`), RAWLASER lines before any ODOM (no pose), the other lasers' lines.

In the "corrected" logs (Intel, ACES...), FLASER's x y theta is the corrected laser pose
(the reference), and the wheel odometry is stored re-anchored: the ODOM line right after
each FLASER repeats the corrected pose, and the following ODOM lines carry the wheel
odometry from there. `CarmenLog.odometry` undoes that: it chains the odometry
increments between consecutive scans into one raw odometry trajectory, the prior a
registration may use. In a log without anchors, the increments are simply those
between the ODOM readings last before each scan; in a log without ODOM lines, the
odometry is the one the laser lines carry.

A 2-D scan becomes a 3-D one by giving its points one height (`carmen_scan_points`).
"""

from __future__ import annotations

import gzip
import os
import re
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scanmap_driver.errors import RecordingError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose

DEFAULT_MAX_RANGE = 40.0  # m; below the logs' "no return" values (Intel 81.83, ACES 50)
HALF_TURN_STEP_DEG = {180: 1.0, 181: 1.0, 360: 0.5, 361: 0.5}  # beam count -> step, from -90
_ANCHOR_TOLERANCE = 1e-5  # the anchor repeats the FLASER pose, up to printing
_LAYOUT_TOLERANCE = 1e-6  # rad; layouts printed with fewer digits still compare equal
_STREAMS = {"FLASER": "front", "ROBOTLASER1": "front", "RLASER": "rear",
            "ROBOTLASER2": "rear", **{f"RAWLASER{k}": f"raw{k}" for k in range(1, 5)}}
LASERS = tuple(dict.fromkeys(_STREAMS.values()))  # "front", "rear", "raw1".."raw4"
_PARAM = re.compile(r"^(?:laser|robot)_(front|rear)_?laser_(fov|resolution)$")
NONFINITE = "non-finite range readings (dropped)"
NEGATIVE = "negative range readings (dropped)"
TRUNCATED = "truncated last line"


@dataclass(frozen=True)
class BeamLayout:
    """Directions of the beams of a scan: beam i at first + i * step (rad, counter-clockwise
    from x forward). source says where the layout came from (a line, a PARAM, the count)."""

    count: int
    first: float
    step: float
    source: str

    @property
    def angles(self) -> np.ndarray:
        """(count,) beam angles in radians."""
        return self.first + self.step * np.arange(self.count)

    def same_as(self, other: BeamLayout) -> bool:
        """Same beams (the source aside)."""
        return (self.count == other.count
                and abs(self.first - other.first) < _LAYOUT_TOLERANCE
                and abs(self.step - other.step) < _LAYOUT_TOLERANCE)

    def __str__(self) -> str:
        return (f"{self.count} beams from {np.rad2deg(self.first):.2f} deg, step "
                f"{np.rad2deg(self.step):.3f} deg ({self.source})")


def half_turn_layout(count: int, fov_deg: float = 180.0, step_deg: float | None = None,
                     source: str = "") -> BeamLayout:
    """The layout of `count` beams over `fov_deg` centred ahead, from -fov/2.

    With no `step_deg`, the step is CARMEN's guess from the count (HALF_TURN_STEP_DEG).
    The count must fill the field of view either with both ends (count - 1 steps) or
    stopping one step short (count steps). ValueError says why when it cannot.
    """
    if step_deg is None:
        if count not in HALF_TURN_STEP_DEG:
            raise ValueError(f"{count} beams: no layout is stated and the count is none of "
                             f"{sorted(HALF_TURN_STEP_DEG)} (a half turn)")
        step_deg = HALF_TURN_STEP_DEG[count]
        source = source or f"beam count {count}"
    if not step_deg > 0.0 or not any(abs(k * step_deg - fov_deg) < 1e-3 * step_deg
                                     for k in (count - 1, count)):
        raise ValueError(f"{count} beams of {step_deg:g} deg do not fill a field of view of "
                         f"{fov_deg:g} deg")
    return BeamLayout(count, float(np.deg2rad(-0.5 * fov_deg)), float(np.deg2rad(step_deg)),
                      source)


@dataclass(frozen=True, eq=False)
class CarmenLog:
    """The scans of one laser of a CARMEN log with their reference poses and raw odometry.

    ranges: (M, n) metres. times: (M,) s (the laser line's timestamp). poses: (M, 3)
    corrected laser (x, y, theta) in the log's world (the odometry for RAWLASER). odometry:
    (M, 3) raw wheel odometry at each scan, chained from the ODOM lines (the prior).
    max_range: the largest finite reading, the laser's "no return" value. layout: the beam
    directions. laser: which laser ("front", "rear", "raw1".."raw4"). skipped: what was
    left out, and how many (lines or readings, as the key says).
    """

    path: Path
    ranges: np.ndarray
    times: np.ndarray
    poses: np.ndarray
    odometry: np.ndarray
    max_range: float
    layout: BeamLayout
    laser: str = "front"
    skipped: dict[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.ranges.shape[0])

    def scan_points(self, index: int, height: float = 0.3) -> np.ndarray:
        """(N, 3) points of scan `index` in base_link, dropping this log's no-return readings."""
        return carmen_scan_points(self.ranges[index], self.layout, height=height,
                                  max_range=min(DEFAULT_MAX_RANGE, self.max_range))

    def subset(self, indices: np.ndarray | slice | range) -> CarmenLog:
        """The same log holding only the scans at `indices` (e.g. every 5th: slice(0, None, 5))."""
        if isinstance(indices, range):
            indices = np.asarray(indices)
        return replace(self, ranges=self.ranges[indices], times=self.times[indices],
                       poses=self.poses[indices], odometry=self.odometry[indices])


def carmen_scan_points(ranges: np.ndarray, layout: BeamLayout | None = None,
                       height: float = 0.3, max_range: float = DEFAULT_MAX_RANGE,
                       ) -> np.ndarray:
    """(N, 3) float64 points in base_link of one CARMEN scan, all at z = `height`.

    Beam i looks along layout.angles[i]; with no layout, the layout CARMEN guesses from
    the beam count (`half_turn_layout`). Readings that are not finite, not positive, or
    at/over `max_range` (no return) are dropped.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    if ranges.ndim != 1:
        raise RecordingError(f"carmen_scan_points: ranges must be 1-D, got shape {ranges.shape}")
    if layout is None:
        try:
            layout = half_turn_layout(ranges.size)
        except ValueError as exc:
            raise RecordingError(f"carmen_scan_points: {exc}") from None
    if layout.count != ranges.size:
        raise RecordingError(f"carmen_scan_points: {ranges.size} readings for a layout of "
                             f"{layout.count} beams")
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(ranges) & (ranges > 0.0) & (ranges < max_range)
    r, a = ranges[keep], layout.angles[keep]
    return np.column_stack([r * np.cos(a), r * np.sin(a), np.full(r.size, float(height))])


def read_carmen(path: str | os.PathLike[str], laser: str = "front") -> CarmenLog:
    """Read one laser of a CARMEN log (`.gz` or plain); RecordingError names file and line."""
    if laser not in LASERS:
        raise ValueError(f"laser must be one of {LASERS}, got {laser!r}")
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt") as fh:
            lines = fh.readlines()
    except FileNotFoundError:
        raise RecordingError(f"{path}: file not found") from None
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: not a readable CARMEN log ({exc})") from None
    last_line = max((k for k, line in enumerate(lines, start=1) if line.strip()), default=0)
    parser = _Parser(path, laser, last_line)
    for number, line in enumerate(lines, start=1):
        parser.feed(number, line.split())
    return parser.result()


class _Truncated(Exception):
    """A line ended before its last field."""


class _Fields:
    """Reads one line's fields in order; errors name the file, line and message."""

    def __init__(self, where: str, tokens: list[str]) -> None:
        self.where = where
        self.tokens = tokens
        self.at = 1

    def numbers(self, count: int) -> np.ndarray:
        """The next `count` fields as float64."""
        if self.at + count > len(self.tokens):
            raise _Truncated(f"{self.where} needs {self.at - 1 + count} numbers, got "
                             f"{len(self.tokens) - 1}")
        try:
            values = np.array(self.tokens[self.at:self.at + count], dtype=np.float64)
        except ValueError:
            raise RecordingError(f"{self.where} has a non-numeric field") from None
        self.at += count
        return values

    def count(self, what: str) -> int:
        """The next field as a count of `what` (a non-negative integer)."""
        if self.at >= len(self.tokens):
            raise _Truncated(f"{self.where} needs {what}")
        try:
            value = int(self.tokens[self.at])
        except ValueError:
            raise RecordingError(f"{self.where} needs {what}, got {self.tokens[self.at]!r}"
                                 ) from None
        if value < 0:
            raise RecordingError(f"{self.where}: {what} {value} is negative")
        self.at += 1
        return value


@dataclass
class _Scan:
    """One laser line: its ranges, layout, time, pose and odometry (RAWLASER: the ODOM)."""

    number: int
    ranges: np.ndarray
    layout: BeamLayout
    time: float
    pose: np.ndarray
    odometry: np.ndarray


class _Parser:
    """Collects one laser's scans and the odometry increments between them, line by line."""

    def __init__(self, path: Path, laser: str, last_line: int) -> None:
        self.path = path
        self.laser = laser
        self.last_line = last_line
        self.scans: list[_Scan] = []
        self.skipped: Counter[str] = Counter()
        self.other_lasers: Counter[str] = Counter()
        self.params: dict[tuple[str, str], tuple[float, str]] = {}  # (side, kind) -> value, text
        self.increments: list[np.ndarray] = []  # odometry motion from scan k-1 to scan k
        self.last_odom: np.ndarray | None = None  # latest ODOM pose (4x4)
        self.segment_start: np.ndarray | None = None  # odometry pose at the previous scan
        self.expect_anchor = False
        self.odom_lines = 0

    def feed(self, number: int, tokens: list[str]) -> None:
        """Take one line (split into tokens)."""
        if not tokens:
            return
        tag = tokens[0]
        fields = _Fields(f"{self.path}:{number}: {tag}", tokens)
        try:
            if tag == "ODOM":
                self._odom(fields)
            elif tag == "PARAM":
                self._param(number, tokens)
            elif tag in _STREAMS and _STREAMS[tag] != self.laser:
                self.other_lasers[tag] += 1
            elif tag in ("FLASER", "RLASER"):
                self._flaser(number, fields)
            elif tag in _STREAMS:
                self._stated(number, fields)
        except _Truncated as exc:
            if number != self.last_line:
                raise RecordingError(f"{exc} (the line is cut short)") from None
            self.skipped[TRUNCATED] += 1

    def _odom(self, fields: _Fields) -> None:
        x, y, theta = fields.numbers(7)[:3]
        if not np.isfinite([x, y, theta]).all():
            raise RecordingError(f"{fields.where}: the pose is not finite")
        pose = se2_to_pose(x, y, theta)
        self.odom_lines += 1
        if self.expect_anchor:
            self.expect_anchor = False
            if np.allclose([x, y, theta], self.scans[-1].pose, atol=_ANCHOR_TOLERANCE, rtol=0.0):
                self.segment_start = pose  # re-anchored odometry restarts here
        self.last_odom = pose

    def _param(self, number: int, tokens: list[str]) -> None:
        match = _PARAM.match(tokens[1]) if len(tokens) > 2 else None
        if match is None:
            return
        try:
            value = float(tokens[2])
        except ValueError:
            raise RecordingError(f"{self.path}:{number}: PARAM {tokens[1]} is not a number: "
                                 f"{tokens[2]!r}") from None
        self.params[(match[1], match[2])] = (value, f"PARAM {tokens[1]} {value:g} (line {number})")

    def _param_layout(self, where: str, count: int, side: str) -> BeamLayout:
        """The layout of an old-format line: from this laser's PARAM lines, else the count."""
        fov = self.params.get((side, "fov"))
        step = self.params.get((side, "resolution"))
        stated = ", ".join(p[1] for p in (fov, step) if p)
        try:
            return half_turn_layout(count, fov[0] if fov else 180.0, step[0] if step else None,
                                    source=stated)
        except ValueError as exc:
            raise RecordingError(f"{where}: {exc}" + (f" ({stated})" if stated else "")) from None

    def _flaser(self, number: int, fields: _Fields) -> None:
        """FLASER / RLASER: ranges, laser pose, odometry; the layout from PARAM or count."""
        n = fields.count("a beam count")
        if n == 0:
            raise RecordingError(f"{fields.where} beam count 0 is not positive")
        values = fields.numbers(n + 7)
        side = "front" if fields.tokens[0] == "FLASER" else "rear"
        layout = self._param_layout(fields.where, n, side)
        self._add(number, values[:n], layout, float(values[n + 6]), values[n:n + 3],
                  values[n + 3:n + 6])

    def _stated(self, number: int, fields: _Fields) -> None:
        """ROBOTLASER / RAWLASER: the line states its layout; RAWLASER has no pose."""
        _, start, _, step, *_ = fields.numbers(7)
        n = fields.count("a beam count")
        if n == 0 or not step > 0.0:
            raise RecordingError(f"{fields.where}: {n} beams of {step} rad: no scan")
        ranges = fields.numbers(n)
        fields.numbers(fields.count("a remission count"))
        tag = fields.tokens[0]
        layout = BeamLayout(n, float(start), float(step), f"{tag} line {number}")
        if tag.startswith("ROBOTLASER"):
            values = fields.numbers(12)
            self._add(number, ranges, layout, float(values[11]), values[:3], values[3:6])
            return
        time = float(fields.numbers(1)[0])
        if self.last_odom is None:
            self.skipped[f"{tag} lines before any ODOM (no pose)"] += 1
            return
        odometry = np.asarray(pose_to_se2(self.last_odom), dtype=np.float64)
        self._add(number, ranges, layout, time, odometry, odometry)

    def _add(self, number: int, ranges: np.ndarray, layout: BeamLayout, time: float,
             pose: np.ndarray, odometry: np.ndarray) -> None:
        """Check a scan against the log's first one, count bad readings, chain odometry."""
        where = f"{self.path}:{number}"
        if self.scans:
            first = self.scans[0]
            if ranges.size != first.ranges.size:
                raise RecordingError(f"{where}: {ranges.size} beams, the log's first scan (line "
                                     f"{first.number}) has {first.ranges.size}")
            if not layout.same_as(first.layout):
                raise RecordingError(f"{where}: beam layout {layout} differs from the first "
                                     f"scan's (line {first.number}): {first.layout}")
        if not (np.isfinite(pose).all() and np.isfinite(odometry).all()):
            raise RecordingError(f"{where}: a pose is not finite")
        finite = np.isfinite(ranges)
        self.skipped[NONFINITE] += int((~finite).sum())
        self.skipped[NEGATIVE] += int((ranges[finite] < 0.0).sum())
        self.scans.append(_Scan(number, ranges, layout, time, pose, odometry))
        here = self.last_odom if self.last_odom is not None else se2_to_pose(*odometry)
        if self.segment_start is not None:
            self.increments.append(invert_pose(self.segment_start) @ here)
        self.segment_start = here
        self.expect_anchor = True

    def result(self) -> CarmenLog:
        """The log, or RecordingError when this laser has no scan."""
        if not self.scans:
            others = ", ".join(f"{n} {tag}" for tag, n in self.other_lasers.items())
            tags = "/".join(t for t, s in _STREAMS.items() if s == self.laser)
            dropped = ", ".join(f"{n} {what}" for what, n in self.skipped.items() if n)
            raise RecordingError(f"{self.path}: no usable {tags} lines"
                                 + (f" (skipped: {dropped})" if dropped else "")
                                 + (f" (it has {others}: choose that laser)" if others else ""))
        ranges = np.vstack([s.ranges for s in self.scans])
        poses = np.vstack([s.pose for s in self.scans])
        if self.odom_lines:
            chain = [se2_to_pose(*self.scans[0].odometry)]
            for step in self.increments:
                chain.append(chain[-1] @ step)
            odometry = np.array([pose_to_se2(p) for p in chain])
        else:
            odometry = np.vstack([s.odometry for s in self.scans])
        finite = ranges[np.isfinite(ranges)]
        if finite.size == 0:
            raise RecordingError(f"{self.path}: no finite range reading")
        skipped = {k: v for k, v in self.skipped.items() if v}
        skipped |= {f"{tag} lines (not the {self.laser} laser)": n
                    for tag, n in self.other_lasers.items()}
        return CarmenLog(path=self.path, ranges=ranges,
                         times=np.array([s.time for s in self.scans]), poses=poses,
                         odometry=odometry, max_range=float(finite.max()),
                         layout=self.scans[0].layout, laser=self.laser, skipped=skipped)
