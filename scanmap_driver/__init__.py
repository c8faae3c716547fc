"""scanmap_driver: the rotating laser-line scanner, from camera frames to 360 deg scans.

It owns the scanner model and calibration, frame processing (laser, encoder,
triangulation), the devices, scan assembly, recordings and the simulator. It imports
nothing from `scanmap`.
"""

from .errors import (
    CalibrationError,
    DeviceError,
    MapError,
    RecordingError,
    RegistrationError,
    ScanError,
    ScanmapError,
    SceneError,
)
from .files import write_json
from .recording import INDEX_NAME, Recording
from .scan import Scan
from .scanner_model import ScannerModel, reference_scanner
from .triangulation import Reason, Triangulation, triangulate

__version__ = "0.1.0"

__all__ = [
    "INDEX_NAME",
    "CalibrationError",
    "DeviceError",
    "MapError",
    "Reason",
    "Recording",
    "RecordingError",
    "RegistrationError",
    "Scan",
    "ScanError",
    "ScanmapError",
    "ScannerModel",
    "SceneError",
    "Triangulation",
    "__version__",
    "reference_scanner",
    "triangulate",
    "write_json",
]
