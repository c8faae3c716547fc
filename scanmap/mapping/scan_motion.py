"""Where the robot was at each frame of a scan: the scan's pose plus its motion within the scan.

A scan takes about 2 s; a robot that keeps driving meanwhile sees each frame from
another pose. Registration returns the pose at the scan's start (the first point's time)
and de-skews with odometry's motion from the first frame to the last, interpolated at
constant velocity (`registration.deskew`). Fusion must place each frame's rays where
registration placed its points, so this module applies the same interpolation.
"""

from __future__ import annotations

import numpy as np

from scanmap.registration.lie import pose_exp, pose_log
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose

_STILL = 1e-9  # m and rad: below this the robot stood still during the scan


def scan_motion(scan: Scan) -> np.ndarray | None:
    """base_link at the scan's last frame in base_link at its first (4x4), None when the
    scan has no odometry or the robot did not move."""
    if not scan.has_odometry:
        return None
    motion = invert_pose(scan.odom_start) @ scan.odom_end
    if np.abs(pose_log(motion)).max() <= _STILL:
        return None
    return motion


def frame_poses(scan: Scan, pose: np.ndarray) -> np.ndarray:
    """Pose of base_link in map per frame: (4, 4) when the robot stood still (one pose for
    every frame), else (F, 4, 4) indexed by the scan's frame_index.

    pose: base_link in map at the scan's start, as registration returns it.
    """
    pose = np.asarray(pose, dtype=np.float64)
    motion = scan_motion(scan)
    if motion is None or len(scan) == 0:
        return pose
    t0, t1 = float(scan.time.min()), float(scan.time.max())
    if not t1 > t0:
        return pose
    frames = int(scan.frame_index.max()) + 1
    frame_time = np.full(frames, t0)
    frame_time[scan.frame_index] = scan.time
    fraction = np.clip((frame_time - t0) / (t1 - t0), 0.0, 1.0)
    twist = pose_log(motion)
    return np.array([pose @ pose_exp(s * twist) for s in fraction])
