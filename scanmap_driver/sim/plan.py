"""The timeline of a simulated run: per scan, when frames are taken, the head's heading, the
robot's true pose and its odometry.

A run visits the scene's scan poses in order. At each, the camera starts, the motor turns
the head once (plus an overlap) and brings it back (`motor_model`), while the robot
stands still or keeps driving at the scene's `motion` twist. Then it drives to the next
pose: turn, straight, turn. Odometry integrates this whole path with noise. Every
random draw comes from a stream keyed by (seed, purpose, scan), so a scan's plan does not
depend on how many scans are requested after it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..scanner_model import ScannerModel
from ..transforms import se2_to_pose
from .motor_model import MotorModelConfig, ScanMotion, scan_motion
from .odometry import arc_poses, dense_arc, dense_drive, odometry_path
from .scene import Motion, Scene

LEAD_FRAMES = 2  # frames the camera delivers before the motor starts
FRAME_JITTER = 2e-4  # s: standard deviation of frame timestamps
DRIVE_SPEED = 0.3  # m/s between scan poses
TURN_SPEED = 0.8  # rad/s when turning on the spot
SETTLE = 0.3  # s the robot waits after arriving before it scans
FIRST_STAMP = 0.5  # s from the start of the recording to the first scan

_MOTOR, _FRAMES, _ODOMETRY, _HEAD = 1, 2, 3, 4  # random stream purposes


def stream(seed: int, purpose: int, index: int = 0) -> np.random.Generator:
    """The random generator for one purpose (and scan) of a seeded run."""
    return np.random.default_rng([seed, purpose, index])


@dataclass(frozen=True)
class ScanPlan:
    """One scan of a run. Times are local: 0 is the motor's start command at `stamp`.

    frame_times: mid-exposure time of each captured frame (s, local).
    start_pose: true (x, y, yaw) of `base_link` in `map` at the first frame.
    odom_start, odom_end: odometry (x, y, yaw) in `odom` at the first and last frame.
    """

    index: int
    stamp: float
    motion: ScanMotion
    frame_times: np.ndarray
    start_pose: np.ndarray
    twist: Motion
    odom_start: np.ndarray
    odom_end: np.ndarray

    @property
    def frame_headings(self) -> np.ndarray:
        """True heading (rad) of the head at each frame's mid-exposure."""
        return self.motion.heading_at(self.frame_times)

    def poses_at(self, t: np.ndarray | float) -> np.ndarray:
        """True (N, 3) (x, y, yaw) of `base_link` in `map` at local times t.

        The robot drives its twist from the first frame to the last.
        """
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=np.float64)), self.frame_times[0],
                    self.frame_times[-1])
        return arc_poses(self.start_pose, self.twist.speed, self.twist.yaw_rate,
                         t - self.frame_times[0])

    def base_poses_at(self, t: np.ndarray | float) -> np.ndarray:
        """True (N, 4, 4) T_map_base at local times t."""
        return np.array([se2_to_pose(*p) for p in self.poses_at(t)])

    @property
    def end_pose(self) -> np.ndarray:
        """True (x, y, yaw) at the last frame."""
        return self.poses_at(self.frame_times[-1])[0]


def plan_scans(scene: Scene, model: ScannerModel, seed: int, count: int | None = None,
               motor: MotorModelConfig | None = None) -> list[ScanPlan]:
    """Plans for the first `count` scan poses of the scene (all when None)."""
    motor = motor or MotorModelConfig()
    total = scene.scan_poses.shape[0]
    count = total if count is None else count
    if not 1 <= count <= total:
        raise SceneError(f"scans: expected 1..{total} (the scene's scan poses), got {count}")
    period = 1.0 / model.camera.frame_rate
    heading = float(stream(seed, _HEAD).uniform(-math.pi, math.pi))
    stamp = FIRST_STAMP
    pieces: list[np.ndarray] = []
    marks: list[tuple[int, int]] = []  # dense-path indices of each scan's first/last frame
    drafts = []
    for index in range(count):
        motion = scan_motion(motor, stream(seed, _MOTOR, index), heading)
        frames_rng = stream(seed, _FRAMES, index)
        first = -LEAD_FRAMES * period + frames_rng.uniform(0.0, period)
        n = math.floor((motion.capture_end - first) / period) + 1
        times = first + period * np.arange(n) + FRAME_JITTER * frames_rng.standard_normal(n)
        start_pose = scene.scan_poses[index]
        if pieces:  # drive here from where the last scan ended
            pieces.append(dense_drive(pieces[-1][-1], start_pose)[1:])
        else:
            pieces.append(start_pose[None, :])
        start_mark = sum(len(p) for p in pieces) - 1
        arc = dense_arc(start_pose, scene.motion.speed, scene.motion.yaw_rate,
                        times[-1] - times[0])
        pieces.append(arc[1:])
        marks.append((start_mark, sum(len(p) for p in pieces) - 1))
        drafts.append((index, stamp, motion, times, start_pose))
        drive = dense_drive(arc[-1], scene.scan_poses[min(index + 1, total - 1)])
        travel = np.abs(np.diff(drive, axis=0))
        stamp += (motion.duration + float(np.hypot(travel[:, 0], travel[:, 1]).sum())
                  / DRIVE_SPEED + float(travel[:, 2].sum()) / TURN_SPEED + SETTLE)
        heading = motion.end_heading
    odometry = odometry_path(np.vstack(pieces), scene.odometry, stream(seed, _ODOMETRY))
    return [ScanPlan(index, stamp, motion, times, start_pose, scene.motion,
                     odometry[a], odometry[b])
            for (index, stamp, motion, times, start_pose), (a, b) in zip(drafts, marks,
                                                                         strict=True)]
