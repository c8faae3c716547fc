"""Where scans come from: our recordings and folders of processed scans (`recordings`),
real robot logs (`carmen`) and ROS 1/2 bags (`rosbag`). See docs/architecture.md."""

from scanmap.datasets.carmen import BeamLayout, CarmenLog, carmen_scan_points, read_carmen
from scanmap.datasets.recordings import InputScan, ScanSource
from scanmap.datasets.rosbag import BagScans, is_bag

__all__ = [
    "BagScans",
    "BeamLayout",
    "CarmenLog",
    "InputScan",
    "ScanSource",
    "carmen_scan_points",
    "is_bag",
    "read_carmen",
]
