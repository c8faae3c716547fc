"""Camera intrinsics from board images: real data against published references, synthetic
views of a known camera, and every refusal (no images, unreadable, sizes, degenerate)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scanmap_driver import CalibrationError
from scanmap_driver.calibration import (
    BoardNotFound,
    BoardView,
    CharucoBoard,
    Chessboard,
    calibrate_camera,
    calibrate_views,
    write_opencv_yaml,
)
from scanmap_driver.calibration.boards import _view
from tests.conftest import real_data

# OpenCV's tutorial_camera_charuco.yml, calibrated from the same 4 images (opencv/opencv
# samples/cpp/tutorial_code/objectDetection).
OPENCV_CHARUCO = {"fx": 452.51, "fy": 456.77, "cx": 317.70, "cy": 277.75, "rms": 0.182}
# 3DScanScience notebook "4.2. Camera calibration", the same 16 Ciclop captures,
# findChessboardCorners + cornerSubPix + calibrateCamera (11x6 inner corners).
CICLOP_NOTEBOOK = {"fx": 1429.66, "fy": 1430.39, "cx": 478.03, "cy": 642.60}

# The synthetic camera: 640x480, a mild barrel lens.
W, H = 640, 480
K = np.array([[600.0, 0.0, 322.0], [0.0, 605.0, 236.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.12, 0.05, 0.001, -0.0005, 0.0])
# Board poses (rvec, tvec): tilted 20-30 deg in different directions, spread over the
# image so that the views pin the lens down.
TILTED_POSES = [
    ([0.3, 0.2, 0.05], [-0.205, -0.155, 0.50]),
    ([-0.35, 0.1, 0.1], [-0.065, -0.155, 0.50]),
    ([0.1, -0.4, -0.1], [-0.205, -0.055, 0.50]),
    ([-0.2, -0.3, 0.2], [-0.065, -0.055, 0.50]),
    ([0.4, 0.35, -0.05], [-0.135, -0.105, 0.55]),
    ([-0.3, 0.3, 0.1], [-0.135, -0.105, 0.45]),
]


def charuco_images() -> list:
    folder = real_data("calib/opencv_charuco")
    return [folder / f"img_0{i}.jpg" for i in range(4)]


def opencv_board(**changes) -> CharucoBoard:
    return CharucoBoard(**{"squares": (5, 7), "square_size": 0.04, "marker_size": 0.02,
                           "dictionary": "DICT_6X6_250", **changes})


def distort(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's radial-tangential model on normalised coordinates, written out."""
    k1, k2, p1, p2, k3 = DIST
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


@pytest.fixture(scope="module")
def pixel_rays() -> np.ndarray:
    """Undistorted normalised ray [x, y, 1] of every pixel, by fixed-point iteration."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    xd, yd = (u.ravel() - K[0, 2]) / K[0, 0], (v.ravel() - K[1, 2]) / K[1, 1]
    x, y = xd.copy(), yd.copy()
    for _ in range(50):
        fx, fy = distort(x, y)
        x, y = x - (fx - xd), y - (fy - yd)
    fx, fy = distort(x, y)
    assert max(np.abs(fx - xd).max(), np.abs(fy - yd).max()) < 1e-12
    return np.column_stack([x, y, np.ones_like(x)])


def render(rays: np.ndarray, texture: np.ndarray, pixels_per_m: float, margin: int,
           rvec, tvec) -> np.ndarray:
    """The board texture seen by the synthetic camera (board origin at texture pixel
    `margin`, board x along texture columns)."""
    rotation = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    to_board = np.linalg.inv(np.column_stack([rotation[:, 0], rotation[:, 1], tvec]))
    q = rays @ to_board.T
    in_front = (q[:, 2] > 0).reshape(H, W)
    map_x = (q[:, 0] / q[:, 2] * pixels_per_m + margin - 0.5).reshape(H, W)
    map_y = (q[:, 1] / q[:, 2] * pixels_per_m + margin - 0.5).reshape(H, W)
    map_x[~in_front] = -1e6
    blurred = cv2.GaussianBlur(texture, (0, 0), 1.5)
    return cv2.remap(blurred, map_x.astype(np.float32), map_y.astype(np.float32),
                     cv2.INTER_LINEAR, borderValue=128)


def chessboard_texture(board: Chessboard, px: int) -> np.ndarray:
    cols, rows = board.squares
    cells = (np.add.outer(np.arange(rows), np.arange(cols)) % 2 == 1) * 255
    texture = np.kron(cells, np.ones((px, px))).astype(np.uint8)
    return cv2.copyMakeBorder(texture, px, px, px, px, cv2.BORDER_CONSTANT, value=255)


def chessboard_views(rays, board: Chessboard, poses) -> list[np.ndarray]:
    px = 160
    texture = chessboard_texture(board, px)
    # The inner corners start one square in from the board's outer corner.
    return [render(rays, texture, px / board.square_size, 2 * px, r, t) for r, t in poses]


def charuco_views(rays, board: CharucoBoard, poses) -> list[np.ndarray]:
    px = 160
    texture = board.image(px, margin=px)
    return [render(rays, texture, px / board.square_size, px, r, t) for r, t in poses]


def assert_recovers_synthetic_intrinsics(camera, sigma, rel_f: float = 3e-3) -> None:
    assert camera.fx == pytest.approx(K[0, 0], rel=rel_f)
    assert camera.fy == pytest.approx(K[1, 1], rel=rel_f)
    # The principal point trades against the board poses: within 3 of the fit's own
    # sigmas, and within 3 px.
    assert abs(camera.cx - K[0, 2]) < min(3 * sigma[2], 3.0)
    assert abs(camera.cy - K[1, 2]) < min(3 * sigma[3], 3.0)


def lens_error(camera) -> float:
    """Largest difference (px) between the fitted and the true lens: where each maps a
    ray, relative to its principal point, over the field the views cover."""
    x, y = np.meshgrid(np.linspace(-0.45, 0.45, 10), np.linspace(-0.35, 0.35, 8))
    rays = np.column_stack([x.ravel(), y.ravel(), np.ones(x.size)])
    fitted, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), camera.matrix,
                                  camera.dist_coeffs)
    xd, yd = distort(x.ravel(), y.ravel())
    truth = np.column_stack([K[0, 0] * xd, K[1, 1] * yd])
    return float(np.abs(fitted.reshape(-1, 2) - [camera.cx, camera.cy] - truth).max())


# -- real data ------------------------------------------------------------------------

def test_charuco_real_images_match_opencv_reference():
    result = calibrate_camera(charuco_images(), opencv_board())
    cam = result.camera
    assert (cam.width, cam.height) == (640, 480)
    assert cam.fx == pytest.approx(OPENCV_CHARUCO["fx"], rel=0.02)
    assert cam.fy == pytest.approx(OPENCV_CHARUCO["fy"], rel=0.02)
    assert cam.cx == pytest.approx(OPENCV_CHARUCO["cx"], abs=5.0)
    assert cam.cy == pytest.approx(OPENCV_CHARUCO["cy"], abs=5.0)
    assert result.rms < 0.25
    assert result.image_count == 4 and result.rejected == ()
    # 24 corners in every image: the overall rms is the mean of the per-image squares.
    assert np.sqrt(np.mean(np.square(result.per_image_rms))) == pytest.approx(result.rms,
                                                                            rel=1e-6)
    # The reference lies within the fit's own uncertainty.
    assert abs(cam.fx - OPENCV_CHARUCO["fx"]) < 2 * result.sigma[0]


def test_legacy_layout_is_the_same_board_for_seven_rows():
    # OpenCV 4.6 changed the ChArUco layout only for an even number of rows: this
    # 5x7 board reads identically in both layouts.
    legacy, current = opencv_board(legacy=True), opencv_board()
    for path in charuco_images():
        image = cv2.imread(str(path))
        a, b = legacy.detect(image), current.detect(image)
        assert len(a.image_points) == 24
        np.testing.assert_array_equal(a.object_points, b.object_points)
        np.testing.assert_array_equal(a.image_points, b.image_points)


def test_real_duplicate_image_is_rejected_and_named():
    # choriginal.jpg is byte for byte img_01.jpg: counting it twice would fake certainty.
    images = [*charuco_images(), real_data("calib/opencv_charuco/choriginal.jpg")]
    result = calibrate_camera(images, opencv_board())
    assert result.image_count == 4
    (rejected,) = result.rejected
    assert rejected.name.endswith("choriginal.jpg")
    assert "img_01.jpg" in rejected.reason


def test_chessboard_real_ciclop_captures_match_notebook():
    folder = real_data("laser/ciclop_3dscanscience/4.2_camera_calibration_captures")
    images = sorted(folder.glob("frame*.jpg"))
    assert len(images) == 16
    result = calibrate_camera(images, Chessboard((12, 7), 0.013))
    cam = result.camera
    assert (cam.width, cam.height) == (960, 1280)
    assert result.image_count == 16 and result.rejected == ()
    assert cam.fx == pytest.approx(CICLOP_NOTEBOOK["fx"], rel=0.005)
    assert cam.fy == pytest.approx(CICLOP_NOTEBOOK["fy"], rel=0.005)
    assert cam.cx == pytest.approx(CICLOP_NOTEBOOK["cx"], abs=2.0)
    assert cam.cy == pytest.approx(CICLOP_NOTEBOOK["cy"], abs=2.0)
    assert result.rms < 0.3


def test_too_few_views_is_refused_when_focal_length_is_uncertain():
    # Three of the four real images leave fx uncertain by ~14% (and 20% off): refused.
    with pytest.raises(CalibrationError, match="focal length uncertain"):
        calibrate_camera(charuco_images()[:3], opencv_board())


# -- synthetic views of a known camera --------------------------------------------------

def test_chessboard_synthetic_recovers_known_camera(pixel_rays):
    board = Chessboard((9, 7), 0.03)
    images = chessboard_views(pixel_rays, board, TILTED_POSES)
    # Detected corners sit where the true camera projects the board's corners.
    for image, (rvec, tvec) in zip(images, TILTED_POSES, strict=True):
        view = board.detect(image)
        truth, _ = cv2.projectPoints(view.object_points.astype(np.float64),
                                     np.array(rvec), np.array(tvec), K, DIST)
        error = np.linalg.norm(truth.reshape(-1, 2) - view.image_points, axis=1)
        if error.mean() > 1.0:  # the symmetric board was read from its other end
            error = np.linalg.norm(truth.reshape(-1, 2)[::-1] - view.image_points, axis=1)
        assert error.mean() < 0.1
    result = calibrate_camera(images, board)
    assert result.rms < 0.1
    assert_recovers_synthetic_intrinsics(result.camera, result.sigma)
    assert lens_error(result.camera) < 0.35


def test_charuco_even_rows_needs_the_legacy_layout(pixel_rays):
    legacy = CharucoBoard((5, 6), 0.04, 0.028, legacy=True)
    poses = [(r, (t[0] + 0.105, t[1] + 0.015, 0.38)) for r, t in TILTED_POSES[:4]]
    images = charuco_views(pixel_rays, legacy, poses)
    result = calibrate_camera(images, legacy)
    assert result.image_count == 4
    assert_recovers_synthetic_intrinsics(result.camera, result.sigma, rel_f=5e-3)
    # Read with the current layout, the markers are found but (in 3 of the 4 views) no
    # corner is, and the refusal points at the layout.
    current = CharucoBoard((5, 6), 0.04, 0.028)
    with pytest.raises(CalibrationError, match=r"found in 1 of 4") as error:
        calibrate_camera(images, current)
    assert str(error.value).count("markers found but no corner") == 3
    assert "legacy layout" in str(error.value)


def test_fronto_parallel_views_are_degenerate(pixel_rays):
    board = Chessboard((9, 7), 0.03)
    poses = [((0.0, 0.0, 0.0), t) for _, t in TILTED_POSES]
    with pytest.raises(CalibrationError, match="faces the camera squarely"):
        calibrate_camera(chessboard_views(pixel_rays, board, poses), board)


def test_parallel_tilted_views_are_degenerate(pixel_rays):
    # Tilted, but all the same way: the focal length is not observable (Zhang).
    board = Chessboard((9, 7), 0.03)
    poses = [((0.3, 0.0, 0.0), t) for _, t in TILTED_POSES]
    with pytest.raises(CalibrationError, match="same orientation"):
        calibrate_camera(chessboard_views(pixel_rays, board, poses), board)


# -- exact corners (no detection) --------------------------------------------------------

def projected_views(board: Chessboard, matrix: np.ndarray, dist: np.ndarray,
                    shift_x: float = 0.0) -> list[BoardView]:
    """The board's corners projected exactly from the tilted poses."""
    views = []
    for rvec, tvec in TILTED_POSES:
        pixels, _ = cv2.projectPoints(board.corner_points.astype(np.float64), np.array(rvec),
                                      np.array(tvec) + (shift_x, 0.0, 0.0), matrix, dist)
        views.append(BoardView(board.corner_points, pixels.reshape(-1, 2).astype(np.float32)))
    return views


def test_exact_corners_give_the_exact_camera():
    result = calibrate_views(projected_views(Chessboard((9, 7), 0.03), K, DIST), (W, H),
                             [f"v{i}" for i in range(len(TILTED_POSES))])
    cam = result.camera
    np.testing.assert_allclose([cam.fx, cam.fy, cam.cx, cam.cy], K[[0, 1, 0, 1], [0, 1, 2, 2]],
                               atol=0.01)
    np.testing.assert_allclose(cam.distortion, DIST, atol=1e-3)
    assert result.rms < 1e-3
    assert result.images == tuple(f"v{i}" for i in range(len(TILTED_POSES)))


def test_reprojection_errors_are_opencvs_and_are_written_to_the_opencv_yaml(tmp_path):
    # Corners with 0.3 px noise: the errors are those of cv2.calibrateCamera on the same
    # corners, and per image those recomputed with cv2.projectPoints from its poses.
    views = projected_views(Chessboard((9, 7), 0.03), K, DIST)
    rng = np.random.default_rng(3)
    views = [BoardView(v.object_points, (v.image_points + rng.normal(0, 0.3, v.image_points.shape)
                                         ).astype(np.float32)) for v in views]
    names = [f"v{i}" for i in range(len(views))]
    result = calibrate_views(views, (W, H), names)
    objects = [v.object_points.reshape(-1, 3).astype(np.float32) for v in views]
    pixels = [v.image_points.reshape(-1, 2) for v in views]  # float32: errors agree to 1e-5
    rms, matrix, dist, rvecs, tvecs = cv2.calibrateCamera(objects, pixels, (W, H), None, None)
    assert result.rms == pytest.approx(rms, rel=1e-7)
    squared = [np.sum((cv2.projectPoints(o, r, t, matrix, dist)[0].reshape(-1, 2) - p) ** 2,
                      axis=1) for o, p, r, t in zip(objects, pixels, rvecs, tvecs, strict=True)]
    np.testing.assert_allclose(result.per_image_rms, [np.sqrt(e.mean()) for e in squared],
                               rtol=1e-5)
    assert np.sqrt(np.concatenate(squared).mean()) == pytest.approx(rms, rel=1e-5)
    path = tmp_path / "camera.yaml"
    write_opencv_yaml(result, path)
    # Our fit is cv2's to the optimiser's floating-point noise (CPUs with other SIMD paths
    # differ by ~4e-6 relative on the weakly determined k3); the file holds our fit exactly.
    cam = result.camera
    np.testing.assert_allclose([cam.fx, cam.fy, cam.cx, cam.cy],
                               matrix[[0, 1, 0, 1], [0, 1, 2, 2]], rtol=1e-5)
    np.testing.assert_allclose(cam.distortion, dist.ravel()[:5], rtol=1e-4, atol=1e-8)
    stored = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(stored.getNode("camera_matrix").mat(),
                                  [[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])
    np.testing.assert_array_equal(stored.getNode("distortion_coefficients").mat().ravel(),
                                  cam.distortion)
    assert stored.getNode("avg_reprojection_error").real() == result.rms
    np.testing.assert_allclose(stored.getNode("per_view_reprojection_errors").mat().ravel(),
                               result.per_image_rms, rtol=1e-12)
    assert (stored.getNode("image_width").real(), stored.getNode("image_height").real(),
            stored.getNode("nr_of_frames").real()) == (W, H, len(views))
    stored.release()


def test_principal_point_outside_the_image_is_refused():
    matrix = K.copy()
    matrix[0, 2] = -400.0  # corners seen as by a camera whose axis misses the image
    views = projected_views(Chessboard((9, 7), 0.03), matrix, np.zeros(5), shift_x=0.54)[:4]
    with pytest.raises(CalibrationError, match=r"degenerate data, the fit gave .*cx -3"):
        calibrate_views(views, (W, H), [f"v{i}" for i in range(len(views))])


def test_misdetected_corners_are_refused_by_reprojection_error():
    views = projected_views(Chessboard((9, 7), 0.03), K, DIST)
    swapped = views[2].image_points.copy()
    swapped[[0, -1]] = swapped[[-1, 0]]  # two corners matched to the wrong board points
    views[2] = BoardView(views[2].object_points, swapped)
    with pytest.raises(CalibrationError, match=r"reprojection error .* \(worst v2: "):
        calibrate_views(views, (W, H), [f"v{i}" for i in range(len(views))])


def test_opencv_failure_becomes_a_calibration_error():
    # Board points off a plane: OpenCV refuses a non-planar rig without an initial guess.
    board = Chessboard((9, 7), 0.03)
    views = projected_views(board, K, DIST)
    bumpy = board.corner_points + np.array([0.0, 0.0, 0.01], dtype=np.float32) * (
        np.arange(len(board.corner_points))[:, None] % 2)
    views = [BoardView(bumpy, v.image_points) for v in views]
    with pytest.raises(CalibrationError, match=r"degenerate data .*non-planar"):
        calibrate_views(views, (W, H), [f"v{i}" for i in range(len(views))])


# -- refusals ---------------------------------------------------------------------------

def test_no_images():
    with pytest.raises(CalibrationError, match="no images"):
        calibrate_camera([], opencv_board())


def test_missing_and_unreadable_images_are_named(tmp_path):
    with pytest.raises(CalibrationError, match=r"nothere\.jpg: image file not found"):
        calibrate_camera([tmp_path / "nothere.jpg"], opencv_board())
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"not a jpeg")
    with pytest.raises(CalibrationError, match=r"broken\.jpg: not a readable image"):
        calibrate_camera([*charuco_images(), broken], opencv_board())


def test_bad_arrays_are_refused():
    with pytest.raises(CalibrationError, match=r"image\[0\]: expected an 8-bit"):
        calibrate_camera([np.zeros((4, 4), dtype=np.float32)], opencv_board())


def test_mixed_image_sizes_name_both_files():
    ciclop = real_data("laser/ciclop_3dscanscience/4.2_camera_calibration_captures/frame0.jpg")
    with pytest.raises(CalibrationError, match=r"img_00\.jpg is 640x480.*frame0\.jpg is 960x1280"):
        calibrate_camera([*charuco_images(), ciclop], opencv_board())


def test_board_not_found_lists_every_image():
    with pytest.raises(CalibrationError, match="found in 0 of 2") as error:
        calibrate_camera(charuco_images()[:2], Chessboard((12, 7), 0.013))
    message = str(error.value)
    assert all(f"img_0{i}.jpg: no 12x7-square chessboard" in message for i in range(2))


def test_blank_image_has_no_board():
    blank = np.full((480, 640), 200, dtype=np.uint8)
    with pytest.raises(BoardNotFound, match="no ChArUco corners"):
        opencv_board().detect(blank)


def test_too_few_or_collinear_corners_are_not_a_view():
    line = np.array([[i * 0.04, 0.0, 0.0] for i in range(8)], dtype=np.float32)
    pixels = np.array([[100.0 + 20 * i, 50.0] for i in range(8)], dtype=np.float32)
    with pytest.raises(BoardNotFound, match="lie on one line"):
        _view(line, pixels)
    with pytest.raises(BoardNotFound, match="only 5 corners"):
        _view(line[:5], pixels[:5])


@pytest.mark.parametrize(("changes", "field"), [
    ({"marker_size": 0.05}, "marker_size"),
    ({"marker_size": float("nan")}, "marker_size"),
    ({"square_size": 0.0}, "square_size"),
    ({"squares": (2, 7)}, "squares"),
    ({"squares": (5.0, 7)}, "squares"),
    ({"dictionary": "DICT_9X9_1"}, "dictionary"),
])
def test_invalid_charuco_board_names_the_field(changes, field):
    with pytest.raises(CalibrationError, match=f"board {field}"):
        opencv_board(**changes)


def test_invalid_chessboard_names_the_field():
    with pytest.raises(CalibrationError, match="board squares"):
        Chessboard((3, 7), 0.02)
    with pytest.raises(CalibrationError, match="board square_size"):
        Chessboard((8, 7), -0.02)
