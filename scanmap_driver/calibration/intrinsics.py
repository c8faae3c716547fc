"""Camera intrinsics from images of a calibration board (Zhang's method, via OpenCV).

`calibrate_camera(images, board)` finds the board in every image, rejects the images
where it is missing or unusable (and says why), fits the pinhole model with OpenCV's
5-coefficient distortion (k1, k2, p1, p2, k3) and returns the `CameraIntrinsics` with the
reprojection errors and the parameters' standard deviations. `write_opencv_yaml` saves
it as OpenCV's calibration sample does (camera_matrix, distortion_coefficients,
avg_reprojection_error, per_view_reprojection_errors), for OpenCV users and tools.

The data must pin the focal length down: views that all show the board in the same
orientation, or all facing the camera squarely, cannot (planar calibration needs the
board tilted, and tilted differently between views), and a fit whose focal length is
uncertain by more than `max_focal_sigma` is refused rather than returned.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from ..errors import CalibrationError
from ..files import atomic_path
from ..scanner_model import CameraIntrinsics
from .boards import BoardNotFound, BoardView, CharucoBoard, Chessboard

ImageSource = str | os.PathLike[str] | np.ndarray

# Views closer than this in board orientation add no constraint on the focal length.
MIN_ORIENTATION_SPREAD = math.radians(1.0)
# A board within this of facing the camera squarely says nothing about the focal length.
MIN_TILT = math.radians(5.0)
# Two views whose corners agree within this (px) are the same view counted twice.
DUPLICATE_TOLERANCE = 0.01
# A fit worse than this (px rms) has misdetected corners or a lens the model cannot hold.
DEFAULT_MAX_RMS = 1.0


@dataclass(frozen=True)
class RejectedImage:
    """An image left out of the calibration, and why."""

    name: str
    reason: str


@dataclass(frozen=True)
class IntrinsicsCalibration:
    """The calibrated camera and how well the data support it.

    rms: reprojection error over all corners (px); per_image_rms matches `images`.
    sigma: standard deviations of (fx, fy, cx, cy) in px, from the fit's covariance.
    """

    camera: CameraIntrinsics
    rms: float
    per_image_rms: tuple[float, ...]
    images: tuple[str, ...]
    rejected: tuple[RejectedImage, ...]
    sigma: tuple[float, float, float, float]

    @property
    def image_count(self) -> int:
        """Number of images the calibration used."""
        return len(self.images)


def calibrate_camera(images: Sequence[ImageSource], board: Chessboard | CharucoBoard, *,
                     min_images: int = 3, max_focal_sigma: float = 0.1,
                     max_rms: float = DEFAULT_MAX_RMS,
                     frame_rate: float = 25.0) -> IntrinsicsCalibration:
    """Calibrate from image files (or BGR/grey arrays) showing `board`.

    min_images: least number of images with a usable board.
    max_focal_sigma: largest accepted standard deviation of fx and fy, relative.
    max_rms: largest accepted reprojection error (px rms).
    frame_rate: carried into the returned intrinsics (images do not tell it).
    Raises CalibrationError for no images, an unreadable image, images of different
    sizes, too few usable views, or data that do not determine the intrinsics.
    """
    if len(images) == 0:
        raise CalibrationError("camera calibration: no images given")
    names: list[str] = []
    views: list[BoardView] = []
    rejected: list[RejectedImage] = []
    size = None
    for name, image in _read_images(images):
        image_size = (image.shape[1], image.shape[0])
        if size is None:
            size, first = image_size, name
        elif image_size != size:
            raise CalibrationError(
                f"camera calibration: images differ in size: {first} is {size[0]}x{size[1]}, "
                f"{name} is {image_size[0]}x{image_size[1]}")
        try:
            view = board.detect(image)
        except BoardNotFound as exc:
            rejected.append(RejectedImage(name, str(exc)))
            continue
        twin = _duplicate_of(view, views)
        if twin is not None:
            rejected.append(RejectedImage(name, f"the same view as {names[twin]}"))
            continue
        names.append(name)
        views.append(view)
    if len(views) < min_images:
        reasons = "".join(f"\n  {r.name}: {r.reason}" for r in rejected)
        raise CalibrationError(
            f"camera calibration: the board was found in {len(views)} of {len(images)} "
            f"images, {min_images} needed{reasons}")
    result = calibrate_views(views, size, names, max_focal_sigma=max_focal_sigma,
                             max_rms=max_rms, frame_rate=frame_rate)
    return replace(result, rejected=tuple(rejected))


def _read_images(images: Sequence[ImageSource]) -> Iterator[tuple[str, np.ndarray]]:
    """(name, image) pairs, read one at a time; arrays are named image[i]."""
    for i, source in enumerate(images):
        if isinstance(source, np.ndarray):
            if source.dtype != np.uint8 or source.ndim not in (2, 3) or source.size == 0:
                raise CalibrationError(
                    f"image[{i}]: expected an 8-bit grey or BGR image, got "
                    f"{source.dtype} array of shape {source.shape}")
            yield f"image[{i}]", source
            continue
        path = Path(source)
        if not path.is_file():
            raise CalibrationError(f"{path}: image file not found")
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise CalibrationError(f"{path}: not a readable image")
        yield str(path), image


def _duplicate_of(view: BoardView, views: list[BoardView]) -> int | None:
    for i, other in enumerate(views):
        if (other.image_points.shape == view.image_points.shape
                and np.array_equal(other.object_points, view.object_points)
                and np.abs(other.image_points - view.image_points).max() < DUPLICATE_TOLERANCE):
            return i
    return None


def calibrate_views(views: Sequence[BoardView], size: tuple[int, int], names: Sequence[str],
                    *, max_focal_sigma: float = 0.1, max_rms: float = DEFAULT_MAX_RMS,
                    frame_rate: float = 25.0) -> IntrinsicsCalibration:
    """Zhang's calibration on board views already found in images of `size` (w, h),
    checked for degenerate data; `names` name the views in the result."""
    try:
        rms, matrix, dist, rvecs, _, sigma, _, per_view = cv2.calibrateCameraExtended(
            [np.asarray(v.object_points, np.float32).reshape(-1, 3) for v in views],
            [np.asarray(v.image_points, np.float32).reshape(-1, 2) for v in views], size,
            None, None)
    except cv2.error as exc:
        raise CalibrationError(f"camera calibration: degenerate data ({exc.err})") from None
    fx, fy, cx, cy = matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2]
    sigma = sigma.ravel()[:4]
    if not (np.all(np.isfinite([rms, fx, fy, cx, cy, *dist.ravel(), *sigma]))
            and fx > 0 and fy > 0 and 0 <= cx < size[0] and 0 <= cy < size[1]):
        raise CalibrationError(
            f"camera calibration: degenerate data, the fit gave fx {fx:.6g}, fy {fy:.6g}, "
            f"cx {cx:.6g}, cy {cy:.6g} for a {size[0]}x{size[1]} image")
    if rms > max_rms:
        worst = int(np.argmax(per_view))
        raise CalibrationError(
            f"camera calibration: reprojection error {rms:.2f} px rms > {max_rms:g} px "
            f"(worst {names[worst]}: {per_view.ravel()[worst]:.2f} px): corners misdetected, "
            "or a lens beyond the 5-coefficient model")
    _check_orientations(rvecs)
    focal_sigma = max(sigma[0] / fx, sigma[1] / fy)
    if focal_sigma > max_focal_sigma:
        raise CalibrationError(
            f"camera calibration: the {len(views)} views leave the focal length uncertain "
            f"by {100 * focal_sigma:.0f}% (fx {fx:.1f} +- {sigma[0]:.1f} px); add views "
            "with the board tilted in other directions")
    camera = CameraIntrinsics(
        width=size[0], height=size[1], fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy),
        distortion=tuple(float(d) for d in dist.ravel()[:5]), frame_rate=frame_rate)
    return IntrinsicsCalibration(
        camera=camera, rms=float(rms), per_image_rms=tuple(map(float, per_view.ravel())),
        images=tuple(names), rejected=(), sigma=tuple(float(s) for s in sigma))


def write_opencv_yaml(result: IntrinsicsCalibration, path: str | os.PathLike[str]) -> None:
    """Write `result` as an OpenCV calibration file (cv2.FileStorage YAML, atomically):
    image_width, image_height, nr_of_frames, camera_matrix, distortion_coefficients
    (k1 k2 p1 p2 k3), avg_reprojection_error (px rms over all corners) and
    per_view_reprojection_errors (px rms per image, in `result.images` order)."""
    cam = result.camera
    with atomic_path(path) as tmp:
        store = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
        try:
            store.write("image_width", cam.width)
            store.write("image_height", cam.height)
            store.write("nr_of_frames", result.image_count)
            store.write("camera_matrix", np.array(
                [[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]]))
            store.write("distortion_coefficients", np.array(cam.distortion).reshape(-1, 1))
            store.write("avg_reprojection_error", result.rms)
            store.write("per_view_reprojection_errors",
                        np.array(result.per_image_rms).reshape(-1, 1))
        finally:
            store.release()


def _check_orientations(rvecs: Sequence[np.ndarray]) -> None:
    """Refuse views that cannot determine a focal length (Zhang's degenerate cases)."""
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    tilts = np.arccos(np.clip(np.abs(normals[:, 2]), 0.0, 1.0))
    spread = np.arccos(np.clip(np.abs(normals @ normals.T), 0.0, 1.0)).max()
    if tilts.max() < MIN_TILT:
        raise CalibrationError(
            "camera calibration: degenerate data, the board faces the camera squarely in "
            f"every view (largest tilt {math.degrees(tilts.max()):.1f} deg); tilt it by "
            "20-45 deg")
    if spread < MIN_ORIENTATION_SPREAD:
        raise CalibrationError(
            "camera calibration: degenerate data, every view shows the board in the same "
            f"orientation (within {math.degrees(spread):.2f} deg); tilt it differently "
            "between views")
