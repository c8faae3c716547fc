"""Calibration of the scanner: camera intrinsics from board images, the laser plane.

`calibrate_camera(images, board)` fits the camera's pinhole model and distortion from
images of a `Chessboard` or `CharucoBoard` (`calibrate_views` from corners already
found) and `write_opencv_yaml` saves it as OpenCV does; `laser_plane_from_points` builds the laser
plane from the laser aperture and two points of the laser line on a wall, as the paper
does; `calibrate_wall` fits the laser plane, camera tilt, vertical separation, height and
encoder zero to a scan of a wall at a measured distance (the paper's calibration).
"""

from .boards import BoardNotFound, BoardView, CharucoBoard, Chessboard
from .intrinsics import (
    IntrinsicsCalibration,
    RejectedImage,
    calibrate_camera,
    calibrate_views,
    write_opencv_yaml,
)
from .laser_plane import laser_plane_from_points
from .wall import WallCalibration, calibrate_wall

__all__ = [
    "BoardNotFound",
    "BoardView",
    "CharucoBoard",
    "Chessboard",
    "IntrinsicsCalibration",
    "RejectedImage",
    "WallCalibration",
    "calibrate_camera",
    "calibrate_views",
    "calibrate_wall",
    "laser_plane_from_points",
    "write_opencv_yaml",
]
