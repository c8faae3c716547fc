"""One full 360 deg scan: the points of about 50 frames, in `base_link`, with per-point data.

File format (docs/architecture.md): `.npz` without pickle holding `points` (N,3) float32 in
`base_link`, `colors` (N,3) uint8 RGB, `time` (N,) float64 s, `heading` (N,) float64 rad,
`frame_index` (N,) int32, `range_sigma` (N,) float32 m, and the scalars/poses below;
`.ply` export goes through Open3D.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .errors import ScanError
from .files import atomic_path, exact_array, load_npz, save_npz

FORMAT_VERSION = 1
_PER_POINT = {
    "points": (np.float32, (3,)),
    "colors": (np.uint8, (3,)),
    "time": (np.float64, ()),
    "heading": (np.float64, ()),
    "frame_index": (np.int32, ()),
    "range_sigma": (np.float32, ()),
}
_NO_POSE = np.full((4, 4), np.nan)


@dataclass(frozen=True, eq=False)
class Scan:
    """Points of one scan in `base_link` with colour, time, heading, frame and uncertainty.

    index: the scan's number in its recording. stamp: time (s) the scan started.
    odom_start, odom_end: 4x4 pose of `base_link` in `odom` at the first and last frame,
    NaN when no odometry was recorded; registration uses them as a prior and for de-skew.
    """

    points: np.ndarray
    colors: np.ndarray
    time: np.ndarray
    heading: np.ndarray
    frame_index: np.ndarray
    range_sigma: np.ndarray
    index: int = 0
    stamp: float = 0.0
    odom_start: np.ndarray = field(default_factory=lambda: _NO_POSE.copy())
    odom_end: np.ndarray = field(default_factory=lambda: _NO_POSE.copy())

    def __post_init__(self) -> None:
        n = None
        for name, (dtype, tail) in _PER_POINT.items():
            value = np.ascontiguousarray(getattr(self, name), dtype=dtype)
            if n is None:
                n = value.shape[0] if value.ndim else -1
            if value.shape != (n, *tail):
                raise ScanError(f"Scan.{name}: expected shape {(n, *tail)}, got {value.shape}")
            object.__setattr__(self, name, value)
        for name in ("odom_start", "odom_end"):
            pose = np.asarray(getattr(self, name), dtype=np.float64)
            if pose.shape != (4, 4):
                raise ScanError(f"Scan.{name}: expected a 4x4 pose, got shape {pose.shape}")
            object.__setattr__(self, name, pose)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def has_odometry(self) -> bool:
        """True when both odometry poses are known."""
        return bool(np.isfinite(self.odom_start).all() and np.isfinite(self.odom_end).all())

    @classmethod
    def empty(cls, index: int = 0, stamp: float = 0.0) -> Scan:
        """A scan with no points."""
        return cls(**{name: np.zeros((0, *tail), dtype) for name, (dtype, tail)
                      in _PER_POINT.items()}, index=index, stamp=stamp)

    def select(self, mask: np.ndarray) -> Scan:
        """The scan restricted to the points where `mask` is true (or to indices)."""
        return Scan(**{name: getattr(self, name)[mask] for name in _PER_POINT},
                    index=self.index, stamp=self.stamp, odom_start=self.odom_start,
                    odom_end=self.odom_end)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scan as `.npz` (atomically)."""
        save_npz(path, format_version=np.array(FORMAT_VERSION),
                 index=np.array(self.index), stamp=np.array(self.stamp),
                 odom_start=self.odom_start, odom_end=self.odom_end,
                 **{name: getattr(self, name) for name in _PER_POINT})

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scan:
        """Read a scan `.npz`; a malformed file raises ScanError naming it and the field.

        Values must arrive as stored: no wrapped integers (a colour of -1 is refused, not
        read as 255), no NaN or inf, no float that overflows float32."""
        arrays = load_npz(path, ScanError, required=("format_version", *_PER_POINT))
        version = _scalar(arrays, "format_version", path, FORMAT_VERSION)
        if version != FORMAT_VERSION:
            raise ScanError(f"{path}: format_version {version} is not {FORMAT_VERSION}")
        fields = {name: exact_array(arrays[name], f"{path}: {name}", dtype, ScanError)
                  for name, (dtype, _) in _PER_POINT.items()}
        if (fields["frame_index"] < 0).any() or (fields["range_sigma"] < 0).any():
            raise ScanError(f"{path}: frame_index and range_sigma: expected values >= 0")
        poses = {}
        for name in ("odom_start", "odom_end"):
            pose = exact_array(arrays.get(name, _NO_POSE), f"{path}: {name}", np.float64,
                               ScanError, allow_nan=True)
            if pose.shape != (4, 4) or not (np.isfinite(pose).all() or np.isnan(pose).all()):
                raise ScanError(f"{path}: {name}: expected a finite 4x4 pose or all NaN")
            poses[name] = pose
        index = _scalar(arrays, "index", path, 0)
        stamp = _scalar(arrays, "stamp", path, 0.0)
        if index < 0 or index != int(index):
            raise ScanError(f"{path}: index: expected an integer >= 0, got {index}")
        try:
            return cls(**fields, index=int(index), stamp=stamp, **poses)
        except ScanError as exc:
            raise ScanError(f"{path}: {exc}") from None

    def save_ply(self, path: str | os.PathLike[str]) -> None:
        """Write the coloured points as binary PLY through Open3D (atomically)."""
        import open3d as o3d

        cloud = o3d.geometry.PointCloud()
        cloud.points = o3d.utility.Vector3dVector(self.points.astype(np.float64))
        cloud.colors = o3d.utility.Vector3dVector(self.colors.astype(np.float64) / 255.0)
        with atomic_path(path) as tmp:
            tmp_ply = tmp.with_suffix(".ply")
            if not o3d.io.write_point_cloud(str(tmp_ply), cloud, write_ascii=False):
                raise ScanError(f"{path}: Open3D could not write the PLY file")
            os.replace(tmp_ply, tmp)


def _scalar(arrays: dict[str, np.ndarray], name: str, path: str | os.PathLike[str],
            default: float) -> float:
    """A finite number stored as a 0-d array (`default` when absent)."""
    value = exact_array(np.asarray(arrays.get(name, default)), f"{path}: {name}", np.float64,
                        ScanError)
    if value.shape != ():
        raise ScanError(f"{path}: {name}: expected a single number, got shape {value.shape}")
    return float(value)

