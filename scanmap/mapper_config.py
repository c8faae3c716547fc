"""Settings of the Mapper: every part's configuration in one value, kept in map files.

The parts keep their own defaults and reasoning (`GridConfig`, `RegistrationConfig`,
`OdometryNoise`, `RobotShape`, `FloorParams`); this adds what only the mapper decides.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field, fields

from scanmap_driver.errors import MapError, ScanmapError

from .floor import FloorParams, RobotShape
from .grid import GridConfig
from .registration import OdometryNoise, RegistrationConfig

_PARTS = {"grid": GridConfig, "registration": RegistrationConfig, "noise": OdometryNoise,
          "robot": RobotShape, "floor": FloorParams}


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
    """

    grid: GridConfig = field(default_factory=GridConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    robot: RobotShape = field(default_factory=RobotShape)
    floor: FloorParams = field(default_factory=FloorParams)
    max_age: float = 3.0
    obstacle_window: float | None = 12.0
    update_obstacles: bool = True
    keep_points: float | None = None
    resume_scans: int = 3

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

    def to_dict(self) -> dict:
        """Plain JSON-able values."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict, source: str = "mapper config") -> MapperConfig:
        """Rebuild from `to_dict`; MapError names `source` and the part at fault.

        A map saved by another version may name tuning settings this one lacks: they
        are dropped with a warning, except the grid's, which shape the saved arrays.
        """
        if not isinstance(data, dict):
            raise MapError(f"{source}: expected an object, got {type(data).__name__}")
        values = _known(cls, data, source, strict=True)
        for name, part in _PARTS.items():
            if name in values:
                try:
                    values[name] = part(**_known(part, values[name], f"{source}: {name}",
                                                 strict=part is GridConfig))
                except (TypeError, ValueError, ScanmapError) as exc:
                    raise MapError(f"{source}: {name}: {exc}") from None
        try:
            return cls(**values)
        except TypeError as exc:
            raise MapError(f"{source}: {exc}") from None


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
