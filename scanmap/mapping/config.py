"""Settings of the Mapper: every part's configuration in one value, kept in map files.

The parts keep their own defaults and reasoning (`GridConfig`, `RegistrationConfig`,
`OdometryNoiseConfig`, `RobotShape`, `FloorConfig`, `LoopClosureConfig`); this adds what
only the mapper decides.

A configuration file is TOML: the mapper's own keys at the top, each part in its table
(`[grid]`, `[registration]`, `[noise]`, `[robot]`, `[floor]`, `[loop_closure]`). Keys
left out keep their defaults; an optional setting is switched off with the string
"none". `scanmap config --defaults` prints every key with its default, `scanmap map
--config FILE` reads one.
"""

from __future__ import annotations

import math
import os
import tomllib
import warnings
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from scanmap.graph import LoopClosureConfig
from scanmap.grid.height_grid import GridConfig
from scanmap.navigation.floor import FloorConfig, RobotShape
from scanmap.registration import OdometryNoiseConfig, RegistrationConfig
from scanmap_driver.errors import MapError, ScanmapError

_PARTS = {"grid": GridConfig, "registration": RegistrationConfig, "noise": OdometryNoiseConfig,
          "robot": RobotShape, "floor": FloorConfig, "loop_closure": LoopClosureConfig}


@dataclass(frozen=True)
class MapperConfig:
    """How the Mapper registers, fuses and publishes.

    max_age: seconds after the newest scan beyond which obstacle queries are STALE. A
      scan takes about 2 s and its newest point is from its last frame, so while the
      scanner runs continuously the data age between 0.1 and 2.1 s; 3 s tolerates one
      late scan, not a lost one. Stop-and-scan robots need their scan interval and more.
    obstacle_window: side (m) of the square around the robot whose obstacle field is
      rebuilt after each scan (4 m range and margin); None rebuilds the whole map.
    update_obstacles: rebuild the obstacle field after each scan (what a controller
      polls). Offline mapping may skip it and segment the finished map once.
    keep_points: voxel size (m) at which the fused points of every scan are kept for the
      overhead view (`overhead`); None keeps none (a long live run).
    resume_scans: how many of the newest fused scans are saved with the map, so that a
      loaded map can register the next scan against what the robot saw last.
    rebuild_submap_scans: with loop closure, the grid is rebuilt after an optimisation by
      merging submaps of this many consecutive scans, each moved whole by its correction
      (`SubmapRebuilder`: 0.23 s for 1000 of the 3-D scanner's scans instead of 5.1 s);
      None fuses every scan's kept rays again (`GridRebuilder`: exact, slow). A rolling
      window (`grid.window`) always rebuilds from rays.
    laser_rays: clear space along the laser's rays (emitter to point) as well as the
      camera's (`HeightGrid.insert`'s `lasers`): a person who walked on clears where only
      the emitter's lower rays cross the heights it stood in.
    swept: miss the levels the laser's plane swept in the camera's view without lighting
      them (`HeightGrid.insert`'s `swept`, `scanmap.grid.swept`): a person who left clears
      where no ray crosses the space they stood in. Not kept for loop-closure rebuilds.
    """

    grid: GridConfig = field(default_factory=GridConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    noise: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)
    robot: RobotShape = field(default_factory=RobotShape)
    floor: FloorConfig = field(default_factory=FloorConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    max_age: float = 3.0
    obstacle_window: float | None = 12.0
    update_obstacles: bool = True
    keep_points: float | None = None
    resume_scans: int = 3
    rebuild_submap_scans: int | None = 25
    laser_rays: bool = True
    swept: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_age) and self.max_age > 0):
            raise MapError(f"MapperConfig.max_age: expected a finite number > 0, "
                           f"got {self.max_age!r}")
        for name in ("obstacle_window", "keep_points"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise MapError(f"MapperConfig.{name}: expected None or a number > 0, "
                               f"got {value!r}")
        if not (isinstance(self.resume_scans, int) and self.resume_scans >= 1):
            raise MapError(f"MapperConfig.resume_scans: expected an integer >= 1, "
                           f"got {self.resume_scans!r}")
        submap = self.rebuild_submap_scans
        if submap is not None and not (isinstance(submap, int) and submap >= 1):
            raise MapError(f"MapperConfig.rebuild_submap_scans: expected None or an "
                           f"integer >= 1, got {submap!r}")
        for name in ("laser_rays", "swept"):
            if not isinstance(getattr(self, name), bool):
                raise MapError(f"MapperConfig.{name}: expected true or false, "
                               f"got {getattr(self, name)!r}")

    def to_dict(self) -> dict:
        """Plain JSON-able values."""
        return asdict(self)

    def to_toml(self) -> str:
        """The configuration as a TOML file that `load` reads back to an equal value."""
        values = self.to_dict()
        top = {k: v for k, v in values.items() if k not in _PARTS}
        lines = ["# scanmap mapper configuration (scanmap.mapping.config.MapperConfig)"]
        lines += [f"{key} = {_toml_value(value)}" for key, value in top.items()]
        for name, part in _PARTS.items():
            lines += ["", f"[{name}]  # {part.__name__}"]
            lines += [f"{key} = {_toml_value(value)}" for key, value in values[name].items()]
        return "\n".join(lines) + "\n"

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> MapperConfig:
        """Read a TOML configuration file (see the module docstring); MapError names the
        file and the key at fault."""
        try:
            data = tomllib.loads(Path(path).read_text())
        except OSError as exc:
            raise MapError(f"{path}: cannot read the configuration: {exc}") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise MapError(f"{path}: not a valid TOML file: {exc}") from None
        data = _none_from_toml(data)
        defaults = cls().to_dict()
        for name in _PARTS:
            if name in data and isinstance(data[name], dict):
                data[name] = {**defaults[name], **data[name]}
        return cls.from_dict(data, source=str(path), strict=True)

    @classmethod
    def from_dict(cls, data: dict, source: str = "mapper config",
                  strict: bool = False) -> MapperConfig:
        """Rebuild from `to_dict`; MapError names `source` and the part at fault.

        A map saved by another version may name tuning settings this one lacks: they
        are dropped with a warning, except the grid's, which shape the saved arrays.
        `strict` (a user's configuration file) refuses every unknown key.
        """
        if not isinstance(data, dict):
            raise MapError(f"{source}: expected an object, got {type(data).__name__}")
        values = _known(cls, data, source, strict=True)
        for name, part in _PARTS.items():
            if name in values:
                known = _known(part, values[name], f"{source}: {name}",
                               strict=strict or part is GridConfig)
                try:
                    values[name] = part(**known)
                except (TypeError, ValueError, ScanmapError) as exc:
                    raise MapError(f"{source}: {name}: {exc}") from None
        try:
            return cls(**values)
        except TypeError as exc:
            raise MapError(f"{source}: {exc}") from None


def _toml_value(value: object) -> str:
    """One TOML value: numbers in full precision, None as the string "none"."""
    if value is None:
        return '"none"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return str(value)


def _none_from_toml(data: object) -> object:
    """The string "none" (any case) as None, in nested tables too."""
    if isinstance(data, dict):
        return {key: _none_from_toml(value) for key, value in data.items()}
    if isinstance(data, str) and data.lower() == "none":
        return None
    return data


def _known(kind: type, data: dict, source: str, strict: bool) -> dict:
    """`data` restricted to the fields of dataclass `kind`; unknown keys are an error
    (strict) or dropped with a warning."""
    if not isinstance(data, dict):
        raise MapError(f"{source}: expected an object, got {type(data).__name__}")
    known = {f.name for f in fields(kind)}
    unknown = sorted(set(data) - known)
    if unknown and strict:
        raise MapError(f"{source}: unknown keys {unknown}")
    if unknown:
        warnings.warn(f"{source}: ignoring settings this version does not have: {unknown}",
                      stacklevel=3)
    return {key: value for key, value in data.items() if key in known}
