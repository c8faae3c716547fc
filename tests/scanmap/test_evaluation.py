"""The error measures of `scanmap map` reports, on cases whose answer is known."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from scanmap.evaluation import ground_truth as evaluation
from scanmap.navigation import morphology
from scanmap.navigation.floor import DROP_OFF, FREE, OBSTACLE, UNKNOWN, RobotShape, Segmentation
from scanmap_driver.processing import recording_scans
from scanmap_driver.recording import Recording
from scanmap_driver.sim import Scene, builtin_scene, truth_raster
from scanmap_driver.sim import raster as truth
from scanmap_driver.sim.truth import ScanTruth, truth_path
from scanmap_driver.transforms import se2_to_pose


def segmentation_of(raster, origin=None, drop_off=DROP_OFF) -> Segmentation:
    """A perfect map: the raster's classes as states (outside -> unknown), drop-offs as
    `drop_off`."""
    state = np.full(raster.classes.shape, UNKNOWN, np.uint8)
    state[raster.classes == truth.FLOOR] = FREE
    state[raster.classes == truth.OBSTACLE] = OBSTACLE
    state[raster.classes == truth.DROP_OFF] = drop_off
    ny, nx = state.shape
    nan = np.full((ny, nx), np.nan, np.float32)
    return Segmentation(origin=tuple(raster.origin if origin is None else origin),
                        resolution=raster.resolution, robot=RobotShape(), floor_height=nan,
                        is_floor=state == FREE, planes=(), state=state,
                        points=np.zeros((ny, nx, 2), np.float32), band_logodds=nan,
                        updated=np.zeros((ny, nx)))


@pytest.fixture(scope="module")
def office_raster():
    return truth_raster(builtin_scene("office"))


def test_a_perfect_map_scores_one(office_raster):
    errors = evaluation.map_errors(segmentation_of(office_raster), office_raster, np.eye(4))
    for key in ("obstacle_precision", "obstacle_recall", "obstacle_f1", "obstacle_coverage",
                "free_precision"):
        assert errors[key] == 1.0, key
    assert errors["free_cells_on_obstacles"] == 0


def test_a_perfect_map_in_a_turned_frame_scores_one(office_raster):
    """The map frame turned 90 deg in the world: the grid is the transposed raster."""
    turned = dataclasses.replace(office_raster, classes=office_raster.classes.T[::-1].copy(),
                                 origin=np.zeros(2))
    nx = office_raster.classes.shape[1]
    # world (x, y) = (-y', x') + (origin x + nx cells, origin y): map cell (r', c') is
    # raster cell (c', nx - 1 - r')
    world_from_map = se2_to_pose(office_raster.origin[0] + nx * office_raster.resolution,
                                 office_raster.origin[1], np.pi / 2)
    errors = evaluation.map_errors(segmentation_of(turned), office_raster, world_from_map)
    assert errors["obstacle_f1"] == pytest.approx(1.0)
    assert errors["free_precision"] == pytest.approx(1.0)


def test_a_map_three_cells_off_loses_precision_and_claims_free_on_obstacles(office_raster):
    shifted = office_raster.origin + 3 * office_raster.resolution
    errors = evaluation.map_errors(segmentation_of(office_raster, shifted), office_raster,
                                   np.eye(4))
    assert errors["obstacle_precision"] < 0.8 and errors["obstacle_f1"] < 0.8
    assert errors["free_cells_on_obstacles"] > 50 and errors["free_precision"] < 0.99


@pytest.fixture(scope="module")
def hazards_raster():
    return truth_raster(builtin_scene("hazards"))


def test_obstacles_where_no_robot_goes_are_not_false_but_those_on_floor_are(hazards_raster):
    """The hazards scene's platform top and too steep ramp are outside the truth (no robot
    gets there): a map calling them obstacles keeps its precision; calling as many floor
    cells obstacles loses it in proportion."""
    seg = segmentation_of(hazards_raster)
    outside = hazards_raster.classes == truth.OUTSIDE
    inside = morphology.dilate(hazards_raster.classes == truth.FLOOR, 3) & outside
    assert inside.sum() > 100  # the platform's and the steep ramp's tops, the walls' backs
    state = seg.state.copy()
    state[inside] = OBSTACLE
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4))
    assert errors["obstacle_precision"] == 1.0
    floor = (hazards_raster.classes == truth.FLOOR) & ~morphology.dilate(
        hazards_raster.classes == truth.OBSTACLE, 2)
    claimed = np.flatnonzero(floor)[:int(inside.sum())]
    state = seg.state.copy()
    state.flat[claimed] = OBSTACLE
    obstacles = int((seg.state == OBSTACLE).sum())
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4))
    assert errors["obstacle_precision"] == pytest.approx(obstacles / (obstacles + len(claimed)))


def test_a_perfect_map_finds_every_drop_off_and_places_its_edge_on_it(hazards_raster,
                                                                     office_raster):
    errors = evaluation.map_errors(segmentation_of(hazards_raster), hazards_raster, np.eye(4))
    assert errors["free_cells_on_drop_offs"] == errors["free_cells_inside_drop_offs"] == 0
    assert errors["drop_off_recall"] == 1.0
    assert errors["drop_off_edge_cells"] > 100  # the stairwell's and the dock's rims
    assert errors["drop_off_edge_error_cells"] == 0.0 and errors["drop_off_edge_within_one"] == 1
    assert errors["false_drop_off_cells"] == 0
    office = evaluation.map_errors(segmentation_of(office_raster), office_raster, np.eye(4))
    assert "drop_off_recall" not in office  # no drop-off in the scene: nothing to report
    assert office["false_drop_off_cells"] == 0  # but the claims of one, none here


def test_drop_off_cells_in_a_scene_without_drop_offs_are_all_false(office_raster):
    seg = segmentation_of(office_raster)
    rows, cols = np.nonzero(seg.state == FREE)  # true floor, all of it
    state = seg.state.copy()
    state[rows[:40], cols[:40]] = DROP_OFF
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), office_raster,
                                   np.eye(4))
    assert errors["false_drop_off_cells"] == 40 and "drop_off_recall" not in errors


def test_drop_offs_called_free_are_counted_and_found_by_none(hazards_raster):
    true_drop = hazards_raster.classes == truth.DROP_OFF
    errors = evaluation.map_errors(segmentation_of(hazards_raster, drop_off=FREE),
                                   hazards_raster, np.eye(4))
    assert errors["free_cells_on_drop_offs"] == true_drop.sum()
    inner = (morphology.min_filter(true_drop, 3) > 0).sum()  # more than a cell inside
    assert 0 < errors["free_cells_inside_drop_offs"] == inner < true_drop.sum()
    assert errors["drop_off_recall"] == 0.0 and errors["drop_off_edge_cells"] == 0


def test_a_drop_off_reported_a_cell_wider_has_its_edge_a_cell_out(hazards_raster):
    """Its edge cells lie one cell from the truth beside a straight rim, sqrt(2) cells at
    the corners that stick out."""
    seg = segmentation_of(hazards_raster)
    wider = morphology.dilate(seg.state == DROP_OFF) & (seg.state == FREE)
    state = seg.state.copy()
    state[wider] = DROP_OFF
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4))
    assert errors["drop_off_edge_error_cells"] == pytest.approx(np.sqrt(2))
    assert 0.8 < errors["drop_off_edge_within_one"] < 1.0
    assert errors["drop_off_recall"] == 1.0 and errors["free_cells_on_drop_offs"] == 0
    assert errors["false_drop_off_cells"] == 0  # within a cell is no false claim


def test_on_the_scenes_fine_raster_a_ring_a_cell_wider_lies_half_a_cell_out(hazards_raster):
    """The same ring measured on a 1 cm raster drawn from the scene: its cells' centres lie
    half a cell beyond a straight rim and sqrt(2)/2 beyond a corner (plus half a 1 cm
    cell), not the 1 and sqrt(2) of the map's own cells' raster."""
    seg = segmentation_of(hazards_raster)
    state = seg.state.copy()
    state[morphology.dilate(seg.state == DROP_OFF) & (seg.state == FREE)] = DROP_OFF
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4), builtin_scene("hazards"))
    half = 0.5 + 0.5 * evaluation.EDGE_RASTER / hazards_raster.resolution
    assert errors["drop_off_edge_error_cells"] == pytest.approx(np.hypot(half, half), abs=0.01)
    assert errors["drop_off_edge_within_one"] == 1.0
    assert errors["free_cells_on_drop_offs"] == 0 and errors["false_drop_off_cells"] == 0


def test_a_drop_off_reported_two_cells_wider_claims_its_outer_ring_falsely(hazards_raster):
    seg = segmentation_of(hazards_raster)
    drop = seg.state == DROP_OFF
    once, twice = morphology.dilate(drop), morphology.dilate(drop, 2)
    state = seg.state.copy()
    state[twice & (seg.state == FREE)] = DROP_OFF
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4))
    ring = twice & ~once & (seg.state == FREE)
    assert ring.sum() > 100 and errors["false_drop_off_cells"] == ring.sum()


def test_statistics_and_trajectory_errors_in_closed_form():
    stats = evaluation.statistics(np.array([1.0, -2.0, 3.0, np.nan]))
    assert stats == {"count": 3, "mean_abs": 2.0, "median_abs": 2.0,
                     "p95_abs": pytest.approx(2.9), "max_abs": 3.0, "median": 1.0}
    reference = np.array([se2_to_pose(x, 0.5 * x, 0.1 * x) for x in range(5)])
    moved = se2_to_pose(3.0, -1.0, 0.7) @ reference  # the same path in another frame
    errors = evaluation.trajectory_errors(moved, reference)
    assert errors["ate_rmse"] < 1e-9 and errors["start_anchored_rmse"] < 1e-9
    moved[2, 0, 3] += 0.1
    assert evaluation.trajectory_errors(moved, reference)["start_anchored_rmse"] == \
        pytest.approx(0.1 / np.sqrt(5))


def test_range_and_heading_errors_see_a_known_bias(office_recording):
    recording = Recording.open(office_recording)
    scan, _, _ = next(recording_scans(recording))
    scan_truth = ScanTruth.load(truth_path(office_recording, 0))
    error, total = evaluation.range_errors(scan, scan_truth, recording.model)
    assert error.size > 0.6 * total and np.median(np.abs(error)) < 0.005
    radial = scan.points[:, :2] / np.hypot(*scan.points[:, :2].T)[:, None]
    farther = dataclasses.replace(scan, points=scan.points + np.column_stack(
        [0.02 * radial, np.zeros(len(scan))]).astype(np.float32))
    biased, _ = evaluation.range_errors(farther, scan_truth, recording.model)
    assert np.median(biased) == pytest.approx(np.median(error) + 0.02, abs=0.002)
    headings = evaluation.heading_errors(scan, scan_truth)
    assert np.abs(headings).max() < np.radians(0.5)
    turned = dataclasses.replace(scan, heading=scan.heading + 0.01)
    assert np.median(evaluation.heading_errors(turned, scan_truth)) == \
        pytest.approx(np.median(headings) + 0.01, abs=1e-9)


def test_gross_ranges_count_points_off_every_lit_point_of_their_column(office_recording):
    """Points moved 10 cm farther are gross, the extracted ones few; a column lit twice
    (the stripe across a depth edge) holds a point on its weaker stripe that is not."""
    recording = Recording.open(office_recording)
    scan, _, _ = next(recording_scans(recording))
    truth = ScanTruth.load(truth_path(office_recording, 0))
    assert evaluation.gross_ranges(scan, truth, recording.model) <= 1e-3 * len(scan)
    radial = scan.points[:, :2] / np.hypot(*scan.points[:, :2].T)[:, None]
    farther = dataclasses.replace(scan, points=scan.points + np.column_stack(
        [0.1 * radial, np.zeros(len(scan))]).astype(np.float32))
    matched = evaluation.range_errors(scan, truth, recording.model)[0].size
    # measured 0.85: a point moved lands in another column, one lit nearer or not at all
    assert evaluation.gross_ranges(farther, truth, recording.model) > 0.75 * matched
    # The strongest point of every column 10 cm nearer than its stripe, as another lit
    # point of the column: the scan's points are then off the strongest, not off the other
    laser = dict(truth.laser)
    primary = laser["primary"].astype(bool)
    base = laser["base"][primary]
    nearer = base.copy()
    nearer[:, :2] *= (1.0 - 0.1 / np.hypot(base[:, 0], base[:, 1]))[:, None]
    twice = dataclasses.replace(truth, laser={
        k: np.concatenate([v, v[primary]]) for k, v in laser.items()}
        | {"base": np.concatenate([laser["base"], nearer])})
    twice.laser["base"][np.flatnonzero(primary)] = nearer  # the strongest moved nearer
    twice.laser["base"][len(primary):] = base  # the other: where the stripe is
    assert evaluation.range_errors(scan, twice, recording.model)[0].size == matched
    assert np.median(np.abs(evaluation.range_errors(scan, twice, recording.model)[0])) > 0.09
    assert evaluation.gross_ranges(scan, twice, recording.model) <= 1e-3 * len(scan)


def test_range_errors_do_not_depend_on_the_order_of_points_or_truth(office_recording):
    """The points come frame by frame and the truth column by column, which the errors
    use when they can; shuffled, both give the same errors (as a set) and count."""
    recording = Recording.open(office_recording)
    scan, _, _ = next(recording_scans(recording))
    scan_truth = ScanTruth.load(truth_path(office_recording, 0))
    error, total = evaluation.range_errors(scan, scan_truth, recording.model)
    rng = np.random.default_rng(5)
    rows = rng.permutation(len(scan))
    shuffled = dataclasses.replace(scan, **{name: getattr(scan, name)[rows] for name in (
        "points", "colors", "time", "heading", "frame_index", "range_sigma")})
    order = rng.permutation(len(scan_truth.laser["frame"]))
    truth_shuffled = dataclasses.replace(
        scan_truth, laser={k: v[order] for k, v in scan_truth.laser.items()})
    again, total_again = evaluation.range_errors(shuffled, truth_shuffled, recording.model)
    assert total_again == total and error.size > 0.6 * total
    np.testing.assert_array_equal(np.sort(again), np.sort(error))


def test_ramps_scored_by_floor_f1_over_the_cells_holding_hits(hazards_raster, office_raster):
    """`hazards` holds a ramp within max_slope (floor) and one too steep (not floor): a
    perfect map scores 1, floor and traversable; a step's edge marked on the ramp (floor,
    but OBSTACLE) costs only the traversable F1; calling the steep ramp's cells floor
    costs them as false claims, in closed form; cells without a hit are not scored; a
    scene without ramps, nothing."""
    seg = segmentation_of(hazards_raster)
    sloped = hazards_raster.slope > 0.0
    gentle = sloped & (hazards_raster.classes == truth.FLOOR)
    steep = sloped & (hazards_raster.slope > hazards_raster.max_slope)
    assert gentle.sum() > 50 and steep.sum() > 50
    everywhere = np.ones(seg.shape, bool)
    perfect = evaluation.map_errors(seg, hazards_raster, np.eye(4), hits=everywhere)
    assert perfect["ramp_f1"] == perfect["ramp_traversable_f1"] == 1.0
    assert perfect["ramp_cells"] == sloped.sum()
    edge = np.zeros(seg.shape, bool)
    edge[np.nonzero(gentle)[0][:10], np.nonzero(gentle)[1][:10]] = True
    state = np.where(edge, OBSTACLE, seg.state).astype(np.uint8)  # floor, a step's edge
    errors = evaluation.map_errors(dataclasses.replace(seg, state=state), hazards_raster,
                                   np.eye(4), hits=everywhere)
    assert errors["ramp_f1"] == 1.0
    kept = gentle.sum() - 10
    assert errors["ramp_traversable_f1"] == pytest.approx(2 * kept / (kept + gentle.sum()))
    claimed = dataclasses.replace(seg, is_floor=seg.is_floor | steep)
    errors = evaluation.map_errors(claimed, hazards_raster, np.eye(4), hits=everywhere)
    assert errors["ramp_f1"] == pytest.approx(2 * gentle.sum() / (2 * gentle.sum() + steep.sum()))
    unseen = evaluation.map_errors(claimed, hazards_raster, np.eye(4), hits=~steep)
    assert unseen["ramp_f1"] == 1.0 and unseen["ramp_cells"] == (sloped & ~steep).sum()
    assert "ramp_f1" not in evaluation.map_errors(segmentation_of(office_raster),
                                                  office_raster, np.eye(4))


def ramp_scene(height: float, gradient: float) -> Scene:
    """The hazards room without its hazards and one floor region 0.5 m square from x = 1.12
    m (inside a 5 cm cell) and y = -0.25: `height` at its centre, rising `gradient` along x."""
    data = builtin_scene("hazards").to_dict()
    data["floor_regions"] = [{"center": [1.37, 0.0], "size": [0.5, 0.5], "height": height,
                              "gradient": [gradient, 0.0], "name": "region"}]
    return Scene.from_dict(data)


@pytest.mark.parametrize("height, gradient, faces", [
    (0.10, 0.0, True), (0.03, 0.0, False),
    (0.25 * np.tan(0.26) + 2e-4, np.tan(0.26), True),
    (0.25 * np.tan(0.052) + 2e-4, np.tan(0.052), False)])
def test_a_face_higher_than_a_step_is_found_in_the_cells_it_crosses(height, gradient, faces):
    """A platform 10 cm high has faces in the cells its sides cross, one 3 cm high none; a
    15 deg ramp rising from the floor has them at its high end, 13 cm up, and where its
    sides stand higher than a step, never inside (its slope alone spans 1.9 cm across a
    cell); a 3 deg one, 2.6 cm at its high end, has none."""
    scene = ramp_scene(height, gradient)
    seg = segmentation_of(truth_raster(scene), origin=(0.0, -1.0))
    ny, nx = seg.shape
    every = np.ones((ny, nx), bool)
    found = evaluation.face_cells(scene, seg, np.eye(4), every, 0.05)
    rows, cols = np.nonzero(found)
    if not faces:
        assert not found.any()
        return
    x = seg.origin[0] + (cols + 0.5) * seg.resolution
    y = seg.origin[1] + (rows + 0.5) * seg.resolution
    # every found cell holds or bounds the region's outline (x 1.12 to 1.62, y -0.25 to
    # 0.25): its centre within a cell of it, inside or out
    def within(margin: float) -> np.ndarray:
        return (np.abs(x - 1.37) < 0.25 + margin) & (np.abs(y) < 0.25 + margin)
    assert (within(0.05) & ~within(-0.05)).all()
    high_end = (np.abs(x - 1.62) < 0.05) & (np.abs(y) < 0.2)
    assert high_end.sum() >= 8  # the 0.5 m high end's cells, along all of it


@pytest.mark.parametrize("shift", [0.0, 0.0015, -0.0015])
def test_a_face_on_a_cells_edge_is_found_in_both_cells_it_runs_between(shift):
    """A platform's side on (or within 2 mm of) the edge between two rows of cells: its
    hits fall either side, so both rows hold it. The region's outline holds its own
    edge, and the edge's samples had found it in the row outside alone."""
    scene = ramp_scene(0.10, 0.0).moved(0.0, shift, 0.0)  # sides at y = +-0.25 + shift
    seg = segmentation_of(truth_raster(scene), origin=(0.0, -1.0))
    found = evaluation.face_cells(scene, seg, np.eye(4), np.ones(seg.shape, bool), 0.05)
    x = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution
    along = (x > 1.17) & (x < 1.57)  # the side's cells, clear of its ends
    for y_centre in (0.225, 0.275, -0.225, -0.275):
        row = round((y_centre - seg.origin[1]) / seg.resolution - 0.5)
        assert found[row, along].all()
    inner = round((0.175 - seg.origin[1]) / seg.resolution - 0.5)
    assert not found[inner, along].any()  # a cell away from the side holds none


def test_a_map_that_saw_none_of_the_ramps_cells_scores_no_ramp():
    """A recording that stopped before the robot saw the scene's ramp (the `scanmap map`
    report of a short one raised in `face_cells`, after the map files were written):
    no ramp cell is scored, and its F1s are NaN."""
    scene = builtin_scene("hazards")
    hazards_raster = truth_raster(scene)
    seg = segmentation_of(hazards_raster)
    unseen = np.zeros(seg.shape, bool)
    assert not evaluation.face_cells(scene, seg, np.eye(4), unseen, 0.05).any()
    errors = evaluation.map_errors(seg, hazards_raster, np.eye(4), scene, unseen)
    assert errors["ramp_cells"] == 0 and math.isnan(errors["ramp_traversable_f1"])


def test_the_traversable_ramp_f1_leaves_out_the_cells_a_face_crosses():
    """`hazards`' ramp up to its 10 cm platform stands higher than a step at its sides'
    upper part; shifted off the cells' boundaries, its sides cross cells. Those cells
    blocked (a step's edge, OBSTACLE) cost the traversable F1 on the raster alone, and
    nothing with the scene at hand."""
    scene = builtin_scene("hazards").moved(0.02, 0.013, 0.0)
    hazards_raster = truth_raster(scene)
    seg = segmentation_of(hazards_raster)
    gentle = (hazards_raster.slope > 0.0) & (hazards_raster.classes == truth.FLOOR)
    faces = evaluation.face_cells(scene, seg, np.eye(4), gentle, hazards_raster.band[0])
    assert faces.sum() >= 5
    blocked = dataclasses.replace(seg, state=np.where(faces, OBSTACLE, seg.state).astype(
        np.uint8))
    everywhere = np.ones(seg.shape, bool)
    alone = evaluation.map_errors(blocked, hazards_raster, np.eye(4), hits=everywhere)
    with_scene = evaluation.map_errors(blocked, hazards_raster, np.eye(4), scene, everywhere)
    assert alone["ramp_traversable_f1"] < 1.0 == with_scene["ramp_traversable_f1"]
    assert with_scene["ramp_face_cells"] >= faces.sum()
