"""The scanner simulator: scenes, ideal scans, rendered frames with ground truth, recordings.

Public API:

* `load_scene(path)`, `builtin_scene(name)`, `builtin_scene_names()`, `resolve_scene(name
  or path)` -> `Scene`: the `scanmap.scene/1` format (docs/architecture.md), validated with errors
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
* `Renderer(scene, model, camera=SimCameraConfig(), laser=LaserAppearance())` with
  `render(plan, frame, rng)` -> `RenderedFrame` (the MJPG bytes, the decoded BGR image as
  the webcam delivers it, and `FrameTruth`: heading, pose, every stripe point with its
  true 3D point in `head`/`base_link`/`map` and shadow flag, the laser pixel mask), and
  `light(plan, frame, rng)` for the radiance before the camera. A simulated camera renders
  the frame for the head's current heading with it.
* `simulate_recording(scene, out, model, seed=, scans=)` writes a raw recording
  (`scanmap_driver.recording`) with `ground_truth/` (`truth.ScanTruth`, `raster`);
  `simulate_ideal` writes ideal scans. `scanmap simulate` is the command line.
* `truth_raster(scene, resolution, low, high)`: `RASTER_OBSTACLE` / `RASTER_FLOOR` /
  `RASTER_DROP_OFF` / `RASTER_OUTSIDE` per cell, with the true floor height and slope.
  Scenes may hold floor regions at other heights and ramps (`FloorRegion`), glass,
  mirrors and black surfaces, and moving people (`Person`, `Scene.at_scan`).
  `truth_path(recording, index)`: where a scan's truth lives.
"""

from importlib import import_module
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .camera_effects import SimCameraConfig
    from .ideal import IdealScan, ideal_scans
    from .plan import ScanPlan, plan_scans
    from .raster import DROP_OFF as RASTER_DROP_OFF
    from .raster import FLOOR as RASTER_FLOOR
    from .raster import OBSTACLE as RASTER_OBSTACLE
    from .raster import OUTSIDE as RASTER_OUTSIDE
    from .raster import TruthRaster, truth_raster
    from .render import FrameTruth, LaserAppearance, RenderedFrame, Renderer
    from .scene import (
        Box,
        Cylinder,
        FloorRegion,
        Person,
        Scene,
        builtin_scene,
        builtin_scene_names,
        load_scene,
        resolve_scene,
    )
    from .simulate import simulate_ideal, simulate_recording
    from .truth import ScanTruth, truth_path

# Each public name is imported from its module on first use: reading ground truth or a
# scene must not load the ray caster (Open3D, about 1.5 s) that rendering needs.
_WHERE = {
    "SimCameraConfig": ("camera_effects", "SimCameraConfig"),
    "IdealScan": ("ideal", "IdealScan"), "ideal_scans": ("ideal", "ideal_scans"),
    "ScanPlan": ("plan", "ScanPlan"), "plan_scans": ("plan", "plan_scans"),
    "RASTER_DROP_OFF": ("raster", "DROP_OFF"), "RASTER_FLOOR": ("raster", "FLOOR"),
    "RASTER_OBSTACLE": ("raster", "OBSTACLE"), "RASTER_OUTSIDE": ("raster", "OUTSIDE"),
    "TruthRaster": ("raster", "TruthRaster"), "truth_raster": ("raster", "truth_raster"),
    "FrameTruth": ("render", "FrameTruth"), "LaserAppearance": ("render", "LaserAppearance"),
    "RenderedFrame": ("render", "RenderedFrame"), "Renderer": ("render", "Renderer"),
    **{name: ("scene", name) for name in (
        "Box", "Cylinder", "FloorRegion", "Person", "Scene", "builtin_scene",
        "builtin_scene_names", "load_scene", "resolve_scene")},
    "simulate_ideal": ("simulate", "simulate_ideal"),
    "simulate_recording": ("simulate", "simulate_recording"),
    "ScanTruth": ("truth", "ScanTruth"), "truth_path": ("truth", "truth_path"),
}


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, attribute = _WHERE[name]
    value = getattr(import_module(f"{__name__}.{module}"), attribute)
    globals()[name] = value
    return value


__all__ = [
    "RASTER_DROP_OFF",
    "RASTER_FLOOR",
    "RASTER_OBSTACLE",
    "RASTER_OUTSIDE",
    "Box",
    "Cylinder",
    "FloorRegion",
    "FrameTruth",
    "IdealScan",
    "LaserAppearance",
    "Person",
    "RenderedFrame",
    "Renderer",
    "ScanPlan",
    "ScanTruth",
    "Scene",
    "SimCameraConfig",
    "TruthRaster",
    "builtin_scene",
    "builtin_scene_names",
    "ideal_scans",
    "load_scene",
    "plan_scans",
    "resolve_scene",
    "simulate_ideal",
    "simulate_recording",
    "truth_path",
    "truth_raster",
]
