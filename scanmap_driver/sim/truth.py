"""Ground truth of a simulated recording: per scan, per frame and per laser pixel.

`ground_truth/scan_NNNN.npz` (no pickle) holds, for F frames and M stripe points:

    format_version        1
    frame_time (F,)       recording time (s) of each frame's mid-exposure
    frame_heading (F,)    true heading (rad, unwrapped) at mid-exposure
    frame_pose (F, 4, 4)  true T_map_base at mid-exposure
    pose_start, pose_end  true T_map_base at the first and last frame
    odom_start, odom_end  the recorded odometry, T_odom_base (4, 4)
    laser_frame (M,)      frame of each stripe point
    laser_u, laser_v (M,) its column (integer valued) and the stripe centre's subpixel row
    laser_heading (M,)    true heading when that row was exposed (differs from the frame's
                          only under a rolling shutter)
    laser_head, laser_base, laser_map (M, 3)   the true 3D point in each frame
    laser_shadowed (M,)   true where the camera sees the laser plane on the surface but the
                          laser cannot reach it (no light is drawn there)
    laser_primary (M,)    the strongest lit point of its column: what one range per image
                          line should find
    laser_strength (M,)   relative laser irradiance x red albedo (0 when shadowed)
    laser_object (M,)     scene object index (0 = floor, i + 1 = the scene's objects[i])
    laser_mask (F, H, W/8) packed bits (np.packbits along rows): pixels the laser brightens
    image_size (2,)       (width, height)

`ground_truth/scene.json` is the scene as simulated (lighting applied) and
`ground_truth/raster.npz` the ground-truth raster (`raster`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import RecordingError
from ..files import load_npz, save_npz
from ..recording import GROUND_TRUTH, scan_name
from ..transforms import se2_to_pose

if TYPE_CHECKING:  # the renderer (and Open3D) is not needed to read truth files
    from .plan import ScanPlan
    from .render import FrameTruth

FORMAT_VERSION = 1
_LASER = ("frame", "u", "v", "heading", "head", "base", "map", "shadowed", "primary",
          "strength", "object")


@dataclass(frozen=True)
class ScanTruth:
    """The truth of one scan; see the module docstring for the fields."""

    frame_time: np.ndarray
    frame_heading: np.ndarray
    frame_pose: np.ndarray
    pose_start: np.ndarray
    pose_end: np.ndarray
    odom_start: np.ndarray
    odom_end: np.ndarray
    laser: dict[str, np.ndarray]
    laser_mask: np.ndarray  # (F, H, W) bool; (0, 0, 0) when loaded without it

    @classmethod
    def from_frames(cls, plan: ScanPlan, frames: list[FrameTruth],
                    plane_object: np.ndarray) -> ScanTruth:
        """Collect the truth of a scan's rendered frames."""
        parts: dict[str, list[np.ndarray]] = {key: [] for key in _LASER}
        for number, truth in enumerate(frames):
            s = truth.stripe
            for key, value in (("frame", np.full(len(s), number, dtype=np.int32)),
                               ("u", s.u), ("v", s.v), ("heading", s.heading),
                               ("head", s.head), ("base", s.base), ("map", s.map),
                               ("shadowed", ~s.lit), ("primary", truth.primary),
                               ("strength", s.strength.astype(np.float32)),
                               ("object", plane_object[s.plane].astype(np.int32))):
                parts[key].append(value)
        poses = np.array([t.base_pose for t in frames])
        return cls(frame_time=plan.stamp + np.array([t.time for t in frames]),
                   frame_heading=np.array([t.heading for t in frames]), frame_pose=poses,
                   pose_start=poses[0], pose_end=poses[-1],
                   odom_start=se2_to_pose(*plan.odom_start),
                   odom_end=se2_to_pose(*plan.odom_end),
                   laser={key: np.concatenate(value) for key, value in parts.items()},
                   laser_mask=np.array([t.laser_mask for t in frames]))

    def frame(self, index: int) -> dict[str, np.ndarray]:
        """The laser truth rows of one frame."""
        rows = self.laser["frame"] == index
        return {key: value[rows] for key, value in self.laser.items()}

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the truth as `.npz` (atomically)."""
        if self.laser_mask.ndim != 3 or not self.laser_mask.shape[0] == len(self.frame_time):
            raise RecordingError(f"{path}: the truth has no laser mask for its "
                                 f"{len(self.frame_time)} frames (loaded with mask=False?)")
        if set(self.laser) != set(_LASER):
            raise RecordingError(f"{path}: the truth lacks the laser fields "
                                 f"{sorted(set(_LASER) - set(self.laser))} (loaded in part?)")
        height, width = self.laser_mask.shape[1:]
        save_npz(path, format_version=np.array(FORMAT_VERSION), frame_time=self.frame_time,
                 frame_heading=self.frame_heading, frame_pose=self.frame_pose,
                 pose_start=self.pose_start, pose_end=self.pose_end,
                 odom_start=self.odom_start, odom_end=self.odom_end,
                 laser_mask=np.packbits(self.laser_mask, axis=2),
                 image_size=np.array([width, height]),
                 **{f"laser_{key}": value for key, value in self.laser.items()})

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, mask: bool = True,
             laser: tuple[str, ...] = _LASER) -> ScanTruth:
        """Read a scan's truth; a malformed file raises RecordingError naming it.

        mask=False leaves the laser pixel mask out (half the reading time; range and
        heading errors do not need it); `laser` names the laser point fields to read (the
        others are left out of `laser`, and their decompression saved)."""
        unknown = set(laser) - set(_LASER)
        if unknown:
            raise ValueError(f"ScanTruth.load: unknown laser fields {sorted(unknown)}")
        names = ("format_version", "frame_time", "frame_heading", "frame_pose", "pose_start",
                 "pose_end", "odom_start", "odom_end", "laser_mask", "image_size",
                 *(f"laser_{key}" for key in _LASER))
        skipped = tuple(f"laser_{key}" for key in _LASER if key not in laser)
        arrays = load_npz(path, RecordingError, required=names,
                          skip=skipped if mask else ("laser_mask", *skipped))
        if int(arrays["format_version"]) != FORMAT_VERSION:
            raise RecordingError(f"{path}: format_version {int(arrays['format_version'])} "
                                 f"is not {FORMAT_VERSION}")
        width, height = (int(x) for x in arrays["image_size"])
        pixels = np.zeros((0, 0, 0), bool)
        if mask:
            pixels = np.unpackbits(arrays["laser_mask"], axis=2, count=width).astype(bool)
            if pixels.shape[1] != height:
                raise RecordingError(f"{path}: laser_mask does not match image_size")
        return cls(frame_time=arrays["frame_time"], frame_heading=arrays["frame_heading"],
                   frame_pose=arrays["frame_pose"], pose_start=arrays["pose_start"],
                   pose_end=arrays["pose_end"], odom_start=arrays["odom_start"],
                   odom_end=arrays["odom_end"],
                   laser={key: arrays[f"laser_{key}"] for key in laser}, laser_mask=pixels)


def truth_path(recording: str | os.PathLike[str], index: int) -> Path:
    """Where scan `index`'s truth lives in a recording folder."""
    return Path(recording) / GROUND_TRUTH / f"{scan_name(index)}.npz"
