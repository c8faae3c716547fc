"""Whole jobs: a recording or folder of scans to a map folder with its report (`offline`),
a CARMEN log fused from its corrected poses (`carmen_map`). See docs/architecture.md."""

from scanmap.pipelines.carmen_map import carmen_segmentation, fuse_carmen
from scanmap.pipelines.offline import map_to_folder, report_text
from scanmap.pipelines.ros_export import BagWriter, export_map_folder, map_bag

__all__ = ["carmen_segmentation", "fuse_carmen", "map_to_folder", "report_text"]
__all__ += ["BagWriter", "export_map_folder", "map_bag"]
