"""The grid kernels against plain-numpy references: masks, ray traversal, levels, clearing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.grid import _kernels as gk
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.rays import laser_origins, scan_rays
from scanmap_driver.errors import MapError
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.scene import builtin_scene

CONFIG = GridConfig(extent=20.0, bundle_run=0)


def reference_mask(za: float, zb: float, z_min: float, dz: float) -> int:
    """Bits b0..b1 of the bins holding za and zb, clipped to 0..63."""
    b0, b1 = (min(max(int(np.floor((z - z_min) / dz)), 0), 63) for z in (za, zb))
    return sum(1 << b for b in range(b0, b1 + 1))


@settings(max_examples=300, deadline=None)
@given(st.floats(-3, 4), st.floats(0, 2), st.floats(-1, 0.5), st.sampled_from([0.025, 0.05]))
def test_height_mask_matches_reference(za, span, z_min, dz):
    assert int(gk.height_mask(za, za + span, z_min, dz)) == reference_mask(za, za + span,
                                                                           z_min, dz)


def test_classify_points_matches_numpy():
    rng = np.random.default_rng(3)
    points = rng.uniform(-12, 12, (500, 3))
    origins = rng.uniform(-12, 12, (500, 3))
    points[::17, 1] = np.nan
    origins[::23, 2] = np.inf
    bounds = np.array([-10.0, -10.0, 10.0, 10.0])
    window = np.array([-5.0, -6.0, 5.0, 6.0])
    cls = gk.classify_points(points, origins, bounds, window, 8.0)

    def inside(box, p):
        return (box[0] <= p[:, 0]) & (p[:, 0] < box[2]) & (box[1] <= p[:, 1]) & (p[:, 1] < box[3])

    finite = np.isfinite(points).all(1) & np.isfinite(origins).all(1)
    in_bounds = inside(bounds, points) & inside(bounds, origins)
    in_window = inside(window, points) & inside(window, origins)
    near = np.linalg.norm(points - origins, axis=1) <= 8.0
    expected = np.select([~finite, ~in_bounds, ~in_window, ~near],
                         [gk.POINT_NONFINITE, gk.POINT_OUTSIDE_EXTENT, gk.POINT_OUTSIDE_WINDOW,
                          gk.POINT_TOO_FAR], gk.POINT_OK)
    np.testing.assert_array_equal(cls, expected)


def reference_ray_cells(origin: np.ndarray, point: np.ndarray, res: float, z_min: float,
                        dz: float) -> dict[tuple[int, int], int]:
    """Cells (global ix, iy) a segment crosses with positive length, and its height bits there,
    by exact clipping of the segment against every cell of its bounding box."""
    corner = CONFIG.corner
    d = point - origin
    lo = np.floor((np.minimum(origin, point)[:2] - corner) / res).astype(int)
    hi = np.floor((np.maximum(origin, point)[:2] - corner) / res).astype(int)
    out = {}
    for ix in range(lo[0], hi[0] + 1):
        for iy in range(lo[1], hi[1] + 1):
            t0, t1 = 0.0, 1.0
            for axis, index in ((0, ix), (1, iy)):
                a, b = corner + index * res, corner + (index + 1) * res
                if d[axis] == 0.0:
                    if not a <= origin[axis] < b:
                        t0, t1 = 1.0, 0.0
                    continue
                ta, tb = sorted(((a - origin[axis]) / d[axis], (b - origin[axis]) / d[axis]))
                t0, t1 = max(t0, ta), min(t1, tb)
            if t1 - t0 > 1e-9:
                za, zb = sorted((origin[2] + d[2] * t0, origin[2] + d[2] * t1))
                out[(ix, iy)] = reference_mask(za, zb, z_min, dz)
    return out


def grid_seen(grid: HeightGrid) -> dict[tuple[int, int], int]:
    """Global (ix, iy) -> observed mask of every cell with a non-zero mask."""
    layers = grid.layers()
    ys, xs = np.nonzero(layers.seen)
    c = grid.config
    ix0 = round((layers.origin[0] - c.corner) / c.resolution)
    iy0 = round((layers.origin[1] - c.corner) / c.resolution)
    return {(ix0 + x, iy0 + y): int(layers.seen[y, x]) for y, x in zip(ys, xs, strict=True)}


@pytest.mark.parametrize("seed", range(6))
def test_ray_traversal_marks_exactly_the_crossed_cells_and_heights(seed):
    rng = np.random.default_rng(seed)
    origin = np.array([*rng.uniform(-2, 2, 2), rng.uniform(0.5, 1.5)])
    point = origin + np.array([*rng.uniform(-4, 4, 2), rng.uniform(-1.5, 0.3)])
    grid = HeightGrid(CONFIG)
    grid.insert(point[None], origin, 0.0)
    c = grid.config
    expected = reference_ray_cells(origin, point, c.resolution, c.z_min, c.mask_dz)
    got = grid_seen(grid)
    assert got == {cell: bits for cell, bits in expected.items() if bits}


@pytest.mark.parametrize("seed", range(4))
def test_collect_missing_tiles_lists_every_tile_a_ray_crosses(seed):
    """Each tile (8 cells of 5 cm) whose cells a ray crosses (exact clipping, as the
    insertion walks them) either has a slot or is listed, and nothing outside the ray's
    bounding box is: also where the walk is skipped, for rays within 2 x 2 tiles that
    all have slots. Short rays among a few missing tiles, one at a time: most take that
    shortcut."""
    res, cells = 0.05, 8
    rng = np.random.default_rng(seed)
    slots = np.arange(64, dtype=np.int32).reshape(8, 8)  # slots but for a few
    slots[rng.integers(0, 8, 6), rng.integers(0, 8, 6)] = -1
    shift = [CONFIG.corner, CONFIG.corner, 0.0]  # reference_ray_cells counts from there
    out = np.empty((64, 2), np.int64)
    for _ in range(300):
        point = np.array([*rng.uniform(0.5, 2.7, 2), 0.0])
        origin = point + [*rng.uniform(-0.45, 0.45, 2), 1.0]
        tile_index = slots.copy()
        count = gk.collect_missing_tiles(point[None], origin[None], np.zeros(1, np.uint8),
                                         tile_index, res, cells, 0.0, 0.0, out)
        listed = {(int(ty), int(tx)) for ty, tx in out[:count]}
        crossed = {(iy // cells, ix // cells) for ix, iy in
                   reference_ray_cells(origin + shift, point + shift, res, -1.0, 0.5)}
        lo = np.floor(np.minimum(point, origin)[:2] / (res * cells)).astype(int)
        hi = np.floor(np.maximum(point, origin)[:2] / (res * cells)).astype(int)
        box = {(ty, tx) for tx in range(lo[0], hi[0] + 1) for ty in range(lo[1], hi[1] + 1)}
        assert {t for t in crossed if slots[t] == -1} <= listed <= box
        assert all(slots[t] == -1 and tile_index[t] == -2 for t in listed)


def single_linkage(z: np.ndarray, gap: float) -> list[tuple[float, float]]:
    """Clusters of heights where neighbours (sorted) are within gap."""
    z = np.sort(z)
    cuts = np.flatnonzero(np.diff(z) > gap) + 1
    return [(part.min(), part.max()) for part in np.split(z, cuts)]


def test_hits_build_levels_like_the_reference_clustering():
    """Rows of cells, each hit by horizontal rays from far left at given heights; a first
    scan of rays passing through the cells at probe heights marks those heights seen free,
    so gaps with a probe (in a height bin strictly between two clusters) stay open and
    others close (single linkage, then consolidation); each level's mean hit height is
    the mean of its cluster's heights, through the merges."""
    config = GridConfig(extent=20.0, bundle_run=0, levels=4)
    grid = HeightGrid(config)
    res, gap = config.resolution, config.merge_gap
    rng = np.random.default_rng(7)
    rows = []
    for row in range(12):
        y = row * 0.5 + 0.0125
        clusters = np.sort(rng.choice([0.0, 0.3, 0.6, 0.9, 1.2], size=rng.integers(1, 4),
                                      replace=False))
        heights = np.concatenate([c + rng.uniform(0, 0.06, 5) for c in clusters])
        probes = rng.choice([0.15, 0.45, 0.75, 1.05], size=rng.integers(0, 3), replace=False)
        rows.append((y, heights, probes))
    x_cell = 2.0 + 0.025  # the test cell's centre
    passes = [(np.array([x_cell + 1.0, y, z]), np.array([-3.0, y, z]))
              for y, _, probes in rows for z in probes]
    if passes:
        ends, starts = map(np.array, zip(*passes, strict=True))
        grid.insert(ends, starts, 0.0)
    hits = np.array([[x_cell + rng.uniform(-0.02, 0.02), y, z] for y, heights, _ in rows
                     for z in heights])
    origins = np.column_stack([np.full(len(hits), -3.0), hits[:, 1], hits[:, 2]])
    grid.insert(hits, origins, 1.0)
    layers = grid.layers()
    ix = int(np.floor((x_cell - layers.origin[0]) / res))
    for y, heights, probes in rows:
        iy = int(np.floor((y - layers.origin[1]) / res))
        clusters = single_linkage(heights, gap)
        merged = [list(clusters[0])]
        for lo, hi in clusters[1:]:
            between = [p for p in probes if merged[-1][1] < p < lo]
            b_lo = int(np.floor((merged[-1][1] - config.z_min) / config.mask_dz)) + 1
            b_hi = int(np.floor((lo - config.z_min) / config.mask_dz)) - 1
            seen_bins = {int(np.floor((p - config.z_min) / config.mask_dz)) for p in between}
            if any(b_lo <= b <= b_hi for b in seen_bins):
                merged.append([lo, hi])
            else:
                merged[-1][1] = hi
        n = layers.nlev[iy, ix]
        got = layers.levels[iy, ix, :n, :2]
        np.testing.assert_allclose(got, np.array(merged), atol=1e-6)
        assert layers.counts[iy, ix, :n, 0].sum() == len(heights)
        means = [heights[(heights >= lo) & (heights <= hi)].mean() for lo, hi in merged]
        np.testing.assert_allclose(layers.levels[iy, ix, :n, gk.MZ], means, atol=1e-5)
        np.testing.assert_allclose(layers.levels[iy, ix, :n, gk.LOGODDS], config.l_hit)


def one_level_grid(lo: float, hi: float) -> tuple[HeightGrid, float]:
    """A grid whose cell at x = 2.025 holds one level [lo, hi] at full log-odds."""
    config = GridConfig(extent=20.0, bundle_run=0)
    grid = HeightGrid(config)
    hits = np.array([[2.025, 0.025, z] for z in np.arange(lo, hi + 1e-9, 0.02)])
    for stamp in range(6):
        grid.insert(hits, hits + [0.0, 0.0, 0.01], float(stamp))  # vertical, no clearing
    return grid, config.l_max


def level_at(grid: HeightGrid, x: float = 2.025, y: float = 0.025) -> np.ndarray:
    layers = grid.layers()
    iy = int(np.floor((y - layers.origin[1]) / grid.config.resolution))
    ix = int(np.floor((x - layers.origin[0]) / grid.config.resolution))
    return layers.levels[iy, ix, :layers.nlev[iy, ix]]


def test_ray_under_a_level_leaves_it_and_a_ray_through_its_middle_clears_it():
    grid, full = one_level_grid(0.72, 0.76)
    origin = np.array([0.0, 0.025, 0.70])
    grid.insert(np.array([[4.0, 0.025, 0.70]]), origin, 10.0)  # under it
    assert level_at(grid)[0, gk.LOGODDS] == pytest.approx(full)
    grid.insert(np.array([[4.0, 0.025, 0.74]]), origin + [0, 0, 0.04], 11.0)  # through it
    assert level_at(grid)[0, gk.LOGODDS] == pytest.approx(full - grid.config.l_miss)


def test_ray_through_a_level_not_hit_in_the_scan_takes_a_whole_miss():
    grid, full = one_level_grid(0.0, 1.0)
    grid.insert(np.array([[4.0, 0.025, 0.2]]), np.array([0.0, 0.025, 0.2]), 10.0)
    levels = level_at(grid)
    assert len(levels) == 1
    assert levels[0, gk.LOGODDS] == pytest.approx(full - grid.config.l_miss)


def test_ray_inside_a_level_hit_elsewhere_in_the_scan_splits_it():
    """The level was hit near its top in this scan and a ray passes at 0.2: the part below
    the ray (no hit in this scan) takes the miss, the part above keeps its confidence."""
    grid, full = one_level_grid(0.0, 1.0)
    top = np.array([[2.025, 0.025, 0.95]])
    points = np.vstack([top, [[4.0, 0.025, 0.2]]])
    origins = np.vstack([top + [0.0, 0.0, 0.01], [[0.0, 0.025, 0.2]]])
    grid.insert(points, origins, 10.0)
    levels = level_at(grid)
    assert len(levels) == 2
    assert levels[0, gk.HI] == pytest.approx(0.2) and levels[1, gk.LO] == pytest.approx(0.2)
    assert levels[0, gk.LOGODDS] == pytest.approx(full - grid.config.l_miss)
    assert levels[1, gk.LOGODDS] == pytest.approx(full)


def test_a_ray_through_the_height_bin_of_a_thin_level_clears_it():
    """A level of one height (a person's arm seen in one scan) is the height bin it lies
    in: a ray through that bin 4 mm above it passes it (issue 17: such levels were left
    standing because no ray hit their exact height), a ray in the next bin does not."""
    grid, full = one_level_grid(0.74, 0.74)  # bin [0.725, 0.75) of the 2.5 cm mask
    miss = grid.config.l_miss
    grid.insert(np.array([[4.0, 0.025, 0.755]]), np.array([0.0, 0.025, 0.755]), 10.0)
    assert level_at(grid)[0, gk.LOGODDS] == pytest.approx(full)  # the next bin up
    grid.insert(np.array([[4.0, 0.025, 0.744]]), np.array([0.0, 0.025, 0.744]), 11.0)
    assert level_at(grid)[0, gk.LOGODDS] == pytest.approx(full - miss)


def test_a_ray_into_the_top_or_bottom_of_a_level_not_hit_in_the_scan_trims_it_there():
    """Issue 17: a person's foot merged with the floor into one level [0, 0.16] m; a ray
    that enters it from above (0.17 to 0.15 m in the cell), not through its middle, shows
    its top free: the level ends where the ray left it, with its confidence (such levels
    stayed whole, and their cells obstacles, although later scans saw through every
    height of them). Likewise a ray rising into the bottom of a level [0.5, 0.88] (0.495 to
    0.505 m) raises its bottom. Both fail without the rule."""
    grid, full = one_level_grid(0.0, 0.16)
    grid.insert(np.array([[2.4, 0.025, 0.01]]), np.array([0.0, 0.025, 0.97]), 10.0)
    (level,) = level_at(grid)
    assert level[gk.LO] == pytest.approx(0.0) and level[gk.HI] == pytest.approx(0.15)
    assert level[gk.LOGODDS] == pytest.approx(full)
    grid, full = one_level_grid(0.5, 0.88)
    grid.insert(np.array([[2.4, 0.025, 0.575]]), np.array([0.0, 0.025, 0.095]), 10.0)
    (level,) = level_at(grid)
    assert level[gk.LO] == pytest.approx(0.505) and level[gk.HI] == pytest.approx(0.88)
    assert level[gk.LOGODDS] == pytest.approx(full)


@pytest.mark.parametrize("trimmed", [True, False])
def test_a_ray_into_the_top_of_a_level_hit_in_the_scan_trims_it_beyond_protect(trimmed):
    """The floor where a person stood, merged with the foot into one level [0, 0.16] m, is
    hit on the floor in every scan: a ray entering its top (0.17 to 0.15 m) more than
    `protect` above this scan's hits (the floor's, at 0 m) still shows that part free
    (such cells stayed obstacles for tens of scans in the people scene). A hit this scan
    within `protect` of the ray (half of it below) keeps it: occupied wins."""
    grid, full = one_level_grid(0.0, 0.16)
    hit_z = 0.0 if trimmed else 0.15 - 0.5 * GridConfig().protect
    hit = np.array([[2.025, 0.025, hit_z]])
    points = np.vstack([hit, [[2.4, 0.025, 0.01]]])
    origins = np.vstack([hit + [0.0, 0.0, 0.01], [[0.0, 0.025, 0.97]]])
    grid.insert(points, origins, 10.0)
    (level,) = level_at(grid)
    assert level[gk.LO] == pytest.approx(0.0)
    assert level[gk.HI] == pytest.approx(0.15 if trimmed else 0.16)
    assert level[gk.LOGODDS] == pytest.approx(full)


def face_grid(scans: int) -> HeightGrid:
    """A box's corner in the cell [2.0, 2.05] x [0, 0.05]: its face x = 2.033 (8 mm past the
    centre) from y = 0 to 0.01, 0.6-0.9 m high, hit in `scans` scans."""
    grid = HeightGrid(CONFIG)
    face = np.array([[2.033, y, z] for y in np.arange(0.0, 0.011, 0.0025)
                     for z in np.arange(0.6, 0.9, 0.02)])
    for stamp in range(scans):
        grid.insert(face, face + [0.0, 0.0, 0.01], float(stamp))  # vertical, no clearing
    return grid


def passes(grid: HeightGrid, y: float, scans: int) -> None:
    """One ray a scan at height 0.76 along x at `y`, through the face's cell to 4 m."""
    for k in range(scans):
        grid.insert(np.array([[4.0, y, 0.76]]), np.array([0.0, y, 0.76]), 100.0 + k)


@pytest.mark.parametrize(("seen", "y", "kept"), [
    (CONFIG.static_scans, 0.047, True),  # a wall: rays beside the face leave it
    (CONFIG.static_scans, 0.025, True),  # even through the cell's middle
    (CONFIG.static_scans, 0.005, False),  # a wall removed: rays where it was clear it
    (3, 0.047, False),  # a person: any ray through the cell clears it
])
def test_rays_beside_a_long_seen_face_leave_it(seen, y, kept):
    """Issue 17: where a face cuts a cell, rays through the cell's free part (here 2.0 cm
    or more from the face's mean hit) must not erode a wall or furniture;
    they still clear what was seen only briefly."""
    grid = face_grid(seen)
    assert len(level_at(grid, 2.025, 0.025)) == 1
    passes(grid, y, 20)
    assert (len(level_at(grid, 2.025, 0.025)) == 1) == kept


@pytest.mark.parametrize(("beside_wall", "y", "kept"), [
    (True, 0.097, True),  # the end of a wall seen longer next door: rays beside it leave it
    (True, 0.056, False),  # rays where its hits are clear it
    (False, 0.097, False),  # nothing static beside it (a person): any ray clears it
])
def test_rays_beside_a_face_seen_briefly_next_to_a_wall_leave_it(beside_wall, y, kept):
    """Issue 17 (people rooms 15 and 16: a cabinet's end or corner, hit in fewer scans
    than its long face beside it, cleared by rays through its cells' free part, its cells
    then FREE): a level hit in 3 scans in the cell [2.0, 2.05] x [0.05, 0.1] (its face at
    x = 2.033, y 0.05-0.06), next to a face at its heights hit in `static_scans` scans in
    the cell below, is passed only by rays within `pass_radius` of its mean hit, as the
    wall's own cells are."""
    grid = HeightGrid(CONFIG)
    wall = np.array([[2.033, y, z] for y in np.arange(0.0, 0.011, 0.0025)
                     for z in np.arange(0.6, 0.9, 0.02)])
    end = wall + [0.0, 0.05, 0.0]
    for stamp in range(CONFIG.static_scans):
        hits = [wall] if beside_wall else []
        hits += [end] if stamp < 3 else []
        if hits:
            points = np.vstack(hits)
            grid.insert(points, points + [0.0, 0.0, 0.01], float(stamp))  # no clearing
    assert len(level_at(grid, 2.025, 0.075)) == 1
    passes(grid, y, 20)
    assert (len(level_at(grid, 2.025, 0.075)) == 1) == kept


@pytest.mark.parametrize(("seen", "y", "trimmed"), [
    (CONFIG.static_scans, 0.047, False),  # a wall: rays into its top beside the face
    (CONFIG.static_scans, 0.005, True),  # a wall's top where its hits are
    (3, 0.047, True),  # seen briefly: trimmed from anywhere in the cell
])
def test_rays_into_the_top_of_a_long_seen_face_beside_it_leave_it(seen, y, trimmed):
    """A ray that enters the top of a face's level (0.91 to 0.89 m; the face 0.6-0.9 m)
    trims it only where a ray through it would clear it: not beside a wall's face."""
    grid = face_grid(seen)
    grid.insert(np.array([[2.4, y, 0.75]]), np.array([0.0, y, 1.71]), 100.0)
    (level,) = level_at(grid, 2.025, 0.025)
    assert level[gk.LO] == pytest.approx(0.6)
    assert level[gk.HI] == pytest.approx(0.89 if trimmed else 0.9, abs=1e-3)


FACE_YAW = np.radians(30.0)  # the face's direction: it cuts its cells diagonally
FACE_ALONG = np.array([np.cos(FACE_YAW), np.sin(FACE_YAW), 0.0])
FACE_ACROSS = np.array([-np.sin(FACE_YAW), np.cos(FACE_YAW), 0.0])
FACE_START = np.array([1.513, 0.007, 0.0])  # the face crosses a tile edge, x = 1.6 m


def slanted_face(config: GridConfig, corner: bool) -> tuple[HeightGrid, list, list]:
    """A face 0.3-0.6 m high along FACE_ALONG from FACE_START for 0.4 m, and with `corner`
    a second one from FACE_START along -FACE_ACROSS for 0.3 m (a cabinet's corner, its
    free side +FACE_ACROSS), hit in `static_scans` scans; and the centres of the cells
    the first face crosses, and of those both cross."""
    grid = HeightGrid(config)
    heights = np.arange(0.3, 0.61, 0.03)
    first = [FACE_START + s * FACE_ALONG for s in np.arange(0.0, 0.4, 0.002)]
    second = [FACE_START - s * FACE_ACROSS for s in np.arange(0.002, 0.3, 0.002)]
    face = np.array([p + [0.0, 0.0, z] for p in first + (second if corner else [])
                     for z in heights])
    for stamp in range(config.static_scans):
        grid.insert(face, face + [0.0, 0.0, 0.01], float(stamp))  # vertical, no clearing
    res = config.resolution

    def centres(points):
        return sorted({((np.floor(x / res) + 0.5) * res, (np.floor(y / res) + 0.5) * res)
                       for x, y, _ in points})

    return grid, centres(first), centres(face)


def face_cells_kept(grid: HeightGrid, cells: list[tuple[float, float]]) -> int:
    return sum(len(level_at(grid, x, y)) > 0 for x, y in cells)


@pytest.mark.parametrize(("angle", "corner"), [(0.0, False), (4.0, False), (0.0, True)])
def test_rays_grazing_a_slanted_face_leave_it_and_steep_rays_clear_it_once_gone(angle,
                                                                                 corner):
    """Issue 17 (a cabinet's end face eroded in `people_room(6)`, next to its corner):
    rays running along a face, 6 mm off it on its free side, pass within `pass_radius`
    of its cells' mean hits, which lie on the face; the face's direction, from the
    neighbouring cells' mean hits, shows them grazing it (within `graze_angle`): they
    leave every cell, also where the face meets another at a corner. Without the rule
    (graze_angle 0) they clear part of it: parallel to it, all but a cell; at 4 deg, the
    cells round where they cross its line (farther off, every static level round them
    lies on one side of the ray, as past a corner: `_kernels._past_corner`). Rays across
    it at 60 deg, one every 1 cm along it (so within 5 mm of each cell's mean hit), still
    clear it once it is gone."""
    turn = np.radians(angle)
    direction = np.cos(turn) * FACE_ALONG + np.sin(turn) * FACE_ACROSS
    middle = FACE_START + 0.2 * FACE_ALONG + 0.006 * FACE_ACROSS + [0.0, 0.0, 0.45]
    origin, end = middle - 1.0 * direction, middle + 3.0 * direction
    for graze_angle, kept in ((0.0, False), (GridConfig().graze_angle, True)):
        config = GridConfig(extent=20.0, bundle_run=0, graze_angle=graze_angle)
        grid, first, cells = slanted_face(config, corner)
        assert face_cells_kept(grid, cells) == len(cells) >= 10
        for k in range(20):
            grid.insert(end[None], origin[None], 100.0 + k)
        assert (face_cells_kept(grid, cells) == len(cells)) == kept
    steep = np.radians(60.0)
    across = np.cos(steep) * FACE_ALONG + np.sin(steep) * FACE_ACROSS
    crossings = [FACE_START + s * FACE_ALONG + [0.0, 0.0, 0.45] for s in np.arange(0.0, 0.4, 0.01)]
    origins = np.array([p - 1.0 * across for p in crossings])
    ends = np.array([p + 3.0 * across for p in crossings])
    for k in range(20):
        grid.insert(ends, origins, 200.0 + k)
    assert face_cells_kept(grid, first) == 0


@pytest.mark.parametrize("angle", [-1.0, 90.0, float("nan"), "10"])
def test_a_graze_angle_outside_0_to_90_degrees_is_refused(angle):
    with pytest.raises(MapError, match="graze_angle"):
        GridConfig(graze_angle=angle)


@pytest.mark.parametrize("distance", [-0.1, float("nan")])
def test_a_see_through_distance_below_0_is_refused(distance):
    with pytest.raises(MapError, match="see_through"):
        GridConfig(see_through=distance)


def legs_grid(scans: int) -> HeightGrid:
    """A person's legs, 0.1-0.3 m high, in the cell [2.0, 2.05] x [0, 0.05], hit in
    `scans` scans at y = 0.01 (their mean hit 1.5 cm off the cell's centre)."""
    grid = HeightGrid(CONFIG)
    legs = np.array([[2.025, 0.01, z] for z in np.arange(0.1, 0.31, 0.02)])
    for stamp in range(scans):
        grid.insert(legs, legs + [0.0, 0.0, 0.01], float(stamp))  # vertical, no clearing
    return grid


def floor_scans(grid: HeightGrid, y: float, scans: int, lasers: bool) -> None:
    """One floor hit a scan at (4, y), seen from a camera 1 m up at (0, y) (its ray
    crosses the legs' cell at 0.5 m, above them) and lit by a laser 0.5 m up (its ray
    crosses it at 0.25 m); `lasers`: the grid is told where the light came from."""
    for k in range(scans):
        grid.insert(np.array([[4.0, y, 0.0]]), np.array([0.0, y, 1.0]), 100.0 + k,
                    lasers=np.array([0.0, y, 0.5]) if lasers else None)


@pytest.mark.parametrize(("seen", "y", "lasers", "kept"), [
    (3, 0.01, True, False),  # the laser's rays cross where the person stood: cleared
    (3, 0.01, False, True),  # the camera's alone pass above
    (3, 0.045, True, True),  # the laser's rays pass 3.5 cm from its hits
    (CONFIG.static_scans, 0.01, True, True),  # furniture: the laser's rays leave it
])
def test_the_lasers_rays_clear_what_was_seen_briefly_near_its_hits(seen, y, lasers, kept):
    """Issue 17: where a person stood about 1 m from the robot, no later camera ray
    crossed the low heights of the cells it left, and they stayed obstacles; the laser's
    light, from below the camera, crossed them on its way to the floor beyond."""
    grid = legs_grid(seen)
    floor_scans(grid, y, 12, lasers)
    assert (len(level_at(grid, 2.025, 0.025)) == 1) == kept


@pytest.mark.parametrize(("face", "kept"), [(True, True), (False, False)])
def test_a_lasers_ray_along_a_face_seen_once_leaves_it(face, kept):
    """Issue 17 (people room 22: a cabinet's side hit in one scan, then passed by the
    laser's nearly level rays at 13 deg through the free part of the cells it cuts, 127
    wall cell-scans lost): a laser's ray that runs along a face read from the
    neighbouring cells' levels, however briefly seen, leaves it; one cell's level with
    no face beside it (a person's) is cleared by the same ray."""
    grid = HeightGrid(CONFIG)
    rows = np.arange(-0.2, 0.2, 0.01) if face else np.array([0.02, 0.03])
    hits = np.array([[2.04, y, z] for y in rows for z in np.arange(0.2, 0.3, 0.02)])
    grid.insert(hits, hits + [0.0, 0.0, 0.01], 0.0)  # vertical, no clearing
    along = np.array([np.sin(np.radians(13.0)), np.cos(np.radians(13.0))])
    emitter = np.array([*(np.array([2.04, 0.025]) - 2.0 * along), 0.5])
    end = np.array([*(np.array([2.04, 0.025]) + 2.0 * along), 0.0])
    for k in range(6):
        grid.insert(end[None], emitter + [0.0, 0.0, 0.5], 10.0 + k, lasers=emitter)
    assert (len(level_at(grid, 2.025, 0.025)) == 1) == kept


def test_a_lasers_ray_leaves_the_heights_it_crossed_unseen():
    """The observed mask is what the camera's rays showed (the segmentation's rules read
    it so): the laser's ray clears, the camera's ray alone marks heights seen."""
    grid = HeightGrid(CONFIG)
    floor_scans(grid, 0.025, 1, lasers=True)
    layers = grid.layers()
    iy, ix = (np.floor((np.array([0.025, 2.025]) - layers.origin[::-1]) / 0.05)).astype(int)
    seen = int(layers.seen[iy, ix])
    camera = int(gk.height_mask(0.49, 0.5, CONFIG.z_min, CONFIG.mask_dz))
    laser = int(gk.height_mask(0.244, 0.25, CONFIG.z_min, CONFIG.mask_dz))
    assert seen & camera == camera and seen & laser == 0


def test_one_walk_for_the_camera_and_an_emitter_under_it_is_the_two_walks():
    """The laser's rays from an emitter under the camera (the reference scanner's) are
    traced in the camera's rays' walk: cells and t are the same. Traced alone instead (an
    emitter just off the camera's x-y), every ray to its end: the same grid, level for
    level, over scans of people walking through a room."""
    model = reference_scanner()
    grids = [HeightGrid(CONFIG), HeightGrid(CONFIG)]
    for ideal in ideal_scans(builtin_scene("people"), model, scans=5):
        points, origins = scan_rays(ideal.scan, model, ideal.frame_poses)
        lasers = laser_origins(ideal.scan, model, ideal.frame_poses)
        assert np.array_equal(lasers[:, :2], origins[:, :2])  # the joint walk's case
        for grid, off in zip(grids, (0.0, 2 * gk.JOINT_XY), strict=True):
            grid.insert(points, origins, float(ideal.scan.time.max()),
                        lasers=lasers + [off, 0.0, 0.0])
    joint, apart = (grid.layers() for grid in grids)
    assert np.array_equal(joint.nlev, apart.nlev) and joint.nlev.sum() > 1000
    used = np.arange(CONFIG.levels) < joint.nlev[..., None]
    assert np.array_equal(joint.levels[used], apart.levels[used])
    assert np.array_equal(joint.counts[used], apart.counts[used])
    assert np.array_equal(joint.seen, apart.seen)


def test_misses_per_scan_are_capped():
    grid, full = one_level_grid(0.72, 0.76)
    many = np.array([[4.0, 0.025 + dy, 0.74] for dy in np.linspace(-0.02, 0.02, 10)])
    grid.insert(many, np.column_stack([np.zeros(10), many[:, 1], many[:, 2]]), 10.0)
    expected = full - grid.config.max_misses * grid.config.l_miss
    assert level_at(grid)[0, gk.LOGODDS] == pytest.approx(expected, abs=1e-6)


def test_absent_tiles_read_as_empty_and_never_updated():
    grid = HeightGrid(CONFIG)
    grid.insert(np.array([[1.0, 1.0, 0.0]]), np.array([1.0, 1.0, 1.0]), 0.0)
    layers = grid.layers((-8.0, -8.0, 8.0, 8.0))
    far = (slice(0, 10), slice(0, 10))
    assert (layers.nlev[far] == 0).all() and (layers.seen[far] == 0).all()
    assert np.isnan(layers.updated[far]).all()


def test_frame_rays_match_an_einsum_reference():
    """scan_rays with a pose per frame, against the per-point product of the pose, the head
    mount and the camera turned by the heading."""
    from scanmap.grid.rays import camera_centres, scan_rays
    from scanmap_driver.scan import Scan
    from scanmap_driver.scanner_model import reference_scanner
    from scanmap_driver.transforms import make_pose, rot_z

    rng = np.random.default_rng(8)
    model = reference_scanner()
    n, frames = 500, 7
    poses = np.array([make_pose(rot_z(a), rng.normal(0, 2, 3))
                      for a in rng.uniform(-3, 3, frames)])
    frame = rng.integers(0, frames, n)
    scan = Scan(points=rng.normal(0, 2, (n, 3)).astype(np.float32),
                colors=np.zeros((n, 3)), heading=rng.uniform(-np.pi, np.pi, n),
                frame_index=frame, time=np.sort(rng.uniform(0, 1, n)),
                range_sigma=np.full(n, 0.005))
    points, origins = scan_rays(scan, model, poses)
    rotate, shift = poses[frame, :3, :3], poses[frame, :3, 3]
    expected = np.einsum("nij,nj->ni", rotate, scan.points.astype(np.float64)) + shift
    centres = np.einsum("nij,nj->ni", rotate, camera_centres(model, scan.heading)) + shift
    assert np.allclose(points, expected, atol=1e-12) and np.allclose(origins, centres,
                                                                     atol=1e-12)


def test_usable_box_bounds_the_usable_rays_only():
    rng = np.random.default_rng(9)
    xy = rng.normal(0, 3, (300, 3))
    cls = rng.integers(0, 3, 300).astype(np.uint8)
    ok = xy[cls == gk.POINT_OK, :2]
    assert np.array_equal(gk.usable_box(xy, cls), np.r_[ok.min(axis=0), ok.max(axis=0)])
    assert np.isnan(gk.usable_box(xy, np.ones(300, np.uint8))).all()
