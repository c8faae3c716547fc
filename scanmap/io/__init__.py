"""Files and pictures at the boundaries: ROS map_server YAML + PGM and our `.npz` maps
(`map_files`), TUM trajectories (`trajectory`), ROS messages and bags (`ros_messages`),
occupancy images and the overhead view.
See docs/architecture.md."""

from scanmap.io.map_files import (
    RosMap,
    SavedMap,
    load_map,
    load_ros_map,
    read_pgm,
    save_map,
    save_ros_map,
)
from scanmap.io.map_image import MapImage, occupancy_image, write_png
from scanmap.io.overhead import overhead_view
from scanmap.io.ros_messages import BagFile, RosMessages
from scanmap.io.trajectory import Trajectory, read_tum, write_tum

__all__ = [
    "BagFile",
    "MapImage",
    "RosMap",
    "RosMessages",
    "SavedMap",
    "Trajectory",
    "load_map",
    "load_ros_map",
    "occupancy_image",
    "overhead_view",
    "read_pgm",
    "read_tum",
    "save_map",
    "save_ros_map",
    "write_png",
    "write_tum",
]
