"""The rays of a scan in the map: each point and the camera centre it was seen from.

For this scanner every ray starts at the camera centre of its frame, which turns with
the head: origin = pose @ model.head_pose(heading) @ camera position. The grid clears
space along these rays, so they must start where the camera really was.
"""

from __future__ import annotations

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap_driver.errors import ScanError
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel
from scanmap_driver.transforms import transform_points


def camera_centres(model: ScannerModel, headings: np.ndarray) -> np.ndarray:
    """(N, 3) camera centres in base_link at the given head headings (rad)."""
    headings = np.asarray(headings, dtype=np.float64)
    camera = np.array(model.camera_mount.position)
    c, s = np.cos(headings), np.sin(headings)
    in_mount = np.column_stack([c * camera[0] - s * camera[1], s * camera[0] + c * camera[1],
                                np.full(headings.shape, camera[2])])
    return transform_points(model.head_mount.pose, in_mount)


def scan_rays(scan: Scan, model: ScannerModel,
              pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and ray origins (N, 3) of `scan` in map, float64.

    pose: 4x4 map <- base_link (identity when None), or (F, 4, 4) one per frame, indexed
    by the scan's frame_index (a robot moving during the scan).
    """
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
    if pose.shape[-2:] != (4, 4) or pose.ndim not in (2, 3) or not np.isfinite(pose).all():
        raise ScanError(f"scan_rays: pose must be a finite 4x4 or (F, 4, 4) array, got shape "
                        f"{pose.shape}")
    if pose.ndim == 2:
        centres = camera_centres(model, scan.heading)
        return transform_points(pose, scan.points), transform_points(pose, centres)
    frames = scan.frame_index
    if len(frames) and not (0 <= frames.min() and frames.max() < len(pose)):
        raise ScanError(f"scan_rays: frame_index spans {frames.min()}..{frames.max()} but "
                        f"{len(pose)} frame poses were given")
    points, origins = np.empty((len(frames), 3)), np.empty((len(frames), 3))
    gk.frame_rays(np.ascontiguousarray(scan.points), np.ascontiguousarray(scan.heading,
                                                                          np.float64),
                  np.ascontiguousarray(frames), np.ascontiguousarray(pose),
                  np.ascontiguousarray(model.head_mount.pose, np.float64),
                  np.array(model.camera_mount.position, np.float64), points, origins)
    return points, origins
