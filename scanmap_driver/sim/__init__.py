"""The scanner simulator: scenes, ideal scans, rendered frames with ground truth, recordings.

Public API:

* `load_scene(path)`, `builtin_scene(name)`, `builtin_scene_names()`, `resolve_scene(name
  or path)` -> `Scene`: the `scanmap.scene/1` format (DESIGN.md), validated with errors
  naming the field. Built-in: `corridor` (1.5 m x 23 m, 50 poses 0.4 m apart) and
  `office` (6 x 5 m, table overhang, chair legs, low step, red objects; 24 poses).
* `ideal_scans(scene, model=None, *, seed=0, scans=None, pixel_sigma=None,
  heading_sigma=0.0)` -> iterator of `IdealScan` (a `scanmap_driver.scan.Scan` with
  odometry, its noise-free points and the true poses): the laser stripe cast directly,
  one point per image column, range noise from the triangulation error model. No images;
  thousands of scans in reasonable time. The same frames, headings and poses as a rendered
  recording with the same seed.
* `plan_scans(scene, model, seed, count)` -> `ScanPlan` per scan: frame times, the DC
  motor's heading profile, true poses and odometry.
"""

from .ideal import IdealScan, ideal_scans
from .plan import ScanPlan, plan_scans
from .scene import (
    Box,
    Cylinder,
    Scene,
    builtin_scene,
    builtin_scene_names,
    load_scene,
    resolve_scene,
)

__all__ = [
    "Box",
    "Cylinder",
    "IdealScan",
    "ScanPlan",
    "Scene",
    "builtin_scene",
    "builtin_scene_names",
    "ideal_scans",
    "load_scene",
    "plan_scans",
    "resolve_scene",
]
