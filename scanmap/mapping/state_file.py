"""The Mapper's map file: one `.npz` holding everything needed to use or resume a map.

It is a full map file of `map_io` (the grid's every layer, its configuration,
resolution, format version, and optional derived layers with their origin; `load_map`
reads it) plus the mapper's own arrays:

    mapper_format        "scanmap.mapper/1"
    mapper_config        JSON of `MapperConfig`
    scanner              JSON of the scanner model (`scanmap.scanner/1`)
    trajectory_stamps    (N,) s: when each scan started
    trajectory_poses     (N, 4, 4): base_link in map at each scan's start
    trajectory_index     (N,) int: each scan's index in its recording
    trajectory_status    (N,) str: its registration status
    trajectory_odometry  (N, 4, 4): its odometry pose (base_link in odom; NaN without)
    resume_points        (M, 3) float32: the newest scans' points in base_link of the
                         last pose, to register the next scan against after a restart
    resume_sigma         (M,) float32: their range sigma (m)
    points, point_colors (K, 3) float32 in map and uint8 RGB: kept points (overhead view)
    loop_closure_*       with loop closure only: the pose graph (`LoopCloser.state`:
                         poses, edges, measurements, information, clouds, cloud_sizes,
                         keyframes, optional fixed: the first nodes held) and the
                         Mapper's per-scan kept points for rebuilding the grid
                         (kept_points, kept_origins in base_link, kept_sizes (N,) with -1
                         for a scan not fused, kept_stamps; kept_unlit in base_link and
                         kept_unlit_sizes per fused scan, the floor its laser lines
                         crossed unlit, absent from older files; kept_lasers in
                         base_link, each kept ray's laser emitter, where the scans were
                         fused with the laser's rays); base_*: the grid's arrays
                         that rebuilds start from, when the graph began over a map
                         saved without one

Written atomically; read without pickle; a missing or malformed array is a MapError
naming the file and the array.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from scanmap.grid.height_grid import HeightGrid
from scanmap.io import map_files as map_io
from scanmap.mapping.config import MapperConfig
from scanmap.navigation.floor import Segmentation
from scanmap_driver.errors import CalibrationError, MapError
from scanmap_driver.files import exact_array, load_npz, save_npz
from scanmap_driver.scanner_model import ScannerModel

FORMAT = "scanmap.mapper/1"
_TRAJECTORY = ("stamps", "poses", "index", "status", "odometry")
_DTYPES = {"stamps": np.float64, "poses": np.float64, "index": np.int64,
           "odometry": np.float64, "resume_points": np.float32, "resume_sigma": np.float32,
           "points": np.float32, "point_colors": np.uint8}
_LOOPS = "loop_closure_"
_LOOP_ARRAYS = ("poses", "edges", "measurements", "information", "clouds", "cloud_sizes",
                "keyframes", "kept_points", "kept_origins", "kept_sizes", "kept_stamps")


@dataclass(frozen=True, eq=False)
class MapperState:
    """What a map file holds, as plain values (see the module docstring)."""

    grid: HeightGrid
    config: MapperConfig
    model: ScannerModel
    stamps: np.ndarray
    poses: np.ndarray
    index: np.ndarray
    status: np.ndarray
    odometry: np.ndarray
    resume_points: np.ndarray
    resume_sigma: np.ndarray
    points: np.ndarray
    point_colors: np.ndarray
    loop_closure: dict[str, np.ndarray] = field(default_factory=dict)


def save_state(path: str | os.PathLike[str], state: MapperState,
               segmentation: Segmentation | None = None) -> None:
    """Write `state` (and the derived obstacle and floor layers of `segmentation`)."""
    grid_config = state.grid.config
    layers = {}
    origin = (math.nan, math.nan)
    if segmentation is not None:
        layers = {"layer_state": segmentation.state,
                  "layer_floor_height": segmentation.floor_height}
        origin = segmentation.origin
    save_npz(path, format_version=np.array(map_io.FORMAT_VERSION),
             config=np.array(json.dumps(grid_config.to_dict())),
             resolution=np.array(grid_config.resolution), origin=np.array(origin),
             **state.grid.state(), **layers,
             mapper_format=np.array(FORMAT),
             mapper_config=np.array(json.dumps(state.config.to_dict())),
             scanner=np.array(json.dumps(state.model.to_dict())),
             **{f"trajectory_{name}": getattr(state, name) for name in _TRAJECTORY},
             resume_points=state.resume_points.astype(np.float32),
             resume_sigma=state.resume_sigma.astype(np.float32),
             points=state.points.astype(np.float32), point_colors=state.point_colors,
             **{f"{_LOOPS}{name}": value for name, value in state.loop_closure.items()})


def load_state(path: str | os.PathLike[str]) -> MapperState:
    """Read a map file written by `save_state`."""
    grid = map_io.load_map(path).grid
    names = ("mapper_format", "mapper_config", "scanner", "resume_points", "resume_sigma",
             "points", "point_colors", *(f"trajectory_{name}" for name in _TRAJECTORY))
    arrays = load_npz(path, MapError, required=names)
    if str(arrays["mapper_format"]) != FORMAT:
        raise MapError(f"{path}: mapper_format {str(arrays['mapper_format'])!r} is not "
                       f"{FORMAT!r}")
    config = MapperConfig.from_dict(_json(arrays, "mapper_config", path),
                                    source=f"{path}: mapper_config")
    if config.grid != grid.config:
        raise MapError(f"{path}: mapper_config.grid disagrees with the grid's config")
    try:
        model = ScannerModel.from_dict(_json(arrays, "scanner", path), source=f"{path}: scanner")
    except CalibrationError as exc:
        raise MapError(str(exc)) from None
    trajectory = {name: arrays[f"trajectory_{name}"] for name in _TRAJECTORY}
    if trajectory["status"].dtype.kind != "U":
        raise MapError(f"{path}: trajectory_status: expected text")
    for name, dtype in _DTYPES.items():  # values exactly as stored: no wrap, NaN or inf
        table, key = (trajectory, f"trajectory_{name}") if name in trajectory else (arrays, name)
        table[name] = exact_array(table[name], f"{path}: {key}", dtype, MapError,
                                  allow_nan=name == "odometry")
    n = trajectory["stamps"].shape[0] if trajectory["stamps"].ndim == 1 else -1
    shapes = {"stamps": (n,), "poses": (n, 4, 4), "index": (n,), "status": (n,),
              "odometry": (n, 4, 4)}
    for name, shape in shapes.items():
        if trajectory[name].shape != shape:
            raise MapError(f"{path}: trajectory_{name} must have shape {shape}, "
                           f"got {trajectory[name].shape}")
    if not np.isfinite(trajectory["poses"]).all():
        raise MapError(f"{path}: trajectory_poses holds non-finite values")
    m = len(arrays["resume_points"]) if arrays["resume_points"].ndim else -1
    _check_points(arrays, "resume_points", "resume_sigma", (m,), path)
    points = len(arrays["points"]) if arrays["points"].ndim else -1
    _check_points(arrays, "points", "point_colors", (points, 3), path)
    loops = {name[len(_LOOPS):]: value for name, value in arrays.items()
             if name.startswith(_LOOPS)}
    if loops:
        missing = [name for name in _LOOP_ARRAYS if name not in loops]
        if missing:
            raise MapError(f"{path}: the loop-closure graph lacks {missing}")
        for name in ("poses", "kept_sizes"):
            if len(loops[name]) != n:
                raise MapError(f"{path}: {_LOOPS}{name} must hold {n} entries, one per scan, "
                               f"got {len(loops[name])}")
        if "kept_lasers" in loops and loops["kept_lasers"].shape != loops["kept_points"].shape:
            raise MapError(f"{path}: {_LOOPS}kept_lasers must have the shape of "
                           f"{_LOOPS}kept_points, {loops['kept_points'].shape}, got "
                           f"{loops['kept_lasers'].shape}")
    return MapperState(grid=grid, config=config, model=model,
                       stamps=trajectory["stamps"].astype(np.float64),
                       poses=trajectory["poses"].astype(np.float64),
                       index=trajectory["index"].astype(np.int64),
                       status=trajectory["status"].astype(str),
                       odometry=trajectory["odometry"].astype(np.float64),
                       resume_points=arrays["resume_points"],
                       resume_sigma=arrays["resume_sigma"], points=arrays["points"],
                       point_colors=arrays["point_colors"].astype(np.uint8),
                       loop_closure=loops)


def _json(arrays: dict[str, np.ndarray], name: str, path: str | os.PathLike[str]) -> dict:
    try:
        return json.loads(str(arrays[name]))
    except json.JSONDecodeError as exc:
        raise MapError(f"{path}: {name} is not valid JSON ({exc})") from None


def _check_points(arrays: dict[str, np.ndarray], points: str, other: str,
                  other_shape: tuple[int, ...], path: str | os.PathLike[str]) -> None:
    p = arrays[points]
    if p.ndim != 2 or p.shape[1] != 3:
        raise MapError(f"{path}: {points} must have shape (M, 3), got {p.shape}")
    if arrays[other].shape != other_shape:
        raise MapError(f"{path}: {other} must have shape {other_shape}, "
                       f"got {arrays[other].shape}")
