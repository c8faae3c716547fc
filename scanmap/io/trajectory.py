"""Trajectories: timestamped poses and their TUM text files.

TUM format (one pose per line): `t tx ty tz qx qy qz qw`, `#` starts a comment. The error
measures against a reference are in `scanmap.evaluation.trajectory_errors`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanmap_driver.errors import MapError
from scanmap_driver.files import atomic_path
from scanmap_driver.transforms import (
    make_pose,
    quaternion_to_rotation,
    rotation_to_quaternion,
)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timestamped poses: times (N,) s, poses (N, 4, 4) float64 (base_link in map)."""

    times: np.ndarray
    poses: np.ndarray

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        poses = np.asarray(self.poses, dtype=np.float64)
        if poses.shape != (times.size, 4, 4):
            raise MapError(f"Trajectory: poses must be ({times.size}, 4, 4), got {poses.shape}")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "poses", poses)

    def __len__(self) -> int:
        return int(self.times.size)

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) translations."""
        return self.poses[:, :3, 3]


def write_tum(path: str | os.PathLike[str], trajectory: Trajectory) -> None:
    """Write `trajectory` as TUM text, atomically (full float64 precision)."""
    rows = [f"{t:.9f} " + " ".join(f"{v:.17g}" for v in
                                    (*pose[:3, 3], *rotation_to_quaternion(pose[:3, :3])))
            for t, pose in zip(trajectory.times, trajectory.poses, strict=True)]
    with atomic_path(path) as tmp:
        tmp.write_text("# t tx ty tz qx qy qz qw\n" + "".join(r + "\n" for r in rows))


def read_tum(path: str | os.PathLike[str]) -> Trajectory:
    """Read a TUM trajectory; MapError names the file and line of a malformed entry."""
    try:
        lines = Path(path).read_text().splitlines()
    except FileNotFoundError:
        raise MapError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"{path}: not a readable TUM trajectory ({exc})") from None
    times, poses = [], []
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            values = np.array(text.replace(",", " ").split(), dtype=np.float64)
        except ValueError:
            raise MapError(f"{path}:{number}: non-numeric field in {line!r}") from None
        if values.size != 8:
            raise MapError(f"{path}:{number}: expected 8 fields (t tx ty tz qx qy qz qw), "
                           f"got {values.size}")
        if not np.isfinite(values).all():
            raise MapError(f"{path}:{number}: non-finite value")
        norm = np.linalg.norm(values[4:])
        if abs(norm - 1.0) > 1e-3:
            raise MapError(f"{path}:{number}: quaternion norm {norm:.6f} is not 1")
        times.append(values[0])
        poses.append(make_pose(quaternion_to_rotation(values[4:]), values[1:4]))
    return Trajectory(np.array(times), np.array(poses).reshape(-1, 4, 4))
