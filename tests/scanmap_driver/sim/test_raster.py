"""The ground-truth raster: obstacle cells by exact overlap, floor reachable, outside not."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.sim.raster import FLOOR, OBSTACLE, OUTSIDE, TruthRaster, truth_raster
from scanmap_driver.sim.scene import Scene

WALL = [200, 200, 200]


def _room(objects):
    """A closed 4 x 4 m room (walls 0.1 m thick, inner faces at 0 and 4) plus objects."""
    walls = [
        {"type": "box", "center": [2.0, -0.05, 1.0], "size": [4.2, 0.1, 2.0], "color": WALL},
        {"type": "box", "center": [2.0, 4.05, 1.0], "size": [4.2, 0.1, 2.0], "color": WALL},
        {"type": "box", "center": [-0.05, 2.0, 1.0], "size": [0.1, 4.2, 2.0], "color": WALL},
        {"type": "box", "center": [4.05, 2.0, 1.0], "size": [0.1, 4.2, 2.0], "color": WALL},
    ]
    return Scene.from_dict({"format": "scanmap.scene/1", "floor": {"color": WALL},
                            "ambient": 1.0, "objects": walls + objects,
                            "scan_poses": [[0.5, 0.5, 0.0]]})


def _class_at(raster, x, y):
    return raster.class_at(np.array([[x, y]]))[0]


def test_points_beyond_the_raster_are_outside():
    classes = np.array([[FLOOR, OBSTACLE], [OBSTACLE, FLOOR]], np.uint8)
    raster = TruthRaster(classes, np.array([1.0, 2.0]), 0.5, (0.05, 1.0))
    points = np.array([[1.25, 2.25], [1.75, 2.25], [1.25, 2.75], [0.9, 2.25], [2.1, 2.25],
                       [1.25, 1.9], [1.25, 3.1]])
    assert raster.class_at(points).tolist() == [FLOOR, OBSTACLE, OBSTACLE] + [OUTSIDE] * 4


def test_classes_of_a_room():
    scene = _room([
        {"type": "box", "center": [1.0, 3.0, 0.5], "size": [0.4, 0.4, 1.0], "color": WALL},
        {"type": "box", "center": [3.0, 1.0, 0.72], "size": [0.6, 0.6, 0.04], "color": WALL},
        {"type": "box", "center": [3.0, 3.0, 1.5], "size": [0.6, 0.6, 0.2], "color": WALL},
        {"type": "box", "center": [2.0, 2.0, 0.02], "size": [0.6, 0.6, 0.04], "color": WALL},
        {"type": "cylinder", "center": [1.0, 1.0, 0.3], "radius": 0.2, "height": 0.6,
         "color": WALL},
    ])
    raster = truth_raster(scene, resolution=0.05, low=0.05, high=1.0)
    assert _class_at(raster, 1.0, 3.0) == OBSTACLE  # a cabinet
    assert _class_at(raster, 3.0, 1.0) == OBSTACLE  # a table top at 0.72 m: an overhang
    assert _class_at(raster, 3.0, 3.0) == FLOOR  # a shelf above the robot
    assert _class_at(raster, 2.0, 2.0) == FLOOR  # a 4 cm step: driven over
    assert _class_at(raster, 1.0, 1.0) == OBSTACLE
    assert _class_at(raster, 1.0, 1.27) == FLOOR  # just beyond the cylinder's radius
    assert _class_at(raster, 2.0, -0.05) == OBSTACLE  # a wall
    assert _class_at(raster, 2.0, -0.3) == OUTSIDE  # behind it
    free = (raster.classes == FLOOR).sum() * 0.05 ** 2
    # room 16 m^2 less the cabinet (0.16), table (0.36) and cylinder (~0.13) with cell rims
    assert 14.5 < free < 15.4


def test_save_and_load(tmp_path):
    raster = truth_raster(_room([]), resolution=0.1)
    raster.save(tmp_path / "r.npz")
    again = TruthRaster.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(again.classes, raster.classes)
    assert again.resolution == 0.1 and again.band == raster.band


@settings(max_examples=40, deadline=None)
@given(x=st.floats(1.0, 3.0), y=st.floats(1.0, 3.0), yaw=st.floats(-math.pi, math.pi),
       sx=st.floats(0.02, 1.0), sy=st.floats(0.02, 1.0))
def test_turned_boxes_cover_exactly_the_cells_they_overlap(x, y, yaw, sx, sy):
    box = {"type": "box", "center": [x, y, 0.5], "size": [sx, sy, 1.0], "yaw": yaw,
           "color": WALL}
    raster = truth_raster(_room([box]), resolution=0.1)
    # dense points inside the box: every cell holding one is an obstacle
    u, v = np.meshgrid(np.linspace(-0.499, 0.499, 60), np.linspace(-0.499, 0.499, 60))
    c, s = math.cos(yaw), math.sin(yaw)
    px = x + c * u.ravel() * sx - s * v.ravel() * sy
    py = y + s * u.ravel() * sx + c * v.ravel() * sy
    cells = raster.cell_of(np.column_stack([px, py]))
    assert np.all(raster.classes[cells[:, 0], cells[:, 1]] == OBSTACLE)
    # and no cell farther than a cell diagonal from the box is marked
    rows, cols = np.nonzero(raster.classes == OBSTACLE)
    cx = raster.origin[0] + (cols + 0.5) * 0.1
    cy = raster.origin[1] + (rows + 0.5) * 0.1
    inner = (cx > 0.2) & (cx < 3.8) & (cy > 0.2) & (cy < 3.8)
    lx = np.abs(c * (cx - x) + s * (cy - y)) - sx / 2
    ly = np.abs(-s * (cx - x) + c * (cy - y)) - sy / 2
    gap = np.hypot(np.maximum(lx, 0), np.maximum(ly, 0))
    assert np.all(gap[inner] < 0.1 * math.sqrt(0.5) + 1e-9)
