"""Gaps between the laser's samples (issue 17 item 6): small bare patches inside consistent
floor are floor, others not (closed forms); band coverage pooled over a cell's neighbours
counts exactly the bins they saw, and without pooling gives the kernel's own rule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from benchmarks.bench_hazards import PARAMS, ROBOT, fuse, scene_window
from scanmap.grid._kernels import LO
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation import floor as floor_module
from scanmap.navigation import morphology
from scanmap.navigation.floor import (
    FloorConfig,
    RobotShape,
    _drop_offs,
    _seen_kernels,
    _states,
    _unseen,
    segment,
)
from scanmap.navigation.floor._band_kernels import classify_band, pooled_bits
from scanmap.navigation.floor._seen_kernels import (
    NO_SAMPLES,
    floor_gaps,
    floor_gaps_reference,
    interpolated_reference,
    lowest_seen,
)
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.ideal import ideal_scans

STEP = 0.05
TOLERANCE = FloorConfig().plane_tolerance


def gap_scene(n: int = 20, gap: tuple[int, int, int, int] = (8, 10, 8, 10)):
    """Floor hits everywhere (height 0) but a bare patch rows gap[0]:gap[1], cols gap[2]:gap[3]
    and the ring of one cell around it (no hit there either): bare, nlev, is_floor,
    heights, drop, dips."""
    y0, y1, x0, x1 = gap
    nlev = np.ones((n, n), np.uint8)
    nlev[y0 - 1:y1 + 1, x0 - 1:x1 + 1] = 0
    is_floor = nlev > 0
    bare = np.zeros((n, n), bool)
    bare[y0:y1, x0:x1] = True
    return (bare, nlev, is_floor, np.zeros((n, n), np.float32), np.zeros((n, n), bool),
            np.zeros((n, n), bool))


def lit_gaps(bare, nlev, is_floor, heights, drop, dips):
    return _unseen._lit_gaps(bare, nlev, is_floor, heights, drop, dips, 6, STEP)


def test_a_small_gap_in_level_floor_is_floor():
    bare, nlev, is_floor, heights, drop, dips = gap_scene()
    assert (lit_gaps(bare, nlev, is_floor, heights, drop, dips) == bare).all()


@pytest.mark.parametrize("spoil", ["step", "obstacle_hit", "drop", "too_large", "edge", "dip"])
def test_a_gap_is_not_floor_when_its_surroundings_are_not_consistent_floor(spoil):
    gap = (8, 10, 8, 10) if spoil not in ("too_large", "edge") else \
        (4, 12, 8, 10) if spoil == "too_large" else (1, 3, 8, 10)
    bare, nlev, is_floor, heights, drop, dips = gap_scene(gap=gap)
    if spoil == "step":
        heights[gap[1] + 1, gap[2]] = 2 * STEP  # a floor hit a step higher, two cells away
    elif spoil == "obstacle_hit":
        is_floor[gap[1] + 1, gap[2]] = False  # a hit there that is not floor
    elif spoil == "drop":
        drop[gap[0] - 1, gap[2]] = True
    elif spoil == "dip":  # a floor cell reaching down a hole's far wall, two cells away
        dips[gap[1] + 1, gap[2]] = True
    assert not lit_gaps(bare, nlev, is_floor, heights, drop, dips).any()


@pytest.mark.parametrize(("depth", "dips"), [(1.2, True), (0.8, False)])
def test_a_dip_is_a_level_reaching_below_the_floor_beside_it(depth, dips):
    # level floor whose bottoms lie at 0 but one cell reaching depth x plane_tolerance down
    nlev = np.ones((9, 9), np.uint8)
    nlev[0, :] = 0  # and a row without hits, whose bottoms mean nothing
    bottom = np.where(nlev > 0, 0.0, -1.0).astype(np.float32)
    bottom[4, 4] = -depth * TOLERANCE
    found = _unseen._dips(nlev, bottom, nlev > 0, TOLERANCE)
    expected = np.zeros((9, 9), bool)
    expected[4, 4] = dips
    assert (found == expected).all()


@given(st.floats(0.0, math.radians(15.0)), st.floats(0.0, 2 * math.pi))
def test_the_steepest_floor_has_no_dips(slope, azimuth):
    """On a plane up to max_slope, a cell's bottom lies at most one cell's rise (5 cm x
    tan 15 deg x sqrt 2 = 1.9 cm) below its neighbours': under plane_tolerance."""
    y, x = np.mgrid[0:12, 0:12] * 0.05
    bottom = (np.tan(slope) * (x * np.cos(azimuth) + y * np.sin(azimuth))).astype(np.float32)
    nlev = np.ones((12, 12), np.uint8)
    assert not _unseen._dips(nlev, bottom, nlev > 0, TOLERANCE).any()


def test_plain_floor_shows_no_dips_under_four_times_the_peak_noise():
    """The corridor's flat floor, 8 ideal scans with a laser peak error of 0.4 px (the
    scanner model's 0.1 px four times over): no floor cell is a dip, so the gaps between
    the laser's lines stay filled (measured: none at 0.1-0.4 px; 2.5 % of the floor cells
    at 0.8 px, where the floor's levels are 1.7 cm thick)."""
    scene = builtin_scene("corridor")
    grid = HeightGrid(GridConfig(extent=50.0))
    for ideal in ideal_scans(scene, scans=8, pixel_sigma=4 * reference_scanner().pixel_sigma):
        fuse(grid, ideal)
    layers = grid.layers(scene_window(scene))
    seg = segment(layers, ROBOT, PARAMS)
    floor = seg.is_floor & (layers.nlev > 0)
    assert floor.sum() > 2000
    bottom = layers.levels[:, :, 0, LO]
    assert not _unseen._dips(layers.nlev, bottom, floor, PARAMS.plane_tolerance).any()


def test_pooled_seen_spreads_each_bin_to_the_neighbours_only():
    seen = np.zeros((7, 7), np.uint64)
    seen[3, 3] = np.uint64(1 << 20)
    pooled = pooled_bits(seen, 1)
    expected = np.zeros((7, 7), bool)
    expected[2:5, 2:5] = True
    assert ((pooled == np.uint64(1 << 20)) == expected).all()
    assert (pooled[~expected] == 0).all()


def pooled_reference(seen: np.ndarray, reach: int) -> np.ndarray:
    """The OR of each cell's (2 reach + 1)^2 square, by shifted copies of a padded grid."""
    ny, nx = seen.shape
    padded = np.pad(seen, reach)
    out = seen.copy()
    for dy in range(2 * reach + 1):
        for dx in range(2 * reach + 1):
            out |= padded[dy:dy + ny, dx:dx + nx]
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.integers(1, 12), st.integers(0, 3))
def test_pooled_bits_and_lowest_seen_match_plain_numpy(seed, ny, nx, reach):
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 64, (ny, nx)).astype(np.uint64)
    seen = np.where(rng.random((ny, nx)) < 0.3, np.uint64(0), np.uint64(1) << bits)
    seen |= np.where(rng.random((ny, nx)) < 0.5, np.uint64(1) << np.uint64(63), np.uint64(0))
    assert np.array_equal(pooled_bits(seen, reach), pooled_reference(seen, reach))
    low = seen & (~seen + np.uint64(1))  # the lowest set bit, 0 for none
    with np.errstate(divide="ignore"):
        expected = -0.35 + 0.025 * np.log2(low.astype(np.float64))
    assert np.array_equal(lowest_seen(seen, -0.35, 0.025), expected)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_floor_gaps_match_their_plain_reference(seed):
    """Random hit-free rectangles in floor of random heights (some NaN), dips, stray hits
    and drop-offs: the kernel's verdict per patch is the plain loop's (measured over 300
    seeds: 191 small patches, 69 gaps without the dips, 46 with them)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(8, 30))
    nlev = np.ones((n, n), np.uint8)
    for _ in range(int(rng.integers(1, 5))):
        y, x = rng.integers(0, n, 2)
        h, w = rng.integers(3, 8, 2)
        nlev[y:y + h, x:x + w] = 0
    nlev[rng.random((n, n)) < 0.02] = 1
    is_floor = (nlev > 0) & (rng.random((n, n)) < 0.97)
    heights = rng.normal(0.0, 0.01, (n, n)).astype(np.float32)
    heights[rng.random((n, n)) < 0.01] = np.nan
    dips = rng.random((n, n)) < 0.01
    bare = ~ndimage.maximum_filter(nlev > 0, 3)
    drop = rng.random((n, n)) < 0.01
    labels, boxes, ok = morphology.small_patches(bare, 4, margin=2)
    near_drop = ndimage.binary_dilation(drop, np.ones((3, 3), bool))
    args = (labels, boxes, ok, near_drop, nlev, is_floor, heights, dips, STEP)
    assert np.array_equal(floor_gaps(*args), floor_gaps_reference(*args))


@pytest.mark.parametrize("pooled", [False, True])
def test_band_coverage_counts_the_band_bins_seen(pooled):
    # Every band bin observable; a cell counts half of them (its own or its neighbours'):
    # FREE at min_coverage 0.5, UNKNOWN with one bin fewer
    grid = HeightGrid(GridConfig())
    layers = grid.layers((0.0, 0.0, 0.15, 0.15))
    robot = RobotShape()
    lo = int(np.floor((robot.step_height - layers.z_min) / layers.mask_dz))
    hi = int(np.floor((robot.height - 1e-6 - layers.z_min) / layers.mask_dz))
    band = sum(1 << b for b in range(lo, hi + 1))
    seen = np.full(layers.shape, band, np.uint64)
    for bins, expected in (((hi - lo + 1 + 1) // 2, floor_module.FREE),
                           ((hi - lo + 1 + 1) // 2 - 1, floor_module.UNKNOWN)):
        half = sum(1 << b for b in range(lo, lo + bins))
        counted = np.full(layers.shape, half, np.uint64)
        if not pooled:
            seen = counted.copy()
            seen[0, 0] = band  # the heights observable in the window
        state = np.empty(layers.shape, np.uint8)
        points = np.empty((*layers.shape, 2), np.float32)
        logodds = np.empty(layers.shape, np.float32)
        covered = np.zeros(layers.shape, bool)
        classify_band(layers.levels, layers.nlev, seen, counted,
                      np.zeros(layers.shape, np.float32), np.ones(layers.shape, bool),
                      robot.step_height, robot.height,
                      layers.z_min, layers.mask_dz, 0.5, 12, 0.1, layers.origin[0],
                      layers.origin[1], layers.resolution, state, points, logodds, covered)
        inner = state[1:, 1:] if not pooled else state
        assert (inner == expected).all(), (bins, hi - lo + 1)
    if pooled:  # the cell itself must have seen one of the band's bins
        seen = np.where(np.eye(*layers.shape, dtype=bool), np.uint64(0), np.uint64(band))
        classify_band(layers.levels, layers.nlev, seen, np.full(layers.shape, band, np.uint64),
                      np.zeros(layers.shape, np.float32), np.ones(layers.shape, bool),
                      robot.step_height, robot.height,
                      layers.z_min, layers.mask_dz, 0.5, 12, 0.1, layers.origin[0],
                      layers.origin[1], layers.resolution, state, points, logodds, covered)
        assert (state[np.eye(*layers.shape, dtype=bool)] == floor_module.UNKNOWN).all()
        assert (state[~np.eye(*layers.shape, dtype=bool)] == floor_module.FREE).all()


def test_without_pooling_the_coverage_rule_is_the_kernels(monkeypatch):
    grid = HeightGrid(GridConfig(extent=20.0))
    rng = np.random.default_rng(0)
    xy = rng.uniform(-2.5, 2.5, (4000, 2))
    points = np.column_stack([xy, np.zeros(len(xy))])
    for origin in ([0.0, 0.0, 1.0], [1.0, 0.5, 1.0]):
        grid.insert(points, np.array(origin), 1.0)
    layers = grid.layers((-2.0, -2.0, 2.0, 2.0))
    kernel = segment(layers, params=FloorConfig(coverage_reach=0.0))
    monkeypatch.setattr(_states, "pooled_bits", lambda seen, reach: seen)
    numpy_rule = segment(layers)
    assert (kernel.state == numpy_rule.state).all()
    assert (kernel.state == floor_module.FREE).sum() > 100


def interpolated(known: np.ndarray, hit: np.ndarray | None = None,
                 heights: np.ndarray | None = None, unlit_corners: bool = False) -> np.ndarray:
    hit = known.copy() if hit is None else hit
    heights = np.zeros(known.shape, np.float32) if heights is None else heights
    out = _seen_kernels.interpolated(known, hit, heights, 2, STEP, unlit_corners, NO_SAMPLES)
    assert (out == interpolated_reference(known, hit, heights, 2, STEP, unlit_corners)).all()
    return out


@pytest.mark.parametrize("gap", [1, 2, 3])
def test_a_gap_of_two_cells_between_floor_samples_is_floor_a_wider_one_not(gap):
    known = np.zeros((7, 12), bool)
    known[3, 2] = known[3, 3 + gap] = True  # along a row
    out = interpolated(known)
    assert out[3, 3:3 + gap].all() == (gap <= 2)
    assert out.sum() == 2 + (gap if gap <= 2 else 0)
    assert (interpolated(known.T) == out.T).all()  # along a column


def test_a_diagonal_gap_is_measured_in_metres():
    known = np.zeros((8, 8), bool)
    known[1, 1] = known[3, 3] = True  # one cell apart on the diagonal: 2.8 cells
    assert interpolated(known)[2, 2]
    known[3, 3], known[4, 4] = False, True  # two cells: 4.2 cells, wider than a 2-cell gap
    assert not interpolated(known)[2:4, 2:4].any()
    flipped = np.zeros((8, 8), bool)
    flipped[1, 3] = flipped[3, 1] = True  # the other diagonal
    assert interpolated(flipped)[2, 2]


@pytest.mark.parametrize("off_floor", [(), ((4, 3),), ((5, 4),), ((4, 3), (5, 4))])
def test_no_diagonal_across_the_inner_corner_of_hits_off_the_floor(off_floor):
    # A hole's corner between two rim cells that hold floor on their outer halves: the
    # cell between them on the diagonal, with hits off the floor (the hole's) both left
    # of it and below it, lies inside the hole, not in a gap between floor samples
    known = np.zeros((9, 9), bool)
    known[3, 3] = known[5, 5] = True  # the rim cells on the diagonal through (4, 4)
    hit = known.copy()
    for cell in off_floor:
        hit[cell] = True
    assert interpolated(known, hit)[4, 4] == (len(off_floor) < 2)
    flipped = interpolated(known[:, ::-1], hit[:, ::-1])  # the other diagonal
    assert flipped[4, 4] == (len(off_floor) < 2)


@pytest.mark.parametrize("floor_beside", [(), ((4, 3),), ((5, 4),), ((4, 3), (3, 4)),
                                          ((4, 3), (4, 5)), ((5, 4), (3, 4))])
@pytest.mark.parametrize("hits", [False, True])
def test_with_unlit_corners_a_diagonal_needs_floor_on_both_sides(floor_beside, hits):
    # A hole's corner often holds no hit at all: with `unlit_corners` (how the free space
    # is filled), the cell between two rim cells on a diagonal is bridged only with floor
    # beside it on both sides of the diagonal, hits or no hits elsewhere
    known = np.zeros((9, 9), bool)
    known[3, 3] = known[5, 5] = True  # the rim cells on the diagonal through (4, 4)
    hit = known | hits  # the rest: hits off the floor, or unobserved
    hit[4, 4] = False  # the cell itself holds no hit
    for cell in floor_beside:
        known[cell] = hit[cell] = True
    sides = {(4, 3): 0, (5, 4): 0, (3, 4): 1, (4, 5): 1}  # side of the diagonal
    both = {sides[cell] for cell in floor_beside} == {0, 1}
    assert interpolated(known, hit, unlit_corners=True)[4, 4] == both
    flipped = interpolated(known[:, ::-1], hit[:, ::-1], unlit_corners=True)
    assert flipped[4, 4] == both  # the other diagonal


@pytest.mark.parametrize("spoil", ["hit", "step"])
def test_no_interpolation_across_a_hit_that_is_not_floor_nor_across_a_step(spoil):
    known = np.zeros((7, 12), bool)
    known[3, 2] = known[3, 5] = True
    hit = known.copy()
    heights = np.zeros(known.shape, np.float32)
    if spoil == "hit":
        hit[3, 4] = True  # a hit that is not floor: the gap is no gap
    else:
        heights[3, 5] = 2 * STEP
    out = interpolated(known, hit, heights)
    assert not out[3, 3:5].any()


def test_cells_without_floor_seen_are_never_free_however_much_of_the_band_rays_saw():
    # Floor hits round a 0.6 m square without any (black carpet, a hole nothing returned
    # from), rays from 1 m up: the cells inside are seen over, never seen as floor
    grid = HeightGrid(GridConfig(extent=20.0))
    rng = np.random.default_rng(0)
    xy = rng.uniform(-2.5, 2.5, (6000, 2))
    xy = xy[(np.abs(xy[:, 0] - 1.0) > 0.3) | (np.abs(xy[:, 1]) > 0.3)]
    points = np.column_stack([xy, np.zeros(len(xy))])
    for origin in ([0.0, 0.0, 1.0], [1.0, 0.5, 1.0], [2.0, -0.5, 1.0]):
        grid.insert(points, np.array(origin), 1.0)
    seg = segment(grid.layers((-2.0, -2.0, 2.0, 2.0)))
    x = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution
    y = seg.origin[1] + (np.arange(seg.shape[0]) + 0.5) * seg.resolution
    gx, gy = np.meshgrid(x, y)
    inside = (np.abs(gx - 1.0) < 0.3 - seg.resolution) & (np.abs(gy) < 0.3 - seg.resolution)
    assert inside.sum() > 50
    assert not (seg.state[inside] == floor_module.FREE).any()
    assert (seg.state[~inside] == floor_module.FREE).sum() > 100


@pytest.mark.parametrize("seed", range(4))
def test_interpolation_matches_its_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    known = rng.random((30, 40)) < 0.3
    hit = known | (rng.random((30, 40)) < 0.1)
    heights = rng.normal(0.0, 0.04, (30, 40)).astype(np.float32)
    heights[rng.random((30, 40)) < 0.05] = np.nan
    samples = rng.uniform(-0.5, 0.5, (30, 40, 2)).astype(np.float32)
    samples[rng.random((30, 40)) < 0.2] = np.nan
    for size in (1, 2, 4):
        for unlit in (False, True):
            assert (_seen_kernels.interpolated(known, hit, heights, size, STEP, unlit, NO_SAMPLES)
                    == interpolated_reference(known, hit, heights, size, STEP, unlit)).all()
            assert (_seen_kernels.interpolated(known, hit, heights, size, STEP, unlit, samples)
                    == interpolated_reference(known, hit, heights, size, STEP, unlit,
                                              samples)).all()


@pytest.mark.parametrize("seed", range(6))
def test_cells_beyond_every_span_passed_as_hits_change_no_interpolation(seed):
    rng = np.random.default_rng(seed)
    known = rng.random((40, 50)) < rng.uniform(0.005, 0.1)
    hit = (rng.random((40, 50)) < 0.2) & ~known
    heights = rng.normal(0.0, 0.03, (40, 50)).astype(np.float32)
    for size in range(7):
        beyond = _drop_offs._beyond_spans(known, size)
        for unlit in (False, True):
            args = (heights, size, STEP, unlit, NO_SAMPLES)
            assert np.array_equal(_seen_kernels.interpolated(known, hit | beyond, *args),
                                  _seen_kernels.interpolated(known, hit, *args))


@pytest.mark.parametrize(("apart", "a", "b", "bridged"), [
    (6, 0.4, -0.4, True),     # samples 0.4 cells in from each end: 5.2 cells open
    (6, -0.4, 0.4, False),    # 0.4 cells out: 6.8
    (6, None, None, False),   # unknown: the cells' outer edges, 7
    (6, 0.4, None, False),    # one known: 6.1
    (5, None, None, True),    # unknown, a cell nearer: 6, as without samples
    (7, 0.5, -0.5, True),     # the samples on the cells' inner edges: 6
    (7, 0.45, -0.45, False),  # 6.1
])
def test_an_opening_is_measured_between_the_floor_samples(apart, a, b, bridged):
    # Two floor cells `apart` cells apart along a row, bridged (size 4) when their samples
    # lie at most 6 cells apart; offsets along the row, a toward b when positive
    known = np.zeros((5, 12), bool)
    known[2, 1] = known[2, 1 + apart] = True
    samples = np.full((5, 12, 2), np.nan, np.float32)
    if a is not None:
        samples[2, 1] = (a, 0.0)
    if b is not None:
        samples[2, 1 + apart] = (b, 0.0)
    for grid in (known, known.T):  # along a row, then a column (offsets swapped)
        cells = np.ascontiguousarray(
            samples if grid is known else samples.transpose(1, 0, 2)[:, :, ::-1])
        heights = np.zeros(grid.shape, np.float32)
        out = _seen_kernels.interpolated(grid, grid, heights, 4, STEP, False, cells)
        gap = out[2, 2:1 + apart] if grid is known else out[2:1 + apart, 2]
        assert len(gap) == apart - 1
        assert gap.all() == bridged and gap.any() == bridged
        assert out.sum() == 2 + bridged * (apart - 1)
        assert (out == interpolated_reference(grid, grid, heights, 4, STEP, False,
                                              cells)).all()
    heights = np.zeros(known.shape, np.float32)
    assert _seen_kernels.interpolated(known, known, heights, 4, STEP, False, NO_SAMPLES)[
        2, 2:1 + apart].all() \
        == (apart <= 5)  # without samples, to the cells' edges


@pytest.mark.parametrize("wall", [None, 1.13, 0.87])
def test_a_small_patch_without_returns_is_a_hole_beside_a_surface_below_the_floor(wall):
    # A 0.25 m patch without hits in dense floor hits: a gap, floor; with the top of its
    # far wall seen 4-12 cm below the floor (a surface below the floor model, though not
    # wholly a step below), a hole: the cells without a hit around them are sunk. The
    # same surface on the patch's near side (x = 0.87 m, seen from the origin) is not
    # its far wall: the patch lies beyond a lowered area (rendered mixed room 10: 15
    # cells of unlit floor beyond a step down's far side were DROP_OFF)
    grid = HeightGrid(GridConfig(extent=20.0))
    a = np.arange(-1.5, 1.5, 0.02)
    x, y = np.meshgrid(a + 1.0, a)
    keep = (np.abs(x - 1.0) > 0.125) | (np.abs(y) > 0.125)
    points = np.column_stack([x[keep], y[keep], np.zeros(keep.sum())])
    if wall is not None:
        wy, wz = np.meshgrid(np.linspace(-0.1, 0.1, 6), np.linspace(-0.12, -0.04, 5))
        top = np.column_stack([np.full(wy.size, wall), wy.ravel(), wz.ravel()])
        points = np.vstack([points[(np.abs(points[:, 0] - wall) > 0.02)
                                   | (np.abs(points[:, 1]) > 0.125)], top])
    grid.insert(points, np.array([0.0, 0.0, 1.0]), 1.0)
    layers = grid.layers((-0.4, -1.0, 2.0, 1.0))
    hit = layers.nlev > 0
    is_floor = hit & (layers.levels[:, :, 0, 1] > -0.02)
    dark = ~ndimage.maximum_filter(hit, size=3)
    lowest = np.zeros(layers.shape, np.float32)
    none = np.zeros(layers.shape, bool)
    assert 4 <= dark.sum() <= 9
    sunk = _unseen._sunk(dark, layers, is_floor, lowest, none, 6, 0.03, None)
    assert (sunk == (dark if wall == 1.13 else none)).all()
    drop = ndimage.binary_dilation(dark) & ~dark  # beside a drop-off: the drop's own rule
    assert not _unseen._sunk(dark, layers, is_floor, lowest, drop, 6, 0.03, None).any()
    assert not _unseen._sunk(dark, layers, is_floor, lowest, none, 1, 0.03, None).any()


def between_floor_lines(first: float, spacing: float, params: FloorConfig
                        ) -> tuple[set[int], np.ndarray]:
    """Five floor lines along x (1-2 m), `spacing` apart from y = `first`, seen from the
    origin 1 m up with a wall behind them (2.6 m: rays to it pass over all): the spacings
    of the lines' rows and the states of the cells between the lines, away from their
    ends."""
    grid = HeightGrid(GridConfig(extent=20.0))
    x = np.arange(1.0, 2.0, 0.01)
    ys = first + spacing * np.arange(5)
    floor = np.column_stack([np.tile(x, 5), np.repeat(ys, len(x)), np.zeros(5 * len(x))])
    wy, wz = np.meshgrid(np.arange(-1.0, 2.0, 0.01), np.arange(0.1, 1.2, 0.02))
    wall = np.column_stack([np.full(wy.size, 2.6), wy.ravel(), wz.ravel()])
    grid.insert(np.vstack([floor, wall]), np.array([0.0, ys.mean(), 1.0]), 1.0)
    seg = segment(grid.layers((-0.5, -1.0, 3.0, 2.0)), params=params)
    x_c = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution
    y_c = seg.origin[1] + (np.arange(seg.shape[0]) + 0.5) * seg.resolution
    lit = np.floor((ys - seg.origin[1]) / seg.resolution).astype(int)  # the lines' rows
    middle = (x_c > 1.35) & (x_c < 1.65)  # away from the lines' ends
    between = (y_c > ys[0]) & (y_c < ys[-1])
    between[lit] = False
    return set(np.diff(lit)), seg.state[np.ix_(between, middle)]


@pytest.mark.parametrize(("spacing", "bridged"), [(0.28, True), (0.32, False)])
def test_the_gap_between_two_laser_lines_is_floor_when_their_hits_lie_max_gap_apart(
        spacing, bridged):
    # Floor lines along x 0.28 m apart hit to hit (their cells 5 or 6 apart): at most
    # max_gap (0.3 m) open, the cells between them are floor, though the cells' edges lie
    # up to 0.35 m apart; 0.32 m apart, they are not
    assert FloorConfig().max_gap == 0.3
    apart, state = between_floor_lines(0.03, spacing, FloorConfig())
    assert apart == ({5, 6} if bridged else {6, 7})
    assert (state == floor_module.FREE).all() == bridged
    assert (state == floor_module.UNKNOWN).all() == (not bridged)


@pytest.mark.parametrize(("spacing", "bridged"), [(0.14, True), (0.18, False)])
def test_a_narrow_gap_is_floor_when_its_floor_hits_lie_at_most_15_cm_apart(spacing, bridged):
    # The narrow rule alone (max_gap 0.1 m turns the laser lines' rule off): floor lines
    # along x 0.14 m apart hit to hit, their cells 2 or 3 apart, leave floor between; 0.18
    # m apart, cells 3 or 4 apart, they do not, though the cells of a pair 3 apart lie
    # within three cells of each other (a pit's turned corner between two rim cells whose
    # floor hits lie on their outer edges: random room 435)
    apart, state = between_floor_lines(0.025, spacing, FloorConfig(max_gap=0.1))
    assert apart == ({2, 3} if bridged else {3, 4})
    assert (state == floor_module.FREE).all() == bridged
    assert (state == floor_module.UNKNOWN).all() == (not bridged)
