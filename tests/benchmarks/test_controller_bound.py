"""The controller benchmark's measures (`bench_controller`): the swept path against the
closed form of a disc moving along a segment, what no scan could see against hand-placed
cells, and the map never knowing a path that no scan could have seen."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.bench_controller import (
    SWEEP_STEP,
    blocked,
    corridor_drive,
    floor_annulus,
    recording_drive,
    swept_cells,
    unseeable,
)
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim import ScanTruth, truth_path
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.raster import DROP_OFF, FLOOR, OBSTACLE, TruthRaster
from scanmap_driver.sim.scene import builtin_scene
from scanmap_driver.sim.simulate import simulate_recording

RES = 0.05


def segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each point to the segment a-b."""
    t = np.clip((points - a) @ (b - a) / max((b - a) @ (b - a), 1e-18), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1)


@settings(max_examples=60, deadline=None)
@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-math.pi, math.pi), st.floats(0, 1.0),
       st.floats(0.05, 0.4))
def test_the_swept_path_holds_the_cells_the_moving_disc_covers(x, y, yaw, reach, radius):
    cells = swept_cells(x, y, yaw, reach, radius, RES)
    a = np.array([x, y])
    b = a + reach * np.array([math.cos(yaw), math.sin(yaw)])
    # every cell of the path lies within the disc's reach of the segment (its square's
    # corner at most half a diagonal from its centre) ...
    assert (segment_distance(cells, a, b) < radius + RES / math.sqrt(2) + 1e-9).all()
    # ... and every cell whose centre the disc passes over, with room for the sampling
    grid = np.mgrid[math.floor((min(a[0], b[0]) - radius) / RES):
                    math.ceil((max(a[0], b[0]) + radius) / RES) + 1,
                    math.floor((min(a[1], b[1]) - radius) / RES):
                    math.ceil((max(a[1], b[1]) + radius) / RES) + 1].reshape(2, -1).T
    centres = (grid + 0.5) * RES
    inside = centres[segment_distance(centres, a, b) < radius - SWEEP_STEP]
    held = {tuple(c) for c in np.round(cells / RES - 0.5).astype(int)}
    assert all(tuple(c) in held for c in np.round(inside / RES - 0.5).astype(int))


def test_a_cell_is_unseeable_only_outside_every_floor_annulus_and_footprint():
    positions = np.array([[0.0, 0.0], [10.0, 0.0]])
    cells = np.array([[1.0, 0.0],  # within the first pose's blind disc: unseeable
                      [2.0, 0.0],  # in the first pose's annulus
                      [0.1, 0.0],  # under the robot
                      [5.0, 0.0],  # beyond the first's annulus, nearer than the second's
                      [7.0, 0.0]])  # in the second pose's annulus
    assert unseeable(cells, positions, (1.5, 4.0), 0.25, RES) == 2
    assert unseeable(cells[[1, 2, 4]], positions, (1.5, 4.0), 0.25, RES) == 0


def test_a_path_is_blocked_by_the_truth_s_obstacle_and_drop_off_cells_it_covers():
    classes = np.full((10, 10), FLOOR, np.uint8)
    classes[2, 5] = OBSTACLE
    classes[7, 1] = DROP_OFF
    raster = TruthRaster(classes, np.array([0.0, 0.0]), RES, (0.05, 1.0))
    cells = np.array([[5.5, 2.5],  # the obstacle (x from column 5, y from row 2)
                      [1.5, 7.5],  # the drop-off
                      [2.5, 2.5],  # floor
                      [-0.5, -0.5]]) * RES  # outside the raster
    assert blocked(cells, raster) == 2
    assert blocked(cells[2:], raster) == 0


def test_the_floor_annulus_is_where_the_true_rays_meet_the_floor():
    """Against the simulator's noise-free points of the same scan (base_link: the robot
    stands still while the first scan turns)."""
    first = next(iter(ideal_scans(builtin_scene("corridor"), scans=1)))
    floor = np.abs(first.true_points[:, 2]) < 1e-6
    true_ranges = np.hypot(first.true_points[floor, 0], first.true_points[floor, 1])
    near, far = floor_annulus(first)
    assert abs(near - true_ranges.min()) < 0.01 and abs(far - true_ranges.max()) < 0.02


def test_the_map_never_knows_a_path_no_scan_could_have_seen():
    drive = corridor_drive(8)
    assert drive["unseeable_ahead_scans"][:1] == [0]  # the start: nothing seen nearer
    assert set(drive["unseeable_ahead_scans"]) <= set(drive["unknown_ahead_scans"])
    assert drive["unknown_ahead_share"] >= drive["unseeable_ahead_share"] > 0
    assert all(0.0 <= t <= 1.0 for t in drive["travel_m"])
    # The bin (r 0.18 m at x 2.8, y -0.52) meets the robot's disc within 0.19 m of scan
    # 7's true pose, and the map does not let it drive there either
    assert drive["blocked_ahead_scans"] == [7]
    assert drive["travel_m"][7] < 0.19
    avoidable = set(drive["avoidable_unknown_scans"])
    assert avoidable == set(drive["unknown_ahead_scans"]) - {7} - set(
        drive["unseeable_ahead_scans"])


def test_on_a_rendered_recording_too_the_map_never_knows_a_path_no_scan_could_have_seen(
        tmp_path):
    recording = tmp_path / "corridor"
    simulate_recording(builtin_scene("corridor"), recording, reference_scanner(), scans=3)
    drive = recording_drive(recording)
    assert drive["scans"] == 3
    # The annulus of the extracted points against the simulator's lit floor stripe of
    # the same scan (true points in base_link; the robot stands while the head turns):
    # the points lie on it within the range error, none beyond its ends (its nearest
    # 13 cm yield no points here: 1.62 m against 1.50)
    truth = ScanTruth.load(truth_path(recording, 0), mask=False).laser
    floor = (np.abs(truth["base"][:, 2]) < 1e-6) & ~truth["shadowed"]
    true_ranges = np.hypot(truth["base"][floor, 0], truth["base"][floor, 1])
    near, far = drive["floor_annulus_m"]
    assert true_ranges.min() - 0.02 <= near < far <= true_ranges.max() + 0.02
    assert drive["unseeable_ahead_scans"][:1] == [0]
    assert set(drive["unseeable_ahead_scans"]) <= set(drive["unknown_ahead_scans"])
