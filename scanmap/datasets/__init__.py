"""Where scans come from: our recordings and folders of processed scans (`recordings`)
and real robot logs (`carmen`). See docs/architecture.md."""

from scanmap.datasets.carmen import CarmenLog, carmen_scan_points, read_carmen
from scanmap.datasets.recordings import InputScan, ScanSource

__all__ = ["CarmenLog", "InputScan", "ScanSource", "carmen_scan_points", "read_carmen"]
