"""Calibration of the scanner: camera intrinsics from board images, the laser plane.

`calibrate_camera(images, board)` fits the camera's pinhole model and distortion from
images of a `Chessboard` or `CharucoBoard` (`calibrate_views` from corners already
found); `laser_plane_from_points` builds the laser
plane from the laser aperture and two points of the laser line on a wall, as the paper
does.
"""

from .boards import BoardNotFound, BoardView, CharucoBoard, Chessboard
from .intrinsics import IntrinsicsCalibration, RejectedImage, calibrate_camera, calibrate_views
from .laser_plane import laser_plane_from_points

__all__ = [
    "BoardNotFound",
    "BoardView",
    "CharucoBoard",
    "Chessboard",
    "IntrinsicsCalibration",
    "RejectedImage",
    "calibrate_camera",
    "calibrate_views",
    "laser_plane_from_points",
]
