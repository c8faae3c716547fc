"""Simulator scenes in the `scanmap.scene/1` JSON format (docs/architecture.md), validated on load.

A scene is the floor (the plane z = 0), boxes and vertical cylinders with RGB colours, an
ambient light level (0 dark room .. 1 bright room) and the robot's stop-and-scan poses
(x, y, yaw) in `map`. Optional keys this module adds to the format (docs/architecture.md allows
added keys; an unknown key is an error):

* `description`: free text.
* `texture`: contrast (0..1) of the procedural surface texture, default 0.25.
* `motion`: `{"speed": m/s, "yaw_rate": rad/s}`, the robot keeps driving at this body
  twist while the head turns (default: stands still during a scan).
* `odometry`: wheel-odometry noise, see `SimOdometryNoise`.
* on an object: `name` (free text), `surface` and `reflectance` (as on a floor region).
* `floor_regions`: patches of floor at other heights, each a convex `polygon`
  ([[x, y], ...] in `map`, counter-clockwise) or a rectangle (`center` [x, y], `size`
  [sx, sy], `yaw`), with `height` (m: the surface's height at the region's centroid;
  below 0 a hole, stairwell or step down, above 0 a platform), an optional `gradient`
  ([dz/dx, dz/dy]: a ramp, the inclined plane height + gradient . (xy - centroid)),
  `color`, `surface`, `reflectance` and `name`. The surface must lie wholly at or above
  0, or wholly at or below 0 (vertical faces join it to the floor z = 0); regions must
  not overlap one another.
* `surface` (the material): "matte" (default), "glass" (transparent: the laser and the camera pass
  through, nothing returns) or "mirror" (opaque, but the laser returns no stripe);
  `reflectance` (0..1, default 1) scales the laser light a matte surface returns, and 0
  returns none (black carpet).
* `people`: vertical cylinders that move: `radius`, `height`, `color`, `name` and a
  `track` [[scan, x, y], ...] (scan indices increasing): the person stands at the
  track's position for each scan, linearly interpolated between its points and held
  beyond its ends (`Scene.at_scan`). People are no part of the static scene (nor of its
  truth raster); `at_scan(i)` places them as cylinders.

Built-in scenes live as JSON files beside this module (`scenes/<name>.json`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError
from ..files import read_json, write_json
from ..validate import check_keys, number, vector

FORMAT = "scanmap.scene/1"
LIGHTING = {"dark": 0.03, "bright": 0.9}  # ambient levels of the --lighting presets
SCENES_DIR = Path(__file__).resolve().parent / "scenes"
DEFAULT_TEXTURE = 0.25
MATERIALS = ("matte", "glass", "mirror")


@dataclass(frozen=True)
class Box:
    """A box: middle at `center`, extent `size` along its own axes, turned by `yaw` about z."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    color: tuple[int, int, int]
    yaw: float = 0.0
    name: str = ""
    material: str = "matte"
    reflectance: float = 1.0


@dataclass(frozen=True)
class Cylinder:
    """A vertical cylinder with its middle at `center`."""

    center: tuple[float, float, float]
    radius: float
    height: float
    color: tuple[int, int, int]
    name: str = ""
    material: str = "matte"
    reflectance: float = 1.0


@dataclass(frozen=True)
class FloorRegion:
    """Floor at another height over a convex polygon (see the module docstring)."""

    polygon: tuple[tuple[float, float], ...]
    height: float
    gradient: tuple[float, float] = (0.0, 0.0)
    color: tuple[int, int, int] = (128, 128, 128)
    material: str = "matte"
    reflectance: float = 1.0
    name: str = ""

    @property
    def corners(self) -> np.ndarray:
        """(K, 2) polygon corners, counter-clockwise."""
        return np.array(self.polygon, dtype=np.float64)

    def height_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Height of the region's surface plane at (x, y)."""
        cx, cy = self.corners.mean(axis=0)
        return self.height + self.gradient[0] * (np.asarray(x) - cx) \
            + self.gradient[1] * (np.asarray(y) - cy)

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether the points (x, y) lie inside the polygon (edges included)."""
        c = self.corners
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        inside = np.ones(np.broadcast(x, y).shape, dtype=bool)
        for (ax, ay), (bx, by) in zip(c, np.roll(c, -1, axis=0), strict=True):
            inside &= (bx - ax) * (y - ay) - (by - ay) * (x - ax) >= -1e-12
        return inside


@dataclass(frozen=True)
class Person:
    """A moving vertical cylinder: at scan s it stands at `track` interpolated at s."""

    radius: float
    height: float
    color: tuple[int, int, int]
    track: np.ndarray  # (T, 3): scan index, x, y; scan indices increasing
    name: str = ""

    def at_scan(self, index: float) -> Cylinder:
        """The person as a cylinder standing where it is at scan `index`."""
        t = self.track
        x, y = np.interp(index, t[:, 0], t[:, 1]), np.interp(index, t[:, 0], t[:, 2])
        return Cylinder((float(x), float(y), 0.5 * self.height), self.radius, self.height,
                        self.color, self.name)


@dataclass(frozen=True)
class Motion:
    """The robot's body twist while a scan is taken (zero: stop-and-scan)."""

    speed: float = 0.0
    yaw_rate: float = 0.0


@dataclass(frozen=True)
class SimOdometryNoise:
    """Wheel-odometry errors: random per metre driven, and systematic (calibration) biases.

    distance_sigma: relative distance error per sqrt(m) (random walk).
    heading_sigma: heading error (rad) per sqrt(m) driven.
    turn_sigma: relative error of each turn angle.
    distance_bias: systematic relative distance error (wheel radius mis-calibration).
    heading_bias: systematic heading drift (rad) per metre (unequal wheels).
    """

    distance_sigma: float = 0.01
    heading_sigma: float = 0.01
    turn_sigma: float = 0.02
    distance_bias: float = 0.01
    heading_bias: float = 0.005


@dataclass(frozen=True)
class Scene:
    """A validated scene; build it with `Scene.from_dict`, `load_scene` or `builtin_scene`."""

    name: str
    floor_color: tuple[int, int, int]
    ambient: float
    objects: tuple[Box | Cylinder, ...]
    scan_poses: np.ndarray  # (K, 3) float64: x, y, yaw in `map`
    texture: float = DEFAULT_TEXTURE
    motion: Motion = field(default_factory=Motion)
    odometry: SimOdometryNoise = field(default_factory=SimOdometryNoise)
    description: str = ""
    floor_regions: tuple[FloorRegion, ...] = ()
    people: tuple[Person, ...] = ()

    def with_ambient(self, ambient: float) -> Scene:
        """The same scene under another light level (0 dark .. 1 bright)."""
        return replace(self, ambient=float(ambient))

    def at_scan(self, index: float) -> Scene:
        """The scene as scan `index` sees it: its people placed as cylinders (static)."""
        if not self.people:
            return self
        return replace(self, objects=self.objects + tuple(p.at_scan(index) for p in self.people),
                       people=())

    def moved(self, dx: float, dy: float, yaw: float = 0.0) -> Scene:
        """The same scene turned by `yaw` (rad) about the origin, then shifted by (dx, dy)
        m: objects, floor regions (and their gradients), people's tracks and scan poses.
        The world is the same; only how it falls on a map's cells changes (a hazard's edge
        off the cell boundaries, walls at an angle to the grid)."""
        c, s = math.cos(yaw), math.sin(yaw)
        turn = np.array([[c, -s], [s, c]])
        shift = np.array([dx, dy], dtype=np.float64)

        def place(xy: Any) -> np.ndarray:
            return np.asarray(xy, dtype=np.float64) @ turn.T + shift

        def placed(thing: Box | Cylinder) -> Box | Cylinder:
            x, y = place(thing.center[:2])
            center = (float(x), float(y), thing.center[2])
            if isinstance(thing, Box):
                return replace(thing, center=center, yaw=thing.yaw + yaw)
            return replace(thing, center=center)

        regions = tuple(replace(r, polygon=tuple(map(tuple, place(r.polygon).tolist())),
                                gradient=tuple((turn @ np.asarray(r.gradient)).tolist()))
                        for r in self.floor_regions)
        people = tuple(replace(p, track=np.column_stack([p.track[:, 0], place(p.track[:, 1:])]))
                       for p in self.people)
        poses = np.column_stack([place(self.scan_poses[:, :2]), self.scan_poses[:, 2] + yaw])
        return replace(self, objects=tuple(placed(o) for o in self.objects),
                       floor_regions=regions, people=people, scan_poses=poses)

    def floor_at(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True floor height and slope (rad) at the points (x, y) in `map`."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        height = np.zeros(np.broadcast(x, y).shape)
        slope = np.zeros_like(height)
        for region in self.floor_regions:
            inside = region.contains(x, y)
            height = np.where(inside, region.height_at(x, y), height)
            slope = np.where(inside, math.atan(math.hypot(*region.gradient)), slope)
        return height, slope

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min_xy, max_xy) of the objects and scan poses in `map` (m)."""
        corners = [self.scan_poses[:, :2]]
        for obj in self.objects:
            corners.append(footprint_corners(obj))
        corners.extend(region.corners for region in self.floor_regions)
        corners.extend(p.track[:, 1:] + sign * p.radius for p in self.people for sign in (-1, 1))
        stacked = np.vstack(corners)
        return stacked.min(axis=0), stacked.max(axis=0)

    # -- JSON -----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The `scanmap.scene/1` JSON object."""
        objects = []
        for obj in self.objects:
            if isinstance(obj, Box):
                item = {"type": "box", "center": list(obj.center), "size": list(obj.size),
                        "yaw": obj.yaw, "color": list(obj.color)}
            else:
                item = {"type": "cylinder", "center": list(obj.center), "radius": obj.radius,
                        "height": obj.height, "color": list(obj.color)}
            if obj.name:
                item["name"] = obj.name
            item |= _material_dict(obj)
            objects.append(item)
        data = {"format": FORMAT, "name": self.name, "description": self.description,
                "floor": {"color": list(self.floor_color)}, "ambient": self.ambient,
                "texture": self.texture,
                "motion": {"speed": self.motion.speed, "yaw_rate": self.motion.yaw_rate},
                "odometry": {k: getattr(self.odometry, k)
                             for k in SimOdometryNoise.__dataclass_fields__},
                "objects": objects, "scan_poses": self.scan_poses.tolist()}
        if self.floor_regions:
            data["floor_regions"] = [
                {"polygon": [list(c) for c in r.polygon], "height": r.height,
                 "gradient": list(r.gradient), "color": list(r.color), "name": r.name}
                | _material_dict(r) for r in self.floor_regions]
        if self.people:
            data["people"] = [{"radius": p.radius, "height": p.height, "color": list(p.color),
                               "track": p.track.tolist(), "name": p.name}
                              for p in self.people]
        return data

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as `scanmap.scene/1` JSON (atomically)."""
        write_json(path, self.to_dict())

    @classmethod
    def from_dict(cls, data: Any, source: str = "scene") -> Scene:
        """Validate and build a scene; errors name `source` and the bad field."""
        err = SceneError

        def where(name: str) -> str:
            return f"{source}: {name}"

        top = check_keys(data, where("(top level)"), err,
                         ["format", "floor", "ambient", "objects", "scan_poses"],
                         ["name", "description", "texture", "motion", "odometry",
                          "floor_regions", "people"])
        if top["format"] != FORMAT:
            raise err(f"{where('format')}: expected {FORMAT!r}, got {top['format']!r}")
        floor = check_keys(top["floor"], where("floor"), err, ["color"])
        if not isinstance(top["objects"], list):
            raise err(f"{where('objects')}: expected a list of objects")
        objects = tuple(_object(item, where(f"objects[{i}]"))
                        for i, item in enumerate(top["objects"]))
        poses = top["scan_poses"]
        if not isinstance(poses, list) or not poses:
            raise err(f"{where('scan_poses')}: expected a non-empty list of [x, y, yaw]")
        scan_poses = np.array([vector(p, 3, where(f"scan_poses[{i}]"), err)
                               for i, p in enumerate(poses)])
        motion = check_keys(top.get("motion", {}), where("motion"), err, [],
                            ["speed", "yaw_rate"])
        odom = check_keys(top.get("odometry", {}), where("odometry"), err, [],
                          list(SimOdometryNoise.__dataclass_fields__))
        defaults = SimOdometryNoise()
        odometry = SimOdometryNoise(**{
            k: number(odom.get(k, getattr(defaults, k)), where(f"odometry.{k}"), err,
                      low=None if k.endswith("bias") else 0.0)
            for k in SimOdometryNoise.__dataclass_fields__})
        for key in ("name", "description"):
            if not isinstance(top.get(key, ""), str):
                raise err(f"{where(key)}: expected a string")
        regions = tuple(_floor_region(item, where(f"floor_regions[{i}]"))
                        for i, item in enumerate(_list(top, "floor_regions", where)))
        for i, a in enumerate(regions):
            for j in range(i + 1, len(regions)):
                if _overlap(a.corners, regions[j].corners):
                    raise err(f"{where(f'floor_regions[{j}]')}: overlaps floor_regions[{i}] "
                              f"({a.name or 'unnamed'}); regions may share edges, not area")
        people = tuple(_person(item, where(f"people[{i}]"))
                       for i, item in enumerate(_list(top, "people", where)))
        return cls(
            name=top.get("name", Path(source).stem),
            floor_color=_color(floor["color"], where("floor.color")),
            ambient=number(top["ambient"], where("ambient"), err, low=0.0, high=1.0),
            objects=objects,
            scan_poses=scan_poses,
            texture=number(top.get("texture", DEFAULT_TEXTURE), where("texture"), err,
                           low=0.0, high=1.0),
            motion=Motion(
                speed=number(motion.get("speed", 0.0), where("motion.speed"), err),
                yaw_rate=number(motion.get("yaw_rate", 0.0), where("motion.yaw_rate"), err)),
            odometry=odometry,
            description=top.get("description", ""),
            floor_regions=regions,
            people=people,
        )


def footprint_corners(obj: Box | Cylinder) -> np.ndarray:
    """(4, 2) corners in `map` of the object's footprint (its bounding square for a cylinder)."""
    if isinstance(obj, Cylinder):
        half = np.array([obj.radius, obj.radius])
        yaw = 0.0
    else:
        half = 0.5 * np.array(obj.size[:2])
        yaw = obj.yaw
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
    c, s = math.cos(yaw), math.sin(yaw)
    return (signs * half) @ np.array([[c, s], [-s, c]]) + np.array(obj.center[:2])


def _color(value: Any, where: str) -> tuple[int, int, int]:
    """An RGB colour: three integers 0..255."""
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255
                       for c in value)):
        raise SceneError(f"{where}: expected [r, g, b] integers 0..255, got {value!r}")
    return (value[0], value[1], value[2])


def _list(top: Any, key: str, where: Callable[[str], str]) -> list:
    """The optional list `top[key]` (empty when absent)."""
    value = top.get(key, [])
    if not isinstance(value, list):
        raise SceneError(f"{where(key)}: expected a list")
    return value


def _material_dict(obj: Box | Cylinder | FloorRegion) -> dict[str, Any]:
    """The material keys of an object or region that differ from the defaults."""
    out: dict[str, Any] = {}
    if obj.material != "matte":
        out["surface"] = obj.material
    if obj.reflectance != 1.0:
        out["reflectance"] = obj.reflectance
    return out


def _material(item: dict, where: str) -> tuple[str, float]:
    """Validated `surface` (material) and `reflectance` of an object or region."""
    material = item.get("surface", "matte")
    if material not in MATERIALS:
        raise SceneError(f"{where}.surface: expected one of {', '.join(MATERIALS)}, "
                         f"got {material!r}")
    return material, number(item.get("reflectance", 1.0), f"{where}.reflectance", SceneError,
                            low=0.0, high=1.0)


def _name(item: dict, where: str) -> str:
    name = item.get("name", "")
    if not isinstance(name, str):
        raise SceneError(f"{where}.name: expected a string")
    return name


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons (K, 2) share area: no edge normal of either separates
    their projections (polygons that only touch along an edge or at a corner do not)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for normal in np.column_stack([edges[:, 1], -edges[:, 0]]):
            pa, pb = a @ normal, b @ normal
            slack = 1e-9 * float(np.abs(normal).sum())
            if pa.max() <= pb.min() + slack or pb.max() <= pa.min() + slack:
                return False
    return True


def _floor_region(item: Any, where: str) -> FloorRegion:
    """One validated floor region: a convex polygon or a rectangle."""
    err = SceneError
    common = ["height", "gradient", "color", "surface", "reflectance", "name"]
    if isinstance(item, dict) and "polygon" in item:
        check_keys(item, where, err, ["polygon", "height"], common)
        points = item["polygon"]
        if not isinstance(points, list) or len(points) < 3:
            raise err(f"{where}.polygon: expected at least 3 [x, y] corners")
        corners = np.array([vector(p, 2, f"{where}.polygon[{i}]", err)
                            for i, p in enumerate(points)])
    else:
        check_keys(item, where, err, ["center", "size", "height"], ["yaw", *common])
        center = vector(item["center"], 2, f"{where}.center", err)
        size = vector(item["size"], 2, f"{where}.size", err)
        if (size <= 0.0).any():
            raise err(f"{where}.size: expected two numbers > 0, got {item['size']!r}")
        yaw = number(item.get("yaw", 0.0), f"{where}.yaw", err)
        c, s = math.cos(yaw), math.sin(yaw)
        local = 0.5 * size * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
        corners = local @ np.array([[c, s], [-s, c]]) + center
    edges = np.roll(corners, -1, axis=0) - corners
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] \
        - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    if not (turns > 0.0).all():
        raise err(f"{where}.polygon: expected a convex polygon, counter-clockwise")
    material, reflectance = _material(item, where)
    region = FloorRegion(
        polygon=tuple((float(x), float(y)) for x, y in corners),
        height=number(item["height"], f"{where}.height", err),
        gradient=tuple(vector(item.get("gradient", [0.0, 0.0]), 2, f"{where}.gradient", err)),
        color=_color(item.get("color", [128, 128, 128]), f"{where}.color"),
        material=material, reflectance=reflectance, name=_name(item, where))
    z = region.height_at(corners[:, 0], corners[:, 1])
    if z.min() < -1e-9 and z.max() > 1e-9:
        raise err(f"{where}.gradient: the surface crosses the floor z = 0 (heights "
                  f"{z.min():.3f}..{z.max():.3f} m at the corners)")
    return region


def _person(item: Any, where: str) -> Person:
    """One validated person: a cylinder with a track."""
    err = SceneError
    check_keys(item, where, err, ["radius", "height", "color", "track"], ["name"])
    track = item["track"]
    if not isinstance(track, list) or not track:
        raise err(f"{where}.track: expected a non-empty list of [scan, x, y]")
    points = np.array([vector(p, 3, f"{where}.track[{i}]", err) for i, p in enumerate(track)])
    if (np.diff(points[:, 0]) <= 0.0).any():
        raise err(f"{where}.track: scan indices must increase")
    return Person(radius=number(item["radius"], f"{where}.radius", err, low=0.0, low_open=True),
                  height=number(item["height"], f"{where}.height", err, low=0.0, low_open=True),
                  color=_color(item["color"], f"{where}.color"), track=points,
                  name=_name(item, where))


def _object(item: Any, where: str) -> Box | Cylinder:
    """One validated box or cylinder."""
    err = SceneError
    if not isinstance(item, dict) or item.get("type") not in ("box", "cylinder"):
        raise err(f"{where}.type: expected 'box' or 'cylinder'")
    name = _name(item, where)
    material, reflectance = _material(item, where)
    extra = ["name", "surface", "reflectance"]
    if item["type"] == "box":
        check_keys(item, where, err, ["type", "center", "size", "color"], ["yaw", *extra])
        size = vector(item["size"], 3, f"{where}.size", err)
        for axis, s in enumerate(size):
            if s <= 0.0:
                raise err(f"{where}.size[{axis}]: expected > 0, got {s}")
        return Box(center=tuple(vector(item["center"], 3, f"{where}.center", err)),
                   size=tuple(size), color=_color(item["color"], f"{where}.color"),
                   yaw=number(item.get("yaw", 0.0), f"{where}.yaw", err), name=name,
                   material=material, reflectance=reflectance)
    check_keys(item, where, err, ["type", "center", "radius", "height", "color"], extra)
    return Cylinder(center=tuple(vector(item["center"], 3, f"{where}.center", err)),
                    radius=number(item["radius"], f"{where}.radius", err, low=0.0,
                                  low_open=True),
                    height=number(item["height"], f"{where}.height", err, low=0.0,
                                  low_open=True),
                    color=_color(item["color"], f"{where}.color"), name=name,
                    material=material, reflectance=reflectance)


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read and validate a `scanmap.scene/1` file; errors name the file and field."""
    return Scene.from_dict(read_json(path, SceneError), source=str(path))


def builtin_scene_names() -> list[str]:
    """Names of the scenes shipped with scanmap (`corridor`, `hazards`, `office`, `people`)."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.json"))


def builtin_scene(name: str) -> Scene:
    """A scene shipped with scanmap, by name."""
    path = SCENES_DIR / f"{name}.json"
    if not path.is_file():
        raise SceneError(f"unknown built-in scene {name!r} "
                         f"(available: {', '.join(builtin_scene_names())})")
    return load_scene(path)


def resolve_scene(name_or_path: str | os.PathLike[str]) -> Scene:
    """A built-in scene by name, or a scene file by path (what the CLI's SCENE means)."""
    text = str(name_or_path)
    if text in builtin_scene_names():
        return builtin_scene(text)
    if not Path(text).exists():
        raise SceneError(f"{text}: neither a scene file nor a built-in scene "
                         f"({', '.join(builtin_scene_names())})")
    return load_scene(text)
