"""The rays of a scan in the map: each point, the camera centre it was seen from and the
laser emitter that lit it.

For this scanner every camera ray starts at the camera centre of its frame, which turns
with the head: origin = pose @ model.head_pose(heading) @ camera position; the light came
from the laser's emitter, which turns with it (`model.laser.origin`). The grid clears
space along both, so they must start where the camera and the emitter really were.
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
    return _turned(model, np.array(model.camera_mount.position, np.float64), headings)


def _turned(model: ScannerModel, mounted: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """(N, 3) in base_link: a point fixed in the head mount at the given headings (rad)."""
    headings = np.asarray(headings, dtype=np.float64)
    c, s = np.cos(headings), np.sin(headings)
    in_mount = np.column_stack([c * mounted[0] - s * mounted[1],
                                s * mounted[0] + c * mounted[1],
                                np.full(headings.shape, mounted[2])])
    return transform_points(model.head_mount.pose, in_mount)


def scan_rays(scan: Scan, model: ScannerModel,
              pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and ray origins (N, 3) of `scan` in map, float64.

    pose: 4x4 map <- base_link (identity when None), or (F, 4, 4) one per frame, indexed
    by the scan's frame_index (a robot moving during the scan).
    """
    return _rays_from(scan, model, np.array(model.camera_mount.position, np.float64), pose)


def laser_origins(scan: Scan, model: ScannerModel,
                  pose: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) in map: where the laser's light that lit each point of `scan` came from (the
    emitter, `model.laser.origin` in the head mount), as `scan_rays` takes `pose`."""
    return _rays_from(scan, model, np.array(model.laser.origin, np.float64), pose,
                      with_points=False)[1]


def _rays_from(scan: Scan, model: ScannerModel, mounted: np.ndarray,
               pose: np.ndarray | None, with_points: bool = True
               ) -> tuple[np.ndarray | None, np.ndarray]:
    """`scan_rays` from a point fixed in the head mount (the points None, and not carried
    to map, without `with_points`)."""
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
    if pose.shape[-2:] != (4, 4) or pose.ndim not in (2, 3) or not np.isfinite(pose).all():
        raise ScanError(f"scan_rays: pose must be a finite 4x4 or (F, 4, 4) array, got shape "
                        f"{pose.shape}")
    if pose.ndim == 2:
        centres = _turned(model, mounted, scan.heading)
        points = transform_points(pose, scan.points) if with_points else None
        return points, transform_points(pose, centres)
    frames = scan.frame_index
    if len(frames) and not (0 <= frames.min() and frames.max() < len(pose)):
        raise ScanError(f"scan_rays: frame_index spans {frames.min()}..{frames.max()} but "
                        f"{len(pose)} frame poses were given")
    points = np.empty((len(frames) if with_points else 0, 3))
    origins = np.empty((len(frames), 3))
    gk.frame_rays(np.ascontiguousarray(scan.points), np.ascontiguousarray(scan.heading,
                                                                          np.float64),
                  np.ascontiguousarray(frames), np.ascontiguousarray(pose),
                  np.ascontiguousarray(model.head_mount.pose, np.float64), mounted, points,
                  origins)
    return (points if with_points else None), origins
