"""Floor segmentation: RANSAC planes, region growing, ramps and steps, precision/recall."""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import CellLayers, GridConfig, HeightGrid
from scanmap.navigation.floor import (
    FREE,
    OBSTACLE,
    FloorConfig,
    RobotShape,
    _drop_offs,
    _model,
    _states,
    ransac_plane,
    segment,
    segmentation,
)
from scanmap.navigation.floor._growth_kernels import (
    _JUMPS,
    _LONG_COUNTS,
    _LONG_CROSSED,
    _LONG_JUMPS,
    _crossed_cells,
    rim_cells,
    rim_cells_reference,
    step_edges,
    step_edges_reference,
    touching_floor,
    touching_floor_reference,
)
from scanmap.navigation.floor._plane_kernels import (
    _most_supported,
    best_plane,
    faces_below,
    floor_candidates,
    level_hypotheses,
    plane_moments,
    plane_support_reference,
)
from scanmap.navigation.floor._seen_kernels import below_floor, ring_heights, ring_heights_reference
from scanmap_driver.errors import MapError

from . import scenes as S
from .growth import grow_region


def test_ransac_recovers_a_tilted_plane_among_outliers():
    rng = np.random.default_rng(0)
    slope = math.radians(6.0)
    xy = rng.uniform(-3, 3, (3000, 2))
    z = 0.2 + math.tan(slope) * xy[:, 0] + rng.normal(0, 0.005, 3000)
    outliers = np.column_stack([rng.uniform(-3, 3, (1000, 2)), rng.uniform(0.1, 1.0, 1000)])
    found = ransac_plane(np.vstack([np.column_stack([xy, z]), outliers]), FloorConfig(),
                         np.random.default_rng(1))
    assert found is not None
    normal, offset, inliers = found
    assert math.degrees(math.acos(normal[2])) == pytest.approx(6.0, abs=0.3)
    assert offset / normal[2] == pytest.approx(0.2, abs=0.005)
    assert inliers[:3000].mean() > 0.99 and inliers[3000:].mean() < 0.15


@pytest.mark.parametrize("seed", range(4))
def test_ransac_takes_the_larger_floor_not_a_plane_tilted_through_it_and_a_lower_one(seed):
    # A floor 3 m deep beside a dock 6.1 cm lower (terrain room 2034): a plane half way
    # down, tilted a little, passes within plane_tolerance (3 cm) of both and holds more
    # cells than the floor alone, and the dock's cells were the floor's seeds (379 of them
    # FREE). The plane that fits its points best is the floor's: hypotheses are scored
    # within the floor's own noise (`seed_tolerance`)
    rng = np.random.default_rng(seed)
    cells = np.arange(0.025, 4.0, 0.05)
    floor_xy = np.array([(x, y) for x in cells for y in cells[cells < 3.0]])
    dock_xy = np.array([(x, -1.0 - y) for x in cells for y in cells[cells < 1.5]])
    points = np.vstack([np.column_stack([floor_xy, rng.normal(0.0, 0.003, len(floor_xy))]),
                        np.column_stack([dock_xy, rng.normal(-0.061, 0.003, len(dock_xy))])])
    tolerance = FloorConfig().plane_tolerance
    held = max(int((np.abs(points[:, 2] - base - rise * points[:, 1]) <= tolerance).sum())
               for base in np.linspace(-0.06, 0.0, 61) for rise in np.linspace(0.0, 0.03, 31))
    assert held > len(floor_xy)  # z = base + rise * y through both holds more than the floor
    normal, offset, inliers = ransac_plane(points, FloorConfig(), np.random.default_rng(seed))
    assert normal[2] > math.cos(math.radians(0.2)) and abs(offset) < 0.002
    assert inliers[:len(floor_xy)].all() and not inliers[len(floor_xy):].any()


def test_ransac_refuses_a_steep_plane():
    rng = np.random.default_rng(2)
    xy = rng.uniform(-1, 1, (500, 2))
    wall = np.column_stack([xy[:, 0], np.zeros(500), xy[:, 1] + 1])
    assert ransac_plane(wall, FloorConfig(), rng) is None


def test_plane_moments_match_numpy_on_the_points_near_the_plane():
    """Count, mean and centred scatter of the points within the tolerance of a plane, as
    numpy's mask, mean and product give them; NaN and inf points are never counted."""
    rng = np.random.default_rng(8)
    points = np.column_stack([rng.uniform(-3.0, 3.0, (900, 2)), rng.normal(0.0, 0.05, 900)])
    points[:5] = [np.nan, 0.0, 0.0]
    points[5:8] = [0.0, np.inf, 0.0]
    normal = np.array([0.004, -0.002, 1.0]) / np.linalg.norm([0.004, -0.002, 1.0])
    for tolerance in (0.03, np.inf):
        count, centre, scatter = plane_moments(np.ascontiguousarray(points.T), normal, 0.01,
                                               tolerance)
        near = points[(np.abs(points @ normal - 0.01) <= tolerance) & np.isfinite(points).all(1)]
        assert count == len(near) > 300 and np.isfinite(near).all()
        np.testing.assert_allclose(centre, near.mean(axis=0), rtol=0, atol=1e-12)
        d = near - near.mean(axis=0)
        np.testing.assert_allclose(scatter, d.T @ d, rtol=1e-10, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_level_hypotheses_are_numpys_cross_products(seed):
    """The compiled hypotheses equal numpy's cross, norm and flip, bit for bit, with
    repeated and collinear triples (no plane) and steep planes dropped alike."""
    rng = np.random.default_rng(seed)
    points = rng.normal(0.0, 1.0, (12, 3)) * [2.0, 2.0, rng.uniform(0.001, 3.0)]
    points[1] = points[0]  # a repeated point: every triple holding both spans nothing
    points[2] = 2.0 * points[3] - points[4]  # 2, 3, 4 on one line
    triples = rng.integers(0, len(points), (200, 3))
    triples[:3] = [[0, 1, 5], [2, 3, 4], [6, 6, 6]]
    min_nz = math.cos(math.radians(15.0))
    normals, anchors = level_hypotheses(points, triples, min_nz)
    sample = points[triples]
    want = np.cross(sample[:, 1] - sample[:, 0], sample[:, 2] - sample[:, 0])
    norms = np.linalg.norm(want, axis=1)
    ok = norms > 1e-9
    want = want[ok] / norms[ok, None]
    want *= np.where(want[:, 2] < 0, -1.0, 1.0)[:, None]
    level = want[:, 2] >= min_nz
    assert np.array_equal(normals, want[level])
    assert np.array_equal(anchors, sample[ok][level, 0])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.sampled_from([1, 255, 256, 257, 1300]),
       floor_share=st.floats(0.0, 1.0), copies=st.integers(1, 3))
def test_the_most_supported_hypothesis_is_the_first_argmax_of_the_support(seed, n, floor_share,
                                                                          copies):
    """`_most_supported` (hypotheses left early) picks what argmax over the plain support
    picks, the first of equals: hypotheses repeated (ties), the floor from none of the
    points to all, and point counts round the block size."""
    rng = np.random.default_rng(seed)
    points = np.column_stack([rng.uniform(-3.0, 3.0, (n, 2)), rng.normal(0.0, 0.005, n)])
    off = rng.random(n) >= floor_share
    points[off, 2] += rng.uniform(0.1, 1.0, int(off.sum()))
    normals = np.tile(rng.normal([0.0, 0.0, 5.0], 1.0, (30, 3)), (copies, 1))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    anchors = np.tile(points[rng.integers(0, n, 30)], (copies, 1))
    support = plane_support_reference(points, anchors, normals, 0.02)
    chosen = _most_supported(np.ascontiguousarray(points.T), anchors, normals, 0.02)
    assert chosen == int(np.argmax(support))


@pytest.mark.parametrize(("better_at", "confidence", "chosen"), [
    (100, 1.0, 100), (20, 1.0 - 1e-9, 20), (30, 1.0 - 1e-9, 0), (30, 1.0 - 1e-12, 30),
    (100, 1.0 - 1e-12, 0)])
def test_ransac_stops_drawing_once_the_best_plane_was_surely_drawn(better_at, confidence,
                                                                  chosen):
    """Hypothesis 0 holds 80 % of the points, a later one all: at a confidence of 1 - 1e-9
    one triple of the 80 % would have been drawn within 29 draws (1 - 0.8 ** 3 per
    draw), so the later one counts only within them; at 1 - 1e-12, within 38."""
    points = np.zeros((3, 1000))
    points[0], points[1] = np.random.default_rng(2).uniform(-3.0, 3.0, (2, 1000))
    points[2, 800:] = 0.015
    normals = np.tile([0.0, 0.0, 1.0], (200, 1))
    anchors = np.zeros((200, 3))
    anchors[:, 2] = 0.5  # no points on them
    anchors[0, 2], anchors[better_at, 2] = -0.005, 0.0075  # 800 points, and all 1000
    assert _most_supported(points, anchors, normals, 0.01, confidence) == chosen


def test_small_holes_take_patches_inside_level_floor_only():
    """A 2 x 2 patch inside level floor is a hole; the same beside a step, touching the
    window's edge, larger than the size, holding a hit or a drop-off is not."""
    floor = np.ones((12, 40), bool)
    for x0 in (2, 10, 18, 26, 34):
        floor[4:6, x0:x0 + 2] = False
    floor[0:2, 0:2] = False  # at the edge
    floor[8:11, 2:5] = False  # 3 x 3
    heights = np.where(floor, 0.0, np.nan).astype(np.float32)
    heights[:, 12:14] = 0.08  # a step beside the second patch
    nlev = np.zeros(floor.shape, np.uint8)
    nlev[4, 18] = 1  # a hit in the third
    drop = np.zeros(floor.shape, bool)
    drop[5, 27] = True  # a drop-off in the fourth
    heights = np.where(floor, heights, np.nan).astype(np.float32)
    holes = _drop_offs._small_holes(nlev, floor, heights, drop, 2, 0.05)
    expected = np.zeros(floor.shape, bool)
    expected[4:6, 2:4] = expected[4:6, 34:36] = True
    assert (holes == expected).all()
    low, high = ring_heights(*ndimage.label(~floor, np.ones((3, 3), bool)), floor, heights)
    ref = ring_heights_reference(*ndimage.label(~floor, np.ones((3, 3), bool)), floor,
                                 heights)
    assert np.array_equal(low, ref[0]) and np.array_equal(high, ref[1])


def test_floor_candidates_match_a_numpy_reference():
    rng = np.random.default_rng(3)
    levels = np.zeros((20, 30, 3, gk.N_FLOAT_FIELDS), np.float32)
    lo = rng.uniform(-0.05, 0.5, (20, 30, 3)).astype(np.float32)
    levels[..., gk.LO] = np.sort(lo, axis=2)
    levels[..., gk.HI] = levels[..., gk.LO] + rng.uniform(0, 0.12, (20, 30, 3))
    nlev = rng.integers(0, 4, (20, 30)).astype(np.uint8)
    got = floor_candidates(levels, nlev, 0.06, 0.2)
    first, second = levels[:, :, 0], levels[:, :, 1]
    thin = first[..., gk.HI] - first[..., gk.LO] <= 0.06
    clear = (nlev == 1) | (second[..., gk.LO] - first[..., gk.HI] >= 0.2)
    ok = (nlev > 0) & thin & clear
    expected = np.where(ok, 0.5 * (first[..., gk.LO] + first[..., gk.HI]), np.nan)
    np.testing.assert_allclose(got, expected, equal_nan=True, rtol=1e-6)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 15), st.integers(1, 15))
def test_touching_floor_matches_a_numpy_reference(seed, ny, nx):
    rng = np.random.default_rng(seed)
    heights = rng.normal(0.0, 0.05, (ny, nx)).astype(np.float32)
    heights[rng.random((ny, nx)) < 0.2] = np.nan
    floor, cells = rng.random((ny, nx)) < 0.5, rng.random((ny, nx)) < 0.5
    got = touching_floor(heights, floor, cells, 0.05)
    assert np.array_equal(got, touching_floor_reference(heights, floor, cells, 0.05))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 15), st.integers(1, 15), st.integers(1, 3))
def test_step_edges_match_a_numpy_reference(seed, ny, nx, depth):
    rng = np.random.default_rng(seed)
    levels = np.zeros((ny, nx, depth, gk.N_FLOAT_FIELDS), np.float32)
    low = rng.choice([0.0, 0.1], (ny, nx)) + rng.normal(0.0, 0.02, (ny, nx))
    levels[..., 0, gk.LO] = low
    levels[..., 0, gk.HI] = low + rng.uniform(0.0, 0.15, (ny, nx))
    for k in range(1, depth):  # each some way above the last, less than clearance or more
        levels[..., k, gk.LO] = levels[..., k - 1, gk.HI] + rng.uniform(0.0, 0.4, (ny, nx))
        levels[..., k, gk.HI] = levels[..., k, gk.LO] + rng.uniform(0.0, 0.15, (ny, nx))
    nlev = rng.integers(0, depth + 1, (ny, nx)).astype(np.uint8)
    heights = rng.choice([0.0, 0.1], (ny, nx)) + rng.normal(0.0, 0.02, (ny, nx))
    heights[rng.random((ny, nx)) < 0.2] = np.nan
    heights = heights.astype(np.float32)
    floor = (rng.random((ny, nx)) < 0.5) & ~np.isnan(heights)
    args = (levels, nlev, heights, floor, 0.05, 0.2, 0.03)
    assert np.array_equal(step_edges(*args), step_edges_reference(*args))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 15), st.integers(1, 15), st.integers(1, 3))
def test_rim_cells_match_a_numpy_reference(seed, ny, nx, depth):
    rng = np.random.default_rng(seed)
    levels = np.zeros((ny, nx, depth, gk.N_FLOAT_FIELDS), np.float32)
    levels[..., 0, gk.LO] = rng.normal(-0.03, 0.03, (ny, nx))
    levels[..., 0, gk.HI] = levels[..., 0, gk.LO] + rng.uniform(0.0, 0.08, (ny, nx))
    share = rng.choice([0.5, 0.75, 0.9], (ny, nx))  # the mean hit's place, on the quarter too
    levels[..., 0, gk.MZ] = levels[..., 0, gk.LO] + share * (levels[..., 0, gk.HI]
                                                             - levels[..., 0, gk.LO])
    nlev = rng.integers(0, depth + 1, (ny, nx)).astype(np.uint8)
    heights = rng.choice([-0.06, 0.0], (ny, nx)) + rng.normal(0.0, 0.01, (ny, nx))
    heights[rng.random((ny, nx)) < 0.2] = np.nan
    heights = heights.astype(np.float32)
    floor = (rng.random((ny, nx)) < 0.6) & ~np.isnan(heights)
    edges = rng.random((ny, nx)) < 0.6
    args = (levels, nlev, edges, floor, heights, 0.05)
    got, want = rim_cells(*args), rim_cells_reference(*args)
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)
    assert got[2].dtype == np.float32


@pytest.mark.parametrize(("bottom", "floor_below", "edge"), [
    (0.0, True, True),     # the whole face, from the floor below to the ramp's top
    (0.1, True, True),     # only its upper part seen (the rays saw no more of it)
    (-0.05, True, False),  # reaching below the floor below: not a face between the two
    (0.1, False, False),   # no floor below within two cells: not a step between floors
])
def test_a_step_edge_holds_a_face_or_its_upper_part_between_two_floors(bottom, floor_below,
                                                                       edge):
    # A row: the ramp's raised end at 0.18 m (floor), a cell holding its face, then the
    # floor below (0 m) or more of the ramp
    levels = np.zeros((1, 5, 1, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, 2, 0, gk.LO], levels[0, 2, 0, gk.HI] = bottom, 0.18
    nlev = np.array([[1, 1, 1, 1, 1]], np.uint8)
    heights = np.array([[0.18, 0.18, np.nan, 0.0, 0.0]], np.float32)
    if not floor_below:
        heights[0, 3:] = 0.18
    is_floor = ~np.isnan(heights)
    args = (levels, nlev, heights, is_floor, 0.05, 0.2, 0.03)
    assert step_edges(*args)[0, 2] == edge
    assert np.array_equal(step_edges(*args), step_edges_reference(*args))


@pytest.mark.parametrize(("mean", "beyond", "rim"), [
    (0.079, "face", True),    # mostly the ramp's top, the face's hits beyond the rim
    (0.040, "face", False),   # the face's own cell: its hits from its foot up
    (0.079, "floor", False),  # the face inside the cell: the floor below lies beside it
])
def test_a_step_edge_whose_hits_lie_on_its_top_beside_the_face_is_the_floor_above(
        mean, beyond, rim):
    # A row: a ramp's top 9 cm up (floor), a cell on its raised end's edge whose level
    # reaches down to 1.6 cm (a face 1 mm past the cell's edge scatters some of its hits
    # into it at the laser's noise: mixed room 2017), then the face's cell (its hits from
    # the floor below up) or the floor below itself, then the floor below
    levels = np.zeros((1, 5, 1, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, 2, 0, [gk.LO, gk.HI, gk.MZ]] = 0.016, 0.098, mean
    levels[0, 3, 0, [gk.LO, gk.HI, gk.MZ]] = -0.001, 0.099, 0.04
    heights = np.array([[0.09, 0.09, np.nan, np.nan, 0.0]], np.float32)
    if beyond == "floor":
        levels[0, 3, 0, [gk.LO, gk.HI, gk.MZ]] = -0.001, 0.002, 0.0
        heights[0, 3] = 0.0
    nlev = np.ones((1, 5), np.uint8)
    is_floor = ~np.isnan(heights)
    edges = step_edges(levels, nlev, heights, is_floor, 0.05, 0.2, 0.03)
    assert edges[0, 2] and edges[0, 3] == (beyond == "face")
    rows, cols, tops = _model._rims(levels, nlev, edges, is_floor, heights, 0.05)
    assert list(zip(rows, cols, strict=True)) == ([(0, 2)] if rim else [])
    assert tops == pytest.approx([0.098] if rim else [])


@pytest.mark.parametrize(("clearance", "edge"), [(0.2, True), (0.05, False)])
def test_a_step_edge_may_hold_its_face_and_top_as_two_levels(clearance, edge):
    # A cell straddling a ramp's side 18 cm up (fresh ramp room 608): the rays saw the
    # side face at 0-8 cm and the ramp's surface at 17-18 cm, nothing between; no robot
    # fits in the 9 cm between (clearance), so the two are one solid from the floor to the
    # ramp's top. With room between, the lower level alone is no edge
    levels = np.zeros((1, 5, 2, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, 2, 0, gk.LO], levels[0, 2, 0, gk.HI] = 0.0, 0.08
    levels[0, 2, 1, gk.LO], levels[0, 2, 1, gk.HI] = 0.17, 0.18
    nlev = np.array([[1, 1, 2, 1, 1]], np.uint8)
    heights = np.array([[0.18, 0.18, np.nan, 0.0, 0.0]], np.float32)
    args = (levels, nlev, heights, ~np.isnan(heights), 0.05, clearance, 0.03)
    assert step_edges(*args)[0, 2] == edge
    assert np.array_equal(step_edges(*args), step_edges_reference(*args))


@pytest.mark.parametrize(("lo", "hi", "beside", "face"), [
    (-0.055, 0.001, 0.0, True),    # the top of a 7.7 cm step's face, under the floor's edge
    (0.0, 0.055, 0.0, False),      # as tall, standing on the floor: a person's feet left
    (-0.04, 0.0, 0.0, False),      # a 4 cm step's face: the robot climbs it
    (-0.055, 0.001, -0.077, False),  # no floor beside it more than a step above its bottom
])
def test_a_face_down_a_step_crosses_a_cell_whose_level_reaches_from_the_floor_beside_it(
        lo, hi, beside, face):
    # A row: floor at `beside`, the cell, the floor 7.7 cm down
    levels = np.zeros((1, 5, 1, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, :, 0, gk.LO] = levels[0, :, 0, gk.HI] = [beside, beside, 0.0, -0.077, -0.077]
    levels[0, 2, 0, gk.LO], levels[0, 2, 0, gk.HI] = lo, hi
    nlev = np.ones((1, 5), np.uint8)
    candidates = floor_candidates(levels, nlev, 0.06, 0.2)
    got = faces_below(levels, candidates, 0.05)
    assert got.tolist() == [[False, False, face, False, False]]


@pytest.mark.parametrize(("lo", "hi", "mean", "below"), [
    (-0.070, -0.055, -0.062, True),    # wholly more than a step down
    (-0.061, -0.048, -0.055, True),    # a floor 5.5 cm down, its highest hits noisy
    (-0.052, -0.040, -0.046, False),   # a floor 4.6 cm down: the robot steps down to it
    (-0.058, -0.0016, -0.0487, False),  # a face: too tall a level for its mean to tell
    (-0.052, -0.045, -0.060, False),   # a mean outside the level's heights (trimmed)
])
def test_a_thin_level_whose_mean_hit_lies_more_than_a_step_down_is_below_the_floor(
        lo, hi, mean, below):
    # Floor at 0 beside it; no ray passed under the floor
    levels = np.zeros((1, 2, 1, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, 1, 0, [gk.LO, gk.HI, gk.MZ]] = lo, hi, mean
    nlev = np.ones((1, 2), np.uint8)
    floor_height = np.zeros((1, 2), np.float32)
    got = below_floor(levels, nlev, np.zeros((1, 2), np.uint64), floor_height, 0.05,
                      -1.0, 0.025, 0.037)
    assert got.tolist() == [[False, below]]


def seen_bins(*heights: tuple[float, float]) -> np.uint64:
    """The observed-height mask (bins of 2.5 cm from -0.35 m) over the spans of heights."""
    mask = np.uint64(0)
    for lo, hi in heights:
        mask |= gk.height_mask(lo, hi, -0.35, 0.025)
    return mask


@pytest.mark.parametrize(("level", "seen", "below"), [
    # floor hits and one noisy hit 16 cm down, seen there and from the floor up only: the
    # hit of a far wall's ray displaced past the wall (0.3 px at 4-6 m)
    ((-0.16, 0.005), seen_bins((-0.16, -0.155), (-0.01, 0.9)), False),
    # a far wall's top in the cell, seen from its lowest hit up to the floor
    ((-0.16, 0.005), seen_bins((-0.16, 0.9)), True),
    # no hit near the floor: rays passed 16 cm down
    ((0.3, 0.35), seen_bins((-0.16, -0.155), (0.1, 0.9)), True),
])
def test_rays_below_the_floor_make_a_drop_off_unless_a_noisy_hit_below_floor_hits(
        level, seen, below):
    levels = np.zeros((1, 1, 1, gk.N_FLOAT_FIELDS), np.float32)
    levels[0, 0, 0, [gk.LO, gk.HI, gk.MZ]] = *level, level[1] - 0.01
    got = below_floor(levels, np.ones((1, 1), np.uint8), np.array([[seen]], np.uint64),
                      np.zeros((1, 1), np.float32), 0.05, -0.35, 0.025, 0.037)
    assert got.tolist() == [[below]]


def spans_no_step(heights: np.ndarray, start: tuple[int, int], end: tuple[int, int]) -> bool:
    """No cell next to `start` (in the grid) lies within 5 cm of it and more than 5 cm from
    `end`."""
    y, x = start
    near = heights[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]
    with np.errstate(invalid="ignore"):
        return not ((np.abs(near - heights[start]) <= 0.05)
                    & (np.abs(near - heights[end]) > 0.05)).any()


def test_grow_region_matches_a_breadth_first_reference():
    rng = np.random.default_rng(4)
    heights = np.cumsum(rng.normal(0, 0.03, (25, 25)), axis=1).astype(np.float32)
    heights[rng.random((25, 25)) < 0.2] = np.nan
    empty = np.isnan(heights) & (rng.random((25, 25)) < 0.5)  # some have hits, not floor
    seeds = np.zeros((25, 25), bool)
    seeds[12, 12] = seeds[3, 20] = True
    got = grow_region(heights, seeds, 0.05, empty, 0.02, heights)
    inside = seeds.copy()
    queue = deque(zip(*np.nonzero(seeds), strict=True))
    while queue:
        y, x = queue.popleft()
        for yy, xx in np.ndindex(25, 25):
            dy, dx = yy - y, xx - x
            if max(abs(dy), abs(dx)) > 2 or inside[yy, xx] \
                    or not abs(heights[yy, xx] - heights[y, x]) <= 0.05:
                continue
            between = {(y + round(t * dy), x + round(t * dx)) for t in (0.4, 0.6)}
            if not spans_no_step(heights, (y, x), (yy, xx)):
                continue  # a step, a neighbour's or a jump's
            if max(abs(dy), abs(dx)) == 2 and not (
                    all(empty[c] for c in between)
                    and abs(heights[yy, xx] - heights[y, x]) <= 0.02 * math.hypot(dy, dx)
                    and spans_no_step(heights, (yy, xx), (y, x))):
                continue
            inside[yy, xx] = True
            queue.append((yy, xx))
    np.testing.assert_array_equal(got, inside)


def test_the_floor_grows_across_a_cell_without_hits_but_not_over_a_step():
    # Floor at 0 left of column 5, column 5 without any hit, a surface right of it at
    # `right`: joined when it rises as a floor may (max_rise per cell), not when steeper
    # though within a step (a step's face: 0, -4, -8 cm down a chain of jumps), and never
    # across a cell that holds hits (a step's face, removed from the candidates)
    for right, hits, joined in ((0.025, False, True), (0.045, False, False), (0.0, True, False)):
        heights = np.zeros((7, 11), np.float32)
        heights[:, 5] = np.nan
        heights[:, 6:] = right
        seeds = np.zeros((7, 11), bool)
        seeds[3, 0] = True
        empty = np.zeros((7, 11), bool)
        empty[:, 5] = not hits
        got = grow_region(heights, seeds, 0.05, empty, 0.0134, heights)  # tan 15 deg x 5 cm
        assert got[:, :5].all() and not got[:, 5].any()
        assert got[:, 6:].all() == joined and got[:, 6:].any() == joined


def test_the_floor_does_not_jump_from_a_step_face_down_to_the_floor_below():
    # A mixed room's (seed 303) 6 cm step down: the face left a level 3 cm down in a cell
    # beside the floor, within a step of it (the growth took it) and within max_rise of
    # the floor below across a gap between the laser's lines (-5.5 cm here): the jump
    # carried the floor onto the whole step-down area, FREE at two scans. A gap on a ramp
    # (each cell 1 cm above the last) is still crossed
    face = np.zeros((7, 11), np.float32)
    face[:, 5], face[:, 7:] = -0.03, -0.055
    ramp = np.tile(0.01 * np.arange(11, dtype=np.float32), (7, 1))  # 11 deg
    for heights, joined in ((face, False), (ramp, True)):
        heights[:, 6] = np.nan
        seeds = np.zeros((7, 11), bool)
        seeds[3, 0] = True
        got = grow_region(heights, seeds, 0.05, np.isnan(heights), 0.0134, heights)
        assert got[:, :6].all() and not got[:, 6].any()
        assert got[:, 7:].any() == joined



def test_a_jump_sees_the_steep_cells_beside_its_end():
    # A 5.5 cm step down: the cells of the floor at its edge fitted steep (their planes
    # reach the face) and left out of the growth, the face left a level 2.8 cm down, a
    # RANSAC inlier of the floor's plane and so a seed, and a gap between the laser's lines
    # lay between it and the floor below (2.6 cm lower: within max_rise over two cells).
    # Read from the growth's heights alone, the face's end showed no step beside it and
    # the jump carried the floor onto the whole step-down area (of 60 rooms each with one
    # turned step down 5.5-9 cm deep: 144 cells FREE in one, 7 in another)
    candidates = np.zeros((7, 11), np.float32)
    candidates[:, 4], candidates[:, 5], candidates[:, 7:] = 0.001, -0.028, -0.054
    candidates[:, 6] = np.nan  # a gap between the laser's lines
    heights = candidates.copy()
    heights[:, 4] = np.nan  # too steep to be floor
    seeds = np.zeros((7, 11), bool)
    seeds[:, :4] = seeds[:, 5] = True
    empty = np.isnan(candidates)
    joined = grow_region(heights, seeds, 0.05, empty, 0.0134, heights)[:, 7:]
    assert joined.all()  # the step unseen
    assert not grow_region(heights, seeds, 0.05, empty, 0.0134, candidates)[:, 7:].any()


def test_a_long_jump_crosses_the_cells_a_jump_two_cells_on_would():
    # The cells between a jump's ends, by one rule: for two cells on, the one between
    # (straight, diagonal) or both beside a knight's move, as `_can_jump` reads them;
    # for three on, the same from either end
    for dy, dx, ay, ax, by, bx in _JUMPS:
        assert set(_crossed_cells(int(dy), int(dx))) == {(ay, ax), (by, bx)}
    for (dy, dx), count, cells in zip(_LONG_JUMPS, _LONG_COUNTS, _LONG_CROSSED,
                                      strict=True):
        back = _crossed_cells(int(-dy), int(-dx))
        assert {(y, x) for y, x in cells[:count]} == {(y + dy, x + dx) for y, x in back}
        assert 2 <= count <= 4


def tangent_planes(heights: np.ndarray, gradient: tuple[float, float]) -> np.ndarray:
    """`grow_region`'s tangents of cells 5 cm apart, all of one gradient (NaN where the
    height is)."""
    ny, nx = heights.shape
    rows, cols = np.mgrid[0:ny, 0:nx] * 0.05
    tangents = np.stack([heights, cols, rows, np.full((ny, nx), gradient[0]),
                         np.full((ny, nx), gradient[1])], axis=-1).astype(np.float32)
    tangents[np.isnan(heights)] = np.nan
    return tangents


@pytest.mark.parametrize("base", [0.0, -250.0])  # a floor far from the map's zero too
@pytest.mark.parametrize("direction", [(0, 1), (1, 0), (1, 1), (1, -1), (2, 1)])
def test_a_ramp_cut_by_a_two_cell_gap_is_joined_along_its_plane(direction, base):
    # A 12.4 deg ramp (1.1 cm a cell along its gradient) seen from afar: a gap two cells
    # wide between the laser's lines cuts off its raised end, an island too small for a
    # plane of its own (fresh ramp room 618: six cells an obstacle). The jump three cells
    # on follows the ramp's tangent plane; the same island 2 cm off that plane (a ledge
    # below the ramp's end, within max_rise of it) is not reached, nor with no plane
    dy, dx = direction
    unit = np.hypot(dy, dx)
    rows, cols = np.mgrid[0:15, 0:15]
    along = (rows * dy + cols * dx) / unit  # cells along the gradient
    along -= along.min()
    gradient = (0.22 * dx / unit, 0.22 * dy / unit)
    end = 9.0 if 0 in direction else 10.0  # turned, wider: a jump two cells on spans 2.8
    cut = (along >= 7.0) & (along < end)
    for off, joined in ((0.0, True), (-0.02, False)):
        heights = (base + 0.011 * along + np.where(along >= end, off, 0.0)).astype(np.float32)
        heights[cut] = np.nan
        seeds = along < 1.0
        empty = np.isnan(heights)
        tangents = tangent_planes(heights, gradient)
        tangents[along >= end, 3:] = np.nan  # the island's cells fit no plane
        got = grow_region(heights, seeds, 0.05, empty, 0.0134, heights, tangents, 0.006)
        assert got[along < 7.0].all()
        assert got[along >= end].all() == joined and got[along >= end].any() == joined
        assert not grow_region(heights, seeds, 0.05, empty, 0.0134, heights)[along >= end].any()


def test_no_jump_along_a_plane_reaches_a_floor_below_a_step_or_crosses_hits():
    # Flat floor, a gap two cells wide, a lower floor beyond: 4 cm down (within max_rise
    # of three cells, 4.02 cm) is off the floor's plane; level with it, the jump is taken,
    # but not across cells holding hits (not floor: a step's face, a wall's foot)
    for lower, hits, joined in ((-0.04, False, False), (0.0, False, True), (0.0, True, False)):
        heights = np.zeros((9, 12), np.float32)
        heights[:, 5:7] = np.nan
        heights[:, 7:] = lower
        seeds = np.zeros((9, 12), bool)
        seeds[4, 0] = True
        empty = np.isnan(heights) & (not hits)
        got = grow_region(heights, seeds, 0.05, empty, 0.0134, heights,
                          tangent_planes(heights, (0.0, 0.0)), 0.006)
        assert got[:, :5].all() and got[:, 7:].all() == joined and got[:, 7:].any() == joined


def ramp_scene() -> S.Scene:
    """A ramp rising 1 cm per 5 cm cell (11 deg) from x = 0.5 m to a 0.3 m platform."""
    steps = tuple(S.Box((0.5125 + 0.05 * k, -0.4875, 0.0), (0.5625 + 0.05 * k, 0.4875,
                                                               0.01 * (k + 1)))
                  for k in range(30))  # contiguous: each step is one cell wide
    platform = S.Box((2.0125, -0.4875, 0.0), (2.7875, 0.4875, 0.30))
    return S.room((*steps, platform))


def test_a_ramp_and_the_platform_it_reaches_are_floor_with_their_planes():
    scene = ramp_scene()
    grid = HeightGrid(GridConfig(extent=50.0))
    poses = [(-0.5, 0.0, 0.0), (0.0, 1.5, 1.0), (0.0, -1.5, 2.0), (2.2, 0.0, 3.0),
             (1.2, 1.2, 4.0), (1.2, -1.2, 5.0)]
    S.map_scene(scene, poses, grid)
    layers = grid.layers((-3.0, -3.0, 3.0, 3.0))
    seg = segment(layers)
    xs, ys = layers.cell_centers()
    x, y = np.meshgrid(xs, ys)
    ramp = (x > 0.6) & (x < 1.9) & (np.abs(y) < 0.4) & (layers.nlev > 0)
    platform = (x > 2.1) & (x < 2.7) & (np.abs(y) < 0.4) & (layers.nlev > 0)
    assert seg.is_floor[ramp].mean() > 0.95 and seg.is_floor[platform].mean() > 0.95
    true_height = np.clip(np.floor((x - 0.5125) / 0.05) * 0.01 + 0.01, 0.0, 0.3)
    assert np.abs(seg.floor_height[ramp] - true_height[ramp]).max() < 0.015
    assert not (seg.state[ramp | platform] == OBSTACLE).any()
    tilts = [math.degrees(math.acos(p.normal[2])) for p in seg.planes]
    assert any(abs(t - math.degrees(math.atan(0.2))) < 1.5 for t in tilts), tilts
    assert any(t < 0.5 and abs(p.offset / p.normal[2] - 0.3) < 0.01
               for t, p in zip(tilts, seg.planes, strict=True)), seg.planes


def test_a_box_higher_than_the_step_is_an_obstacle_and_its_top_no_floor():
    box = S.cell_box(10, 10, 20, 20, 0.0, 0.10)
    scene = S.room((box,))
    grid = HeightGrid(GridConfig(extent=50.0))
    mapped = S.map_scene(scene, [(-0.5, 0.0, 0.0), (1.5, 2.2, 2.0)], grid)
    layers = grid.layers((-3.0, -3.0, 3.0, 3.0))
    seg = segment(layers)
    on_box = (mapped.labels == 4) & (mapped.points[:, 2] > 0.05)  # above the step height
    ix = np.floor((mapped.points[on_box, 0] - layers.origin[0]) / 0.05).astype(int)
    iy = np.floor((mapped.points[on_box, 1] - layers.origin[1]) / 0.05).astype(int)
    assert len(ix) > 100
    assert (seg.state[iy, ix] == OBSTACLE).all()
    assert not seg.is_floor[iy, ix].any()


def test_floor_precision_and_recall_on_the_furnished_room():
    scene = S.furnished_room()
    robot = RobotShape(height=0.8)
    mapped = S.map_scene(scene, S.ROOM_POSES, HeightGrid(GridConfig(extent=50.0)))
    layers = mapped.grid.layers((-3.1, -3.1, 3.1, 3.1))
    seg = segment(layers, robot)
    xs, ys = layers.cell_centers()
    truth = S.truth_floor(scene, xs, ys, robot.step_height, robot.height)
    walkable = [k for k, b in enumerate(scene.boxes) if b.hi[2] <= robot.step_height]
    floor_seen = S.hit_cells(layers, mapped, [S.FLOOR, *walkable])
    predicted = seg.is_floor
    precision = (predicted & truth).sum() / predicted.sum()
    recall = (predicted & truth & floor_seen).sum() / (truth & floor_seen).sum()
    assert precision >= 0.99 and recall >= 0.99, (precision, recall)


def test_a_2d_laser_map_needs_an_assumed_floor():
    """Points all at 0.3 m (a 2-D scan): no floor is seen; without floor detection and
    with a fallback floor the walls are obstacles and the beams' cells free."""
    grid = HeightGrid(GridConfig(extent=50.0))
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    wall = np.column_stack([2.0 * np.cos(angles), 2.0 * np.sin(angles), np.full(360, 0.3)])
    grid.insert(wall, np.array([0.0, 0.0, 0.3]), 0.0)
    layers = grid.layers((-2.5, -2.5, 2.5, 2.5))
    flat = FloorConfig(min_coverage=0.0, detect=False)
    seg = segment(layers, params=flat, fallback_floor=0.0)
    xs, ys = layers.cell_centers()
    r = np.hypot(*np.meshgrid(xs, ys))
    assert (seg.state[np.abs(r - 2.0) < 0.02] == OBSTACLE).mean() > 0.9
    assert (seg.state[(r > 0.5) & (r < 1.8)] == FREE).mean() > 0.9


@settings(max_examples=60, deadline=None)
@given(ny=st.integers(1, 7), nx=st.integers(1, 7), share=st.sampled_from([0.0, 0.05, 0.5]),
       places=st.integers(0, 3), seed=st.integers(0, 2**31 - 1))
def test_the_observed_box_bounds_the_observed_cells_and_the_places_stood(ny, nx, share,
                                                                         places, seed):
    """`_observed_box` (`observed_span` and the places stood) against numpy: cells with a
    level or seen heights, and places the robot stood inside the window (not those beyond
    it), grown by the reach and the footprint; none at all gives an empty box."""
    rng = np.random.default_rng(seed)
    nlev = (rng.random((ny, nx)) < share).astype(np.uint8)
    seen = np.where(rng.random((ny, nx)) < share, np.uint64(8), np.uint64(0))
    stood = rng.uniform(-0.1, 0.1 + 0.05 * max(nx, ny), (places, 2))  # some beyond it
    observed = (nlev > 0) | (seen != 0)
    cols, rows = np.floor(stood / 0.05).astype(int).T
    inside = (cols >= 0) & (cols < nx) & (rows >= 0) & (rows < ny)
    observed[rows[inside], cols[inside]] = True
    r, c = np.flatnonzero(observed.any(axis=1)), np.flatnonzero(observed.any(axis=0))
    grow = 1 + 1  # reach 1, and a footprint of 0.01 m: one cell
    want = (slice(max(r[0] - grow, 0), min(r[-1] + grow + 1, ny)),
            slice(max(c[0] - grow, 0), min(c[-1] + grow + 1, nx))) if len(r) \
        else (slice(0, 0), slice(0, 0))
    layers = CellLayers(origin=(0.0, 0.0), resolution=0.05, z_min=-0.35, mask_dz=0.025,
                        levels=np.zeros((ny, nx, 3, gk.N_FLOAT_FIELDS), np.float32),
                        counts=np.zeros((ny, nx, 3, 2), np.uint32), nlev=nlev, seen=seen,
                        updated=np.zeros((ny, nx)), stood=stood)
    assert segmentation._observed_box(layers, RobotShape(radius=0.01), 1) == want


@settings(max_examples=60, deadline=None)
@given(ny=st.integers(1, 6), nx=st.integers(1, 6), seed=st.integers(0, 2**31 - 1))
def test_between_takes_cells_with_the_mask_on_both_sides_in_a_row_or_column(ny, nx, seed):
    """`_between` against its definition, cell by cell, on grids down to one cell."""
    mask = np.random.default_rng(seed).random((ny, nx)) < 0.5
    want = np.zeros((ny, nx), bool)
    for y in range(ny):
        for x in range(nx):
            want[y, x] = (0 < x < nx - 1 and mask[y, x - 1] and mask[y, x + 1]) or (
                0 < y < ny - 1 and mask[y - 1, x] and mask[y + 1, x])
    assert np.array_equal(_states._between(mask), want)


@pytest.mark.parametrize("height", [math.nan, math.inf, -math.inf])
def test_a_fallback_floor_that_is_no_height_is_refused(height):
    """NaN or inf as the assumed floor: a clear error naming it, not a map of it."""
    grid = HeightGrid(GridConfig(extent=10.0))
    grid.insert(np.array([[1.0, 0.0, 0.3]]), np.array([0.0, 0.0, 0.3]), 0.0)
    with pytest.raises(MapError, match="fallback_floor"):
        segment(grid.layers((-1.0, -1.0, 1.5, 1.0)), fallback_floor=height)


def assert_same_segmentation(got, want) -> None:
    """The same cells, states and planes; heights and points to rounding (a window's cell
    centres computed from another origin)."""
    assert np.array_equal(got.state, want.state)
    assert np.array_equal(got.is_floor, want.is_floor)
    for name in ("floor_height", "points", "band_logodds", "slope"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0,
                                   atol=1e-6, err_msg=name)
    assert len(got.planes) == len(want.planes)
    for a, b in zip(got.planes, want.planes, strict=True):
        np.testing.assert_allclose(a.normal, b.normal, atol=1e-12)
        assert abs(a.offset - b.offset) < 1e-12 and a.cells == b.cells


def test_a_window_mostly_unobserved_segments_as_a_whole():
    """A 16 m window round the 6 m furnished room: the part no rule reaches is left out
    (a quarter of the window is segmented), the result is the whole window's."""
    mapped = S.map_scene(S.furnished_room(), S.ROOM_POSES[:3],
                         HeightGrid(GridConfig(extent=50.0)))
    layers = mapped.grid.layers((-8.0, -8.0, 8.0, 8.0))
    params, robot = FloorConfig(), RobotShape()
    rows, cols = segmentation._observed_box(layers, robot,
                                            segmentation._reach(params, layers.resolution))
    assert (rows.stop - rows.start) * (cols.stop - cols.start) < 0.4 * layers.nlev.size
    seg = segment(layers, robot, params)
    assert_same_segmentation(seg, segmentation._segment(layers, robot, params, None)[0])
    assert (seg.state == FREE).sum() > 1000 and (seg.state == OBSTACLE).sum() > 300
    assert np.isfinite(seg.floor_height).all()  # beyond the reach: the floor plane's height


def test_a_2d_laser_window_mostly_unobserved_keeps_its_assumed_floor():
    grid = HeightGrid(GridConfig(extent=50.0))
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    wall = np.column_stack([1.0 * np.cos(angles), 1.0 * np.sin(angles), np.full(360, 0.3)])
    # off the cells' corners: a footprint whose rim passes through a cell's corner exactly
    # is decided by the rounding of the cell centres, which differs between windows
    grid.insert(wall + [0.013, -0.021, 0.0], np.array([0.013, -0.021, 0.3]), 0.0)
    layers = grid.layers((-9.0, -9.0, 9.0, 9.0))
    flat = FloorConfig(min_coverage=0.0, detect=False)
    seg = segment(layers, params=flat, fallback_floor=0.0)
    assert_same_segmentation(seg, segmentation._segment(layers, RobotShape(), flat, 0.0)[0])
    assert (seg.floor_height == 0.0).all() and (seg.state == OBSTACLE).sum() > 100


@pytest.mark.parametrize("kwargs", [{"step_height": 0.0}, {"height": -1.0},
                                    {"radius": math.nan}, {"step_height": 1.2}])
def test_robot_shape_rejects_nonsense(kwargs):
    with pytest.raises(MapError):
        RobotShape(**kwargs)


@settings(max_examples=60, deadline=None)
@given(tilt=st.floats(0.0, 1.2), azimuth=st.floats(0.0, 6.3), far=st.sampled_from([0.0, 1e5]),
       noise=st.sampled_from([0.0, 1e-3, 0.02]), seed=st.integers(0, 2**31 - 1))
def test_the_plane_fit_is_the_svd_least_squares_plane(tilt, azimuth, far, noise, seed):
    """The scatter-matrix fit (`best_plane`'s refinement) against the plain SVD of the
    centred points, near the origin and 100 km from it, with no noise to a 2 cm spread."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-2.0, 2.0, (400, 2)) + far
    slope = math.tan(tilt) * np.array([math.cos(azimuth), math.sin(azimuth)])
    z = 0.3 + (xy - far) @ slope + rng.normal(0.0, noise, 400)
    p = np.column_stack([xy, z])
    any_plane = np.array([[0.0, 0.0, 1.0]])  # every point is within inf of it
    count, normal, offset = best_plane(np.ascontiguousarray(p.T), np.arange(400),
                                       any_plane, any_plane, np.inf, 1.0, 1)
    assert count == 400
    centre = p.mean(axis=0)
    reference = np.linalg.svd(p - centre, full_matrices=False)[2][-1]
    reference = -reference if reference[2] < 0 else reference
    np.testing.assert_allclose(normal, reference, atol=1e-9)
    assert offset == pytest.approx(float(reference @ centre), rel=1e-12, abs=1e-9)
    assert normal[2] >= 0 and np.linalg.norm(normal) == pytest.approx(1.0)
