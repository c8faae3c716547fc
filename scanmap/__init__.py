"""scanmap: registration, 2.5D height/occupancy mapping and obstacle queries for the scanner.

The public API a planner, a controller or a batch job needs is importable from here; the
subpackages (`grid`, `navigation`, `io`, `registration`, `mapping`, `datasets`,
`evaluation`, `pipelines`, `cli`) hold the rest, each naming its public parts in
`__all__`. The driver's data types are re-exported, so `from scanmap import Scan` works.
The architecture and the layers are in docs/architecture.md.

The names load on first use (PEP 562): `import scanmap` itself imports nothing heavy, so
the command line can set up the process (BLAS threads, `scanmap.cli`) before NumPy loads,
and a controller that needs one name pays only for its modules.
"""

import importlib
from typing import TYPE_CHECKING

# Where each public name lives (its module is imported on first use, see __getattr__).
_MODULES = {
    "scanmap.datasets": ("CarmenLog", "ScanSource", "read_carmen"),
    "scanmap.grid": ("GridConfig", "HeightGrid"),
    "scanmap.io": ("Trajectory", "load_map", "load_ros_map", "occupancy_image",
                   "overhead_view", "read_tum", "save_map", "save_ros_map", "write_png",
                   "write_tum"),
    "scanmap.mapping": ("Mapper", "MapperConfig", "MapUpdate"),
    "scanmap.navigation": ("FREE", "INSCRIBED", "LETHAL", "OBSTACLE", "UNKNOWN", "Clearance",
                           "FloorConfig", "Nearest", "ObstacleMap", "PolarScan", "QueryStatus",
                           "RobotShape", "Segmentation", "Travel", "distance_transform",
                           "inflate", "occupancy_grid", "segment"),
    "scanmap.registration": ("OdometryNoiseConfig", "RegistrationConfig"),
    "scanmap_driver": ("CalibrationError", "DeviceError", "MapError", "RecordingError",
                       "RegistrationError", "Scan", "ScanError", "ScanmapError",
                       "ScannerModel", "SceneError", "__version__", "reference_scanner"),
    "scanmap.pipelines": ("map_to_folder", "report_text"),
}
_HOME = {name: module for module, names in _MODULES.items() for name in names}

if TYPE_CHECKING:
    from scanmap.datasets import CarmenLog, ScanSource, read_carmen
    from scanmap.grid import GridConfig, HeightGrid
    from scanmap.io import (
        Trajectory,
        load_map,
        load_ros_map,
        occupancy_image,
        overhead_view,
        read_tum,
        save_map,
        save_ros_map,
        write_png,
        write_tum,
    )
    from scanmap.mapping import Mapper, MapperConfig, MapUpdate
    from scanmap.navigation import (
        FREE,
        INSCRIBED,
        LETHAL,
        OBSTACLE,
        UNKNOWN,
        Clearance,
        FloorConfig,
        Nearest,
        ObstacleMap,
        PolarScan,
        QueryStatus,
        RobotShape,
        Segmentation,
        Travel,
        distance_transform,
        inflate,
        occupancy_grid,
        segment,
    )
    from scanmap.pipelines import map_to_folder, report_text
    from scanmap.registration import OdometryNoiseConfig, RegistrationConfig
    from scanmap_driver import (
        CalibrationError,
        DeviceError,
        MapError,
        RecordingError,
        RegistrationError,
        Scan,
        ScanError,
        ScanmapError,
        ScannerModel,
        SceneError,
        __version__,
        reference_scanner,
    )


def __getattr__(name: str):
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f"module 'scanmap' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [  # noqa: RUF022 (grouped by the layer they come from, sorted within)
    # the scanner's data types and errors (scanmap_driver)
    "CalibrationError", "DeviceError", "MapError", "RecordingError", "RegistrationError",
    "Scan", "ScanError", "ScanmapError", "ScannerModel", "SceneError", "__version__",
    "reference_scanner",
    # the mapper and its settings
    "GridConfig", "HeightGrid", "MapUpdate", "Mapper", "MapperConfig", "OdometryNoiseConfig",
    "RegistrationConfig",
    # floor, obstacles, queries and costmaps
    "FREE", "INSCRIBED", "LETHAL", "OBSTACLE", "UNKNOWN", "Clearance", "FloorConfig",
    "Nearest", "ObstacleMap", "PolarScan", "QueryStatus", "RobotShape", "Segmentation",
    "Travel", "distance_transform", "inflate", "occupancy_grid", "segment",
    # files and pictures
    "Trajectory", "load_map", "load_ros_map", "occupancy_image", "overhead_view", "read_tum",
    "save_map", "save_ros_map", "write_png", "write_tum",
    # scan sources and whole jobs
    "CarmenLog", "ScanSource", "map_to_folder", "read_carmen", "report_text",
]
