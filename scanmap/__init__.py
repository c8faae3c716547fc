"""scanmap: registration, 2.5D height/occupancy mapping and obstacle queries for the scanner.

The public API a planner, a controller or a batch job needs is importable from here; the
subpackages (`grid`, `navigation`, `io`, `registration`, `mapping`, `datasets`,
`evaluation`, `pipelines`, `cli`) hold the rest, each naming its public parts in
`__all__`. The driver's data types are re-exported, so `from scanmap import Scan` works.
The architecture and the layers are in docs/architecture.md.
"""

from typing import TYPE_CHECKING

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

if TYPE_CHECKING:
    from scanmap.pipelines import map_to_folder, report_text

# Whole-job pipelines import the simulator's truth (and Open3D): loaded on first use only,
# so that `import scanmap` stays light for a controller.
_LAZY = {"map_to_folder": "scanmap.pipelines", "report_text": "scanmap.pipelines"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'scanmap' has no attribute {name!r}")


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
