"""scanmap: registration, 2.5D height/occupancy mapping and obstacle queries for the scanner.

The driver's data types are re-exported, so `from scanmap import Scan` works.
"""

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

from .mapper import Mapper

__all__ = [
    "CalibrationError",
    "DeviceError",
    "MapError",
    "Mapper",
    "RecordingError",
    "RegistrationError",
    "Scan",
    "ScanError",
    "ScanmapError",
    "ScannerModel",
    "SceneError",
    "__version__",
    "reference_scanner",
]
