"""Calibration boards (chessboard, ChArUco) and their detection in one image.

A board knows its geometry (squares, sizes in metres) and turns a grey image into a
`BoardView`: the board-frame 3D points of the corners it found and their subpixel image
positions, ready for `cv2.calibrateCamera`. A board that cannot be found raises
`BoardNotFound` with the reason, which the calibration reports per image.

Both boards are sized in squares (COLSxROWS, as printed), so a chessboard of 12x7
squares has 11x6 inner corners.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import CalibrationError

# Fewer corners than this per view give a pose too weak to help the calibration.
MIN_CORNERS = 6
# A view whose corners span less than this fraction of their extent across is a line.
MIN_SPREAD_RATIO = 0.05
# cornerSubPix half window: half the corner spacing, at most 11 px (OpenCV samples' value;
# on the Ciclop captures 11 gives 0.24 px rms against 0.30 px for 5).
MAX_SUBPIX_HALF_WINDOW = 11
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)


class BoardNotFound(CalibrationError):
    """The board is not (usably) visible in an image; the message says why."""


@dataclass(frozen=True)
class BoardView:
    """Corners of one board seen in one image: (N, 3) board points (m), (N, 2) pixels."""

    object_points: np.ndarray
    image_points: np.ndarray


def _check_size(squares: tuple[int, int], square_size: float, minimum: int) -> None:
    if (len(squares) != 2 or not all(isinstance(n, int) for n in squares)
            or min(squares) < minimum):
        raise CalibrationError(
            f"board squares: expected two integers >= {minimum} (COLSxROWS), got {squares}")
    if not (math.isfinite(square_size) and square_size > 0):
        raise CalibrationError(f"board square_size: expected > 0 m, got {square_size}")


def _view(object_points: np.ndarray, image_points: np.ndarray) -> BoardView:
    """A view, or BoardNotFound when its corners are too few or on one line."""
    obj = np.asarray(object_points, dtype=np.float32).reshape(-1, 3)
    img = np.asarray(image_points, dtype=np.float32).reshape(-1, 2)
    if len(obj) < MIN_CORNERS:
        raise BoardNotFound(f"only {len(obj)} corners found (need {MIN_CORNERS})")
    spread = np.linalg.svd(obj[:, :2] - obj[:, :2].mean(axis=0), compute_uv=False)
    if spread[1] < MIN_SPREAD_RATIO * spread[0]:
        raise BoardNotFound(f"the {len(obj)} corners found lie on one line")
    return BoardView(obj, img)


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


@dataclass(frozen=True)
class Chessboard:
    """A plain chessboard of `squares` = (columns, rows) squares of `square_size` metres.

    Detection: OpenCV's classic detector refined with cornerSubPix (fast, and what the
    Ciclop/Horus tool chain uses), falling back to the sector-based detector
    (findChessboardCornersSB) for images the classic one misses.
    """

    squares: tuple[int, int]
    square_size: float

    def __post_init__(self) -> None:
        _check_size(self.squares, self.square_size, minimum=4)

    @property
    def inner_corners(self) -> tuple[int, int]:
        """OpenCV's pattern size: inner corners per row and per column."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def corner_points(self) -> np.ndarray:
        """(N, 3) board coordinates (m) of the inner corners, row by row."""
        cols, rows = self.inner_corners
        grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * self.square_size
        return np.column_stack([grid, np.zeros(len(grid))]).astype(np.float32)

    def detect(self, image: np.ndarray) -> BoardView:
        """The board's corners in a BGR or grey image."""
        grey = _grey(image)
        pattern = self.inner_corners
        found, corners = cv2.findChessboardCorners(
            grey, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if found:
            corners = cv2.cornerSubPix(grey, corners, _subpix_window(corners, pattern),
                                       (-1, -1), SUBPIX_CRITERIA)
        else:
            found, corners = cv2.findChessboardCornersSB(
                grey, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY)
        if not found:
            raise BoardNotFound(
                f"no {self.squares[0]}x{self.squares[1]}-square chessboard "
                f"({pattern[0]}x{pattern[1]} inner corners) found")
        return _view(self.corner_points, corners)


def _subpix_window(corners: np.ndarray, pattern: tuple[int, int]) -> tuple[int, int]:
    """cornerSubPix half window from the smallest corner spacing."""
    grid = corners.reshape(pattern[1], pattern[0], 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(spacing / 2.0, 2, MAX_SUBPIX_HALF_WINDOW))
    return half, half


def _dictionary_id(name: str) -> int:
    value = getattr(cv2.aruco, name, None) if name.startswith("DICT_") else None
    if not isinstance(value, int):
        names = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise CalibrationError(f"board dictionary: unknown {name!r} (known: {', '.join(names)})")
    return value


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board: a chessboard whose white squares carry ArUco markers.

    squares: (columns, rows) of squares; marker_size < square_size, both in metres.
    legacy: the layout of OpenCV < 4.6 (and boards printed from it). The two layouts
        differ only for an even number of rows; with the wrong one the markers are
        found but no corner is, and the rejection reason says so.
    """

    squares: tuple[int, int]
    square_size: float
    marker_size: float
    dictionary: str = "DICT_6X6_250"
    legacy: bool = False
    _detector: cv2.aruco.CharucoDetector = field(init=False, repr=False, compare=False)
    _board: cv2.aruco.CharucoBoard = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_size(self.squares, self.square_size, minimum=3)
        if not (math.isfinite(self.marker_size) and 0 < self.marker_size < self.square_size):
            raise CalibrationError(
                f"board marker_size: expected 0 < marker_size < square_size "
                f"({self.square_size} m), got {self.marker_size}")
        dictionary = cv2.aruco.getPredefinedDictionary(_dictionary_id(self.dictionary))
        board = cv2.aruco.CharucoBoard(self.squares, self.square_size, self.marker_size,
                                       dictionary)
        board.setLegacyPattern(self.legacy)
        object.__setattr__(self, "_board", board)
        object.__setattr__(self, "_detector", cv2.aruco.CharucoDetector(board))

    def image(self, pixels_per_square: int, margin: int = 0) -> np.ndarray:
        """The printable board as a grey image (for printing and for synthetic views)."""
        cols, rows = self.squares
        size = (cols * pixels_per_square + 2 * margin, rows * pixels_per_square + 2 * margin)
        return self._board.generateImage(size, marginSize=margin)

    def detect(self, image: np.ndarray) -> BoardView:
        """The ChArUco corners (interpolated from the markers) in a BGR or grey image."""
        corners, ids, _, marker_ids = self._detector.detectBoard(_grey(image))
        markers = 0 if marker_ids is None else len(marker_ids)
        if corners is None or len(corners) == 0:
            hint = "" if markers == 0 else (
                f"{markers} {self.dictionary} markers found but no corner: check the board "
                "size (COLSxROWS), and the legacy layout if it has an even number of rows; ")
            raise BoardNotFound(f"{hint}no ChArUco corners found")
        object_points, image_points = self._board.matchImagePoints(corners, ids)
        return _view(object_points, image_points)
