"""Pictures and progress: the overhead view, the occupancy image, PNG files, the bar."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scanmap import MapError
from scanmap.io.map_image import (
    BETWEEN_SHADE,
    FREE_SHADE,
    OCCUPIED_SHADE,
    UNKNOWN_SHADE,
    occupancy_image,
    write_png,
)
from scanmap.io.overhead import FLOOR_BGR, INK, height_colours, overhead_view


def test_overhead_shows_the_highest_point_of_each_pixel_coloured_by_height():
    points = np.array([[0.0, 0.0, 0.0],  # floor
                       [1.0, 0.0, 0.0], [1.0, 0.0, 0.8],  # floor under a high point
                       [0.5, 0.5, 0.2]])
    image = overhead_view(points, resolution=0.01)
    assert image.shape[:2] == (round(0.5 / 0.01) + 61, round(1.0 / 0.01) + 61)

    def at(x: float, y: float) -> tuple[int, ...]:
        return tuple(image[image.shape[0] - 1 - round((y + 0.3) / 0.01), round((x + 0.3) / 0.01)])

    assert at(0.0, 0.0) == FLOOR_BGR
    high, low = at(1.0, 0.0), at(0.5, 0.5)
    assert high == tuple(height_colours(np.array([0.8]), 0.03, 1.0)[0])
    assert high[2] > high[0] and low[0] > low[2]  # red-ish high, blue-ish low
    assert at(0.25, 0.25) == (255, 255, 255)  # nothing there


def test_overhead_draws_the_path_and_survives_empty_input():
    path = np.array([[0.0, 0.0], [2.0, 0.0]])
    image = overhead_view(np.zeros((0, 3)), path=path, resolution=0.01)
    row = image.shape[0] - 1 - round(0.3 / 0.01)
    line = image[row - 1:row + 2, 50:200].min(axis=(0, 2))  # anti-aliased ink, 1 px wide
    assert (line <= max(INK) + 30).all()
    assert overhead_view(np.full((3, 3), np.nan)).shape == (64, 64, 3)


def test_occupancy_image_uses_map_server_shades_north_up(tmp_path):
    grid = np.array([[-1, 0, 50], [100, 10, 70]], np.int8)  # row 0 is the lowest y
    picture = occupancy_image(grid, origin=(1.0, 2.0), resolution=0.1, scale=3)
    grey = picture.image[..., 0]
    assert grey.shape == (6, 9)
    expected = np.array([[OCCUPIED_SHADE, FREE_SHADE, OCCUPIED_SHADE],
                         [UNKNOWN_SHADE, FREE_SHADE, BETWEEN_SHADE]])
    np.testing.assert_array_equal(grey[::3, ::3], expected)
    # the centre of cell (row 1, col 2) at (1.25, 2.15) lands inside its 3x3 block
    col, row = picture.pixel(np.array([[1.25, 2.15]]))[0]
    assert 6 <= col < 9 and 0 <= row < 3
    write_png(tmp_path / "map.png", picture.image)
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "map.png")), picture.image)
    with pytest.raises(MapError, match="scale"):
        occupancy_image(grid, (0, 0), 0.1, scale=0)
