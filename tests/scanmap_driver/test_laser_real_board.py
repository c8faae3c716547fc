"""The default laser extraction against the simple detector on the real flat board
(3DScanScience 3.2: two laser lines on a chessboard): the line on a plane is straight
once the lens is undone. The measure (rows, outliers, RMS off the fitted line) is defined
once, in benchmarks/bench_laser.py, and applied identically to both detectors."""

from __future__ import annotations

import pytest

from benchmarks.bench_laser import BOARD_IMAGES, flat_board
from tests.conftest import real_data

PLAIN, CROSSED = BOARD_IMAGES
# Measured on the plain image: ours 875 rows / 3 outliers, the simple detector 876 / 2.
# Our outliers lie 1.07-1.20 px off (the simple detector's 0.95-1.00 px there): rows 41-42
# of the left line, whose right flank a dark seam between the board's panels cuts, and
# row 37 of the right line, where both detectors give the same position.
# Why (measured 2026-11-24 with this measure): the simple detector's edge is its blur
# across the lines (cv2.GaussianBlur is 2D). Blurred along the lines only, it gives
# 868 / 10 (crossed image 788 / 96, against its 794 / 90) and 274.14 / 273.98 px at rows
# 41-42 (ours 274.04 / 274.03, the fitted line 275.23): both detectors dip over rows 38-44
# there, and only averaging along the stripe makes the dip shallower. No per-line change
# tried reaches 876 / 2 (the other estimators and fit channels, smoothing sigma 1.2, a
# side-mean background, centroid levels 0.3-0.6, red clipped at 180 taken as saturation).
# Our fit profiles averaged over +-2 lines (sigma 1) tie it, 876 / 2 with RMS about
# 0.33 px (crossed 815 / 62), by moving row 37 of the right line inside 1 px (rows 41-42
# stay 1.10 px off); but the synthetic frames' true stripe steps 0.37 px from line to
# line (every subpixel phase), and such averaging costs them ~0.2 px RMS (dark 0.03 ->
# 0.22 px). The margin is thin either way: the simple detector's row 37 of the right
# line lies 0.997 px off.
SHORT_ON_PLAIN = pytest.mark.xfail(
    strict=True, reason="plain board image: 1 row fewer and 1 outlier more than the simple "
                        "detector (issue 14 item 3, open)")


@pytest.fixture(scope="module")
def board() -> dict:
    real_data("laser/ciclop_3dscanscience/3.2_laser_in_pattern")
    real_data("laser/ciclop_3dscanscience/4.2_camera_calibration_captures")
    return flat_board()


@pytest.mark.parametrize("image", BOARD_IMAGES)
def test_straight_line_rms_is_no_worse_than_the_simple_detector(board, image):
    ours, simple = board[image]["ours (default)"], board[image]["simple"]
    assert ours["rms_px"] <= simple["rms_px"]


@pytest.mark.parametrize("image", [pytest.param(PLAIN, marks=SHORT_ON_PLAIN), CROSSED])
def test_no_more_outliers_than_the_simple_detector(board, image):
    assert board[image]["ours (default)"]["outliers"] <= board[image]["simple"]["outliers"]


@pytest.mark.parametrize("image", [pytest.param(PLAIN, marks=SHORT_ON_PLAIN), CROSSED])
def test_no_fewer_rows_than_the_simple_detector(board, image):
    assert board[image]["ours (default)"]["rows"] >= board[image]["simple"]["rows"]


def test_the_measure_sees_the_whole_board(board):
    """Sanity of the measure: both detectors put most board rows on the line."""
    for image in BOARD_IMAGES:
        for result in board[image].values():
            assert result["rows"] > 0.85 * result["board_rows"]
            assert 0.2 < result["rms_px"] < 0.5
