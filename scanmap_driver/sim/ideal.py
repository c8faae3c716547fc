"""Ideal scans: what the scanner measures, without rendering a single image.

For every frame of the simulated run (the same headings, frame times and poses as the
rendered recording), the laser fan is cast from the aperture, the stripe points the camera
sees are solved exactly on each image column (`laser_stripe`), and the strongest one per
column is kept, as the real pipeline does. The peak row is then disturbed by the
triangulation error model (Gaussian, `pixel_sigma` px along the image line) and
triangulated with the real `triangulate`, so every point carries the same validity limits
and `range_sigma` as a measured one. Fast enough for thousands of scans.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..scan import Scan
from ..scanner_model import ScannerModel, reference_scanner
from ..transforms import se2_to_pose
from ..triangulation import triangulate
from .geometry import World
from .laser_stripe import points_from_fan
from .motor_model import MotorModelConfig
from .plan import ScanPlan, plan_scans, stream
from .scene import Scene
from .texture import texture_factor

_NOISE = 10  # random stream purpose


@dataclass(frozen=True)
class IdealScan:
    """An ideal scan with its truth.

    scan: the measured points (noisy, in `base_link` at each point's frame), with
        odometry in `odom_start`/`odom_end`.
    true_points: (N, 3) the same points without noise, in `base_link`.
    pose_start, pose_end: true T_map_base at the first and last frame.
    frame_poses: (F, 4, 4) true T_map_base at each frame; frame_headings: (F,) true.
    """

    scan: Scan
    true_points: np.ndarray
    pose_start: np.ndarray
    pose_end: np.ndarray
    frame_poses: np.ndarray
    frame_headings: np.ndarray
    plan: ScanPlan


def ideal_scans(scene: Scene, model: ScannerModel | None = None, *, seed: int = 0,
                scans: int | None = None, pixel_sigma: float | None = None,
                heading_sigma: float = 0.0, motor: MotorModelConfig | None = None,
                threads: int = 0) -> Iterator[IdealScan]:
    """Ideal scans of the first `scans` scan poses (all by default), one at a time.

    pixel_sigma: peak error (px, along the image line); default the model's.
    heading_sigma: heading error (rad) per frame, as the encoder decoding would add.
    Deterministic for a seed; the same frames as `scanmap simulate` with that seed.
    The scene's people stand where they are at each scan (`Scene.at_scan`).
    """
    model = model or reference_scanner()
    sigma = model.pixel_sigma if pixel_sigma is None else pixel_sigma
    static = None if scene.people else World(scene, model.encoder)
    for plan in plan_scans(scene, model, seed, scans, motor):
        world = static or World(scene.at_scan(plan.index), model.encoder)
        yield _ideal_scan(world, model, plan, sigma, heading_sigma,
                          stream(seed, _NOISE, plan.index), threads)


def _ideal_scan(world: World, model: ScannerModel, plan: ScanPlan, pixel_sigma: float,
                heading_sigma: float, rng: np.random.Generator, threads: int) -> IdealScan:
    poses = plan.base_poses_at(plan.frame_times)
    headings = plan.frame_headings
    points = points_from_fan(world, model, poses, headings, threads)
    points = points.select(points.strongest_per_column())
    n = len(points)
    measured_heading = (headings + heading_sigma * rng.standard_normal(headings.shape[0]))
    v = points.v + pixel_sigma * rng.standard_normal(n)
    result = triangulate(model, points.u, v, measured_heading[points.frame])
    keep = result.valid
    points = points.select(keep)
    albedo = world.plane_albedo[points.plane]
    shade = texture_factor(points.map, points.plane, world.plane_axes,
                           world.scene.texture)[:, None]
    colors = np.clip(np.round(255.0 * albedo * shade), 0, 255).astype(np.uint8)
    scan = Scan(points=result.points_base[keep], colors=colors,
                time=plan.stamp + plan.frame_times[points.frame],
                heading=measured_heading[points.frame], frame_index=points.frame,
                range_sigma=result.range_sigma[keep], index=plan.index,
                stamp=plan.stamp + plan.frame_times[0],
                odom_start=se2_to_pose(*plan.odom_start), odom_end=se2_to_pose(*plan.odom_end))
    return IdealScan(scan, points.base, poses[0], poses[-1], poses, headings, plan)
