"""Map files: ROS map_server YAML + PGM for planners, and the full grid as .npz.

map_server (docs/architecture.md): an 8-bit PGM, row 0 at the top, free 254, occupied 0, unknown
205, and a YAML whose `origin` is the pose of the lower-left pixel. Writing follows the
map_saver: a value is free if <= free_thresh * 100, occupied if >= occupied_thresh * 100.
Every map_server (ROS 1, Nav2) reads a shade p as occupancy occ = (255 - p) / 255, occupied
if occ > occupied_thresh, else free if occ < free_thresh, else unknown; so the YAML gets
the thresholds of ROS 1's map_saver and of Nav2's since ros-navigation/navigation2 PR
#5278, 0.65 and 0.196, which put the unknown shade's occ 50 / 255 = 0.19608 between them
(with the user's free_thresh 0.25 every unknown cell would read as free). Our reader
applies the same rule, without exceptions.

The full map keeps every layer of the grid (levels, counts, observed masks, times), where
the robot stood (`stood`: floor it knows, which the segmentation reads; optional, absent
from files written before 2026-12-03), its configuration, resolution and origin, and a
format version. All writes are atomic.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap_driver.errors import MapError
from scanmap_driver.files import atomic_path, exact_array, load_npz, save_npz

FORMAT_VERSION = 5  # 2: the level record counts the scans that hit it (lev_n[..., SCANS]);
# 3: a cell records the last scan whose laser line crossed its floor unlit (cells[..., UNLIT]);
# 4: the level record keeps its mean hit's height (lev_f[..., MZ]); 5: a cell records where
# its lowest level was seen from (cells[..., FROM])
UNKNOWN_SHADE, FREE_SHADE, OCCUPIED_SHADE = 205, 254, 0
# The thresholds written to the YAML for readers: 254 (occ 0.0039) < 0.196 < 205 (0.19608)
# <= 0.65 < 0 (1.0), with the strict and the inclusive comparisons alike.
READ_FREE_THRESH, READ_OCCUPIED_THRESH = 0.196, 0.65


@dataclass(frozen=True, eq=False)
class RosMap:
    """An OccupancyGrid-style map: data (ny, nx) int8, row 0 at the lowest y."""

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float]  # x, y, yaw of the lower-left pixel


def save_ros_map(path: str | os.PathLike[str], occupancy: np.ndarray, resolution: float,
                 origin: tuple[float, float] | tuple[float, float, float],
                 occupied_thresh: float = 0.65, free_thresh: float = 0.25) -> Path:
    """Write `path` (.yaml) and the PGM beside it from int8 occupancy (row 0 = lowest y).

    The thresholds classify the occupancy values (percent); the YAML always carries
    READ_FREE_THRESH and READ_OCCUPIED_THRESH, which every map_server reads back right."""
    occupancy = np.asarray(occupancy)
    if occupancy.ndim != 2 or occupancy.size == 0 or not np.issubdtype(occupancy.dtype,
                                                                        np.integer):
        raise MapError(f"save_ros_map: occupancy must be a non-empty 2-D integer array, "
                       f"got {occupancy.dtype} of shape {occupancy.shape}")
    if not (0.0 <= free_thresh < occupied_thresh <= 1.0):
        raise MapError(f"save_ros_map: need 0 <= free_thresh < occupied_thresh <= 1, got "
                       f"{free_thresh}, {occupied_thresh}")
    yaml_path = Path(path)
    pgm_path = yaml_path.with_suffix(".pgm")
    values = occupancy.astype(np.int64)
    pixels = np.full(values.shape, UNKNOWN_SHADE, np.uint8)
    known = (values >= 0) & (values <= 100)
    pixels[known & (values <= round(free_thresh * 100))] = FREE_SHADE
    pixels[known & (values >= round(occupied_thresh * 100))] = OCCUPIED_SHADE
    ny, nx = pixels.shape
    with atomic_path(pgm_path) as tmp:
        tmp.write_bytes(f"P5\n{nx} {ny}\n255\n".encode() + pixels[::-1].tobytes())
    x, y = float(origin[0]), float(origin[1])
    yaw = float(origin[2]) if len(origin) > 2 else 0.0
    text = (f"image: {pgm_path.name}\nmode: trinary\nresolution: {float(resolution)!r}\n"
            f"origin: [{x!r}, {y!r}, {yaw!r}]\nnegate: 0\n"
            f"occupied_thresh: {READ_OCCUPIED_THRESH!r}\nfree_thresh: {READ_FREE_THRESH!r}\n")
    with atomic_path(yaml_path) as tmp:
        tmp.write_text(text)
    return pgm_path


def _parse_yaml(text: str, source: str) -> dict[str, object]:
    """The flat `key: value` YAML of map_server (scalars and [a, b, c] lists)."""
    out: dict[str, object] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        match = re.fullmatch(r"([A-Za-z_][\w]*)\s*:\s*(.*)", line)
        if not match:
            raise MapError(f"{source}:{number}: expected 'key: value', got {raw!r}")
        key, value = match.groups()
        if value.startswith("["):
            if not value.endswith("]"):
                raise MapError(f"{source}:{number}: unterminated list for {key}")
            items = [v.strip() for v in value[1:-1].split(",") if v.strip()]
            try:
                out[key] = [float(v) for v in items]
            except ValueError:
                raise MapError(f"{source}:{number}: {key} must be a list of numbers") from None
        else:
            out[key] = value.strip("'\"")
    return out


def _number(meta: dict[str, object], key: str, source: str, default: float | None = None,
            ) -> float:
    if key not in meta:
        if default is None:
            raise MapError(f"{source}: missing field {key}")
        return default
    try:
        value = float(meta[key])  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise MapError(f"{source}: {key} must be a number, got {meta[key]!r}") from None
    if not math.isfinite(value):
        raise MapError(f"{source}: {key} must be finite, got {value}")
    return value


def read_pgm(path: str | os.PathLike[str]) -> np.ndarray:
    """An 8- or 16-bit P5 (binary) or P2 (text) PGM as a 2-D array of 0-255 shades, row 0
    at the top. Values are scaled by the header's maxval as map_server's image loader
    does; OpenCV's PGM decoder ignores maxval, which is why this small reader stays."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise MapError(f"{path}: cannot read the image ({exc})") from None
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        match = re.compile(rb"\s*(#[^\n]*\n\s*)*(\S+)").match(data, pos)
        if not match:
            raise MapError(f"{path}: truncated PGM header")
        tokens.append(match.group(2))
        pos = match.end()
    magic = tokens[0]
    try:
        width, height, maxval = (int(t) for t in tokens[1:])
    except ValueError:
        raise MapError(f"{path}: PGM header has non-integer size or maxval") from None
    if magic not in (b"P5", b"P2") or width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise MapError(f"{path}: not a PGM (magic {magic!r}, {width} x {height}, max {maxval})")
    count = width * height
    if magic == b"P2":
        values = data[pos:].split()
        if len(values) < count:
            raise MapError(f"{path}: truncated PGM: {len(values)} of {count} pixels")
        try:
            pixels = np.array([int(v) for v in values[:count]], dtype=np.int64)
        except ValueError:
            raise MapError(f"{path}: PGM pixels must be integers") from None
    else:
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        body = data[pos + 1:pos + 1 + count * dtype.itemsize]
        if len(body) < count * dtype.itemsize:
            raise MapError(f"{path}: truncated PGM: {len(body)} of {count * dtype.itemsize} "
                           "pixel bytes")
        pixels = np.frombuffer(body, dtype=dtype).astype(np.int64)
    if pixels.max(initial=0) > maxval:
        raise MapError(f"{path}: pixel values exceed maxval {maxval}")
    return (pixels * 255 // maxval).reshape(height, width)


def load_ros_map(path: str | os.PathLike[str]) -> RosMap:
    """Read a map_server YAML and its image by map_server's rules (thresholds required, as
    there); MapError names the file and field at fault."""
    yaml_path = Path(path)
    try:
        meta = _parse_yaml(yaml_path.read_text(), str(yaml_path))
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"{yaml_path}: cannot read the map YAML ({exc})") from None
    source = str(yaml_path)
    if "image" not in meta:
        raise MapError(f"{source}: missing field image")
    resolution = _number(meta, "resolution", source)
    if resolution <= 0:
        raise MapError(f"{source}: resolution must be > 0, got {resolution}")
    origin = meta.get("origin")
    if not (isinstance(origin, list) and len(origin) == 3 and all(map(math.isfinite, origin))):
        raise MapError(f"{source}: origin must be a list of 3 finite numbers, got {origin!r}")
    occupied = _number(meta, "occupied_thresh", source)
    free = _number(meta, "free_thresh", source)
    if not 0.0 <= occupied <= 1.0:
        raise MapError(f"{source}: occupied_thresh must be within 0..1, got {occupied}")
    if not 0.0 <= free < occupied:
        raise MapError(f"{source}: free_thresh must be within 0..occupied_thresh "
                       f"({occupied}), got {free}")
    negate = _number(meta, "negate", source, 0.0)
    if negate not in (0.0, 1.0):
        raise MapError(f"{source}: negate must be 0 or 1, got {negate:g}")
    mode = str(meta.get("mode", "trinary"))
    if mode not in ("trinary", "scale"):
        raise MapError(f"{source}: mode {mode!r} is not supported (trinary, scale)")
    image = yaml_path.parent / str(meta["image"])
    shade = read_pgm(image)[::-1]  # row 0 = lowest y
    occ = shade / 255.0 if negate else 1.0 - shade / 255.0
    data = np.full(shade.shape, -1, np.int8)
    data[occ < free] = 0
    data[occ > occupied] = 100
    if mode == "scale":
        between = (occ >= free) & (occ <= occupied)
        data[between] = np.rint((occ[between] - free) / (occupied - free) * 100.0)
    return RosMap(data, resolution, (float(origin[0]), float(origin[1]), float(origin[2])))


def save_map(path: str | os.PathLike[str], grid: HeightGrid,
             layers: dict[str, np.ndarray] | None = None,
             origin: tuple[float, float] | None = None) -> None:
    """Write the whole grid (and optional dense derived layers with their origin) to .npz."""
    state = grid.state()
    extra = {f"layer_{name}": np.asarray(value) for name, value in (layers or {}).items()}
    if extra and origin is None:
        raise MapError("save_map: layers need the origin of their cell [0, 0]")
    save_npz(path, format_version=np.array(FORMAT_VERSION),
             config=np.array(json.dumps(grid.config.to_dict())),
             resolution=np.array(grid.config.resolution),
             origin=np.array(origin if origin is not None else (math.nan, math.nan)),
             **state, **extra)


@dataclass(frozen=True, eq=False)
class SavedMap:
    """A map read back: the grid, and the derived layers saved with it (origin of [0, 0])."""

    grid: HeightGrid
    layers: dict[str, np.ndarray]
    origin: tuple[float, float]


def _from_version_1(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A version-1 map read as version 2: its levels count no scans yet, so they clear as
    a briefly seen level does until later scans hit them (GridConfig.static_scans)."""
    lev_n = np.asarray(arrays["lev_n"])
    if lev_n.ndim == 0:
        return arrays
    scans = np.zeros(lev_n.shape[:-1] + (1,), lev_n.dtype)
    return {**arrays, "lev_n": np.concatenate([lev_n, scans], axis=-1)}


def _from_version_2(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A version-2 map read as version 3: no cell was seen unlit (`scanmap.grid.unlit`)."""
    cells = np.asarray(arrays["cells"])
    if cells.ndim != 3 or cells.shape[-1] != gk.UNLIT:
        return arrays  # from_state names the bad shape
    return {**arrays, "cells": np.concatenate([cells, np.zeros_like(cells[..., :1])], axis=-1)}


def _from_version_3(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A version-3 map read as version 4: each level's mean hit height is taken as the
    middle of its heights (what the floor's slope read before it was kept)."""
    lev_f = np.asarray(arrays["lev_f"])
    if lev_f.ndim != 3 or lev_f.shape[-1] != gk.MZ:
        return arrays  # from_state names the bad shape
    middle = 0.5 * (lev_f[..., gk.LO] + lev_f[..., gk.HI])
    return {**arrays, "lev_f": np.concatenate([lev_f, middle[..., None]], axis=-1)}


def _from_version_4(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A version-4 map read as version 5: where no cell's lowest level was seen from is
    known (a drop-off then keeps to where the robot stood, `scanmap.navigation.floor`)."""
    cells = np.asarray(arrays["cells"])
    if cells.ndim != 3 or cells.shape[-1] != gk.FROM:
        return arrays  # from_state names the bad shape
    return {**arrays, "cells": np.concatenate([cells, np.zeros_like(cells[..., :1])], axis=-1)}


def load_map(path: str | os.PathLike[str]) -> SavedMap:
    """Read a full map .npz; a corrupt, truncated or inconsistent file raises MapError."""
    required = ("format_version", "config", "resolution", "origin", "tile_coords",
                "scan_times", "stamp", "lev_f", "lev_n", "lev_flag", "nlev", "cells")
    arrays = load_npz(path, MapError, required=required)
    for key in ("format_version", "resolution", "stamp"):
        if arrays[key].shape != () or arrays[key].dtype.kind not in "iuf":
            raise MapError(f"{path}: {key} must be a real number, got "
                           f"{arrays[key].dtype} of shape {arrays[key].shape}")
    version = arrays["format_version"]
    if version not in (1, 2, 3, 4, FORMAT_VERSION):
        raise MapError(f"{path}: format_version {version} is not 1-{FORMAT_VERSION}")
    if version == 1:
        arrays = _from_version_1(arrays)
    if version in (1, 2):
        arrays = _from_version_2(arrays)
    if version in (1, 2, 3):
        arrays = _from_version_3(arrays)
    if version in (1, 2, 3, 4):
        arrays = _from_version_4(arrays)
    try:
        config = GridConfig(**json.loads(str(arrays["config"])))
    except (json.JSONDecodeError, TypeError) as exc:
        raise MapError(f"{path}: config is not a grid configuration ({exc})") from None
    except MapError as exc:
        raise MapError(f"{path}: {exc}") from None
    if float(arrays["resolution"]) != config.resolution:
        raise MapError(f"{path}: resolution {arrays['resolution']} disagrees with the config")
    grid = HeightGrid.from_state(config, arrays, source=str(path))
    layers = {key.removeprefix("layer_"): value for key, value in arrays.items()
              if key.startswith("layer_")}
    origin = exact_array(np.asarray(arrays["origin"]).reshape(-1)[:2], f"{path}: origin",
                         np.float64, MapError, allow_nan=True)  # NaN: no layers saved
    if origin.size != 2:
        raise MapError(f"{path}: origin must hold x and y, got {origin.size} values")
    origin = (float(origin[0]), float(origin[1]))
    return SavedMap(grid, layers, origin)
