"""Where scans come from: our recordings and folders of processed scans (`recordings`)
and real robot logs (`carmen`). See docs/architecture.md."""

from scanmap.datasets.carmen import BeamLayout, CarmenLog, carmen_scan_points, read_carmen
from scanmap.datasets.recordings import InputScan, ScanSource
from scanmap.datasets.rosbag import BagScans, is_bag

__all__ = ["BeamLayout", "CarmenLog", "InputScan", "ScanSource", "carmen_scan_points",
           "read_carmen"]
__all__ += ["BagScans", "is_bag"]
