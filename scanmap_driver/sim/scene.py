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
* on an object: `name` (free text).

Built-in scenes live as JSON files beside this module (`scenes/<name>.json`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError
from ..files import read_json, write_json
from ..validate import check_keys, number, vector

FORMAT = "scanmap.scene/1"
SCENES_DIR = Path(__file__).resolve().parent / "scenes"
DEFAULT_TEXTURE = 0.25


@dataclass(frozen=True)
class Box:
    """A box: middle at `center`, extent `size` along its own axes, turned by `yaw` about z."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    color: tuple[int, int, int]
    yaw: float = 0.0
    name: str = ""


@dataclass(frozen=True)
class Cylinder:
    """A vertical cylinder with its middle at `center`."""

    center: tuple[float, float, float]
    radius: float
    height: float
    color: tuple[int, int, int]
    name: str = ""


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

    def with_ambient(self, ambient: float) -> Scene:
        """The same scene under another light level (0 dark .. 1 bright)."""
        return Scene(self.name, self.floor_color, float(ambient), self.objects,
                     self.scan_poses, self.texture, self.motion, self.odometry,
                     self.description)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min_xy, max_xy) of the objects and scan poses in `map` (m)."""
        corners = [self.scan_poses[:, :2]]
        for obj in self.objects:
            corners.append(footprint_corners(obj))
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
            objects.append(item)
        data = {"format": FORMAT, "name": self.name, "description": self.description,
                "floor": {"color": list(self.floor_color)}, "ambient": self.ambient,
                "texture": self.texture,
                "motion": {"speed": self.motion.speed, "yaw_rate": self.motion.yaw_rate},
                "odometry": {k: getattr(self.odometry, k)
                             for k in SimOdometryNoise.__dataclass_fields__},
                "objects": objects, "scan_poses": self.scan_poses.tolist()}
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
                         ["name", "description", "texture", "motion", "odometry"])
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


def _object(item: Any, where: str) -> Box | Cylinder:
    """One validated box or cylinder."""
    err = SceneError
    if not isinstance(item, dict) or item.get("type") not in ("box", "cylinder"):
        raise err(f"{where}.type: expected 'box' or 'cylinder'")
    name = item.get("name", "")
    if not isinstance(name, str):
        raise err(f"{where}.name: expected a string")
    if item["type"] == "box":
        check_keys(item, where, err, ["type", "center", "size", "color"], ["yaw", "name"])
        size = vector(item["size"], 3, f"{where}.size", err)
        for axis, s in enumerate(size):
            if s <= 0.0:
                raise err(f"{where}.size[{axis}]: expected > 0, got {s}")
        return Box(center=tuple(vector(item["center"], 3, f"{where}.center", err)),
                   size=tuple(size), color=_color(item["color"], f"{where}.color"),
                   yaw=number(item.get("yaw", 0.0), f"{where}.yaw", err), name=name)
    check_keys(item, where, err, ["type", "center", "radius", "height", "color"], ["name"])
    return Cylinder(center=tuple(vector(item["center"], 3, f"{where}.center", err)),
                    radius=number(item["radius"], f"{where}.radius", err, low=0.0,
                                  low_open=True),
                    height=number(item["height"], f"{where}.height", err, low=0.0,
                                  low_open=True),
                    color=_color(item["color"], f"{where}.color"), name=name)


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read and validate a `scanmap.scene/1` file; errors name the file and field."""
    return Scene.from_dict(read_json(path, SceneError), source=str(path))


def builtin_scene_names() -> list[str]:
    """Names of the scenes shipped with scanmap (`corridor`, `office`)."""
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
