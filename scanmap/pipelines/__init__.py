"""Whole jobs: a recording or folder of scans to a map folder with its report (`offline`),
a CARMEN log fused from its corrected poses (`carmen_map`), ROS bags out and in
(`ros_export`), a fleet of recordings on a Dask cluster (`fleet`, the `cluster` extra:
import it yourself) and the kernel warm-up (`warm_cache`). See docs/architecture.md."""

from scanmap.pipelines.carmen_map import carmen_segmentation, fuse_carmen
from scanmap.pipelines.offline import map_to_folder, report_text
from scanmap.pipelines.ros_export import BagWriter, export_map_folder, map_bag

__all__ = [
    "BagWriter",
    "carmen_segmentation",
    "export_map_folder",
    "fuse_carmen",
    "map_bag",
    "map_to_folder",
    "report_text",
]
