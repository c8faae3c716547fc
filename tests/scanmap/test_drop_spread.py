"""How far a drop-off spreads through the unlit cells round the cells that show it
(`morphology.dilate_in_range`): against ndimage and a plain level-by-level search, and on
the simulator's `hazards` scene, beyond a hole seen from one side, and beside a pit the
robot passed nearer than the scanner sees the floor."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage

from benchmarks.bench_hazards import ROBOT, hazard_run, mapped, truth_classes
from benchmarks.random_rooms import mixed_room
from scanmap.navigation import DROP_OFF, morphology
from scanmap.navigation.floor._drop_offs import _shadow_share
from scanmap_driver.sim import RASTER_FLOOR, builtin_scene, truth_raster

SQUARE = np.ones((3, 3), bool)
shapes = st.tuples(st.integers(1, 30), st.integers(1, 30))


def spread_reference(seeds, within, ranges, low, high, steps):
    """`dilate_in_range` level by level: a cell of `within` joins at the first depth where
    a neighbour reached at the depth before holds its range in its bounds, and takes the
    widest bounds of all such neighbours."""
    ny, nx = seeds.shape
    out = seeds.copy()
    lows = np.where(seeds, low, np.nan)
    highs = np.where(seeds, high, np.nan)
    front = seeds.copy()
    for _ in range(steps):
        new = np.zeros_like(seeds)
        new_low = np.full(seeds.shape, np.inf)
        new_high = np.full(seeds.shape, -np.inf)
        for y, x in zip(*np.nonzero(front), strict=True):
            for yy in range(max(y - 1, 0), min(y + 2, ny)):
                for xx in range(max(x - 1, 0), min(x + 2, nx)):
                    if out[yy, xx] or not within[yy, xx]:
                        continue
                    if lows[y, x] <= ranges[yy, xx] <= highs[y, x]:
                        new[yy, xx] = True
                        new_low[yy, xx] = min(new_low[yy, xx], lows[y, x])
                        new_high[yy, xx] = max(new_high[yy, xx], highs[y, x])
        out |= new
        lows[new], highs[new] = new_low[new], new_high[new]
        front = new
    return out


@settings(max_examples=60, deadline=None)
@given(data=st.data(), steps=st.integers(1, 12))
def test_unbounded_it_is_the_geodesic_dilation(data, steps):
    seeds = data.draw(arrays(np.bool_, shapes))
    within = data.draw(arrays(np.bool_, seeds.shape))
    ranges = np.zeros(seeds.shape, np.float32)
    assert np.array_equal(
        morphology.dilate_in_range(seeds, within, ranges, ranges - 1.0, ranges + 1.0, steps),
        ndimage.binary_dilation(seeds, SQUARE, iterations=steps, mask=within))


@settings(max_examples=80, deadline=None)
@given(data=st.data(), steps=st.integers(1, 8))
def test_it_matches_the_plain_search(data, steps):
    seeds = data.draw(arrays(np.bool_, shapes))
    within = data.draw(arrays(np.bool_, seeds.shape, elements=st.booleans()))
    ranges = data.draw(arrays(np.float32, seeds.shape, elements=st.integers(0, 6)))
    below = data.draw(arrays(np.float32, seeds.shape, elements=st.integers(0, 3)))
    above = data.draw(arrays(np.float32, seeds.shape, elements=st.integers(0, 3)))
    low, high = ranges - below, ranges + above
    assert np.array_equal(morphology.dilate_in_range(seeds, within, ranges, low, high, steps),
                          spread_reference(seeds, within, ranges, low, high, steps))


@settings(max_examples=80, deadline=None)
@given(data=st.data(), steps=st.integers(1, 10), right=st.floats(0.0, 5.0),
       left=st.floats(0.0, 5.0) | st.none())
def test_from_one_seed_it_keeps_to_the_seeds_line_of_sight(data, steps, right, left):
    """One seed seen from one cell: the plain search through the cells of `within` no
    farther than `right` to the right of the line through the two and `left` to its left
    (`right` both ways without `left`; closed form: the cross product over the line's
    length, positive to the left looking from the cell it was seen from)."""
    ny, nx = data.draw(shapes)
    within = data.draw(arrays(np.bool_, (ny, nx)))
    ranges = data.draw(arrays(np.float32, (ny, nx), elements=st.integers(0, 6)))
    sy, sx = data.draw(st.integers(0, ny - 1)), data.draw(st.integers(0, nx - 1))
    py, px = data.draw(st.integers(0, ny - 1)), data.draw(st.integers(0, nx - 1))
    seeds = np.zeros((ny, nx), bool)
    seeds[sy, sx] = True
    low, high = ranges - 2.0, ranges + 2.0
    y, x = np.mgrid[:ny, :nx]
    length = np.sqrt(float((sy - py) ** 2 + (sx - px) ** 2))
    off = ((sx - px) * (y - py) - (sy - py) * (x - px)) / length if length else 0 * y
    viewed_from = np.full((ny, nx), py * nx + px, np.int64)
    lateral = right if left is None else (right, left)
    bounded = (-right <= off) & (off <= (right if left is None else left))
    assert np.array_equal(
        morphology.dilate_in_range(seeds, within, ranges, low, high, steps, viewed_from,
                                   lateral),
        spread_reference(seeds, within & bounded, ranges, low, high, steps))


@settings(max_examples=80, deadline=None)
@given(data=st.data(), steps=st.integers(1, 10), right=st.floats(0.0, 5.0),
       left=st.floats(0.0, 5.0), share=st.floats(0.0, 1.0), above=st.sampled_from([0.0, 0.5]))
def test_a_seed_seen_from_no_cell_keeps_to_a_place_in_reach(data, steps, right, left, share,
                                                             above):
    """One seed seen from no cell, with places it may have been seen from: the plain
    search through the cells of `within` that one of the places `nearest` to `farthest`
    cells off the seed puts within the seed's bounds from it (its share of the seed's
    range less a cell to that range and `above`) and within `right` and `left` of its line
    of sight through the seed (closed form); with none that far off, through those in the
    seed's own bounds. Where the place it was seen from is known (`own`, anywhere, in the
    window or not), that place alone, at any distance. Every cell reached came from it."""
    ny, nx = data.draw(shapes)
    within = data.draw(arrays(np.bool_, (ny, nx)))
    ranges = data.draw(arrays(np.float32, (ny, nx), elements=st.integers(0, 6)))
    sy, sx = data.draw(st.integers(0, ny - 1)), data.draw(st.integers(0, nx - 1))
    count = data.draw(st.integers(0, 4))
    places = np.column_stack([data.draw(arrays(np.int64, count, elements=st.integers(
        0, size - 1))) for size in (ny, nx)]).astype(np.float64).reshape(count, 2)
    nearest = data.draw(st.floats(0.0, 8.0))
    farthest = nearest + data.draw(st.floats(0.0, 12.0))
    own = np.full((ny, nx, 2), np.nan)
    if data.draw(st.booleans()):
        own[sy, sx] = [data.draw(st.integers(-6, ny + 6)), data.draw(st.integers(-6, nx + 6))]
    seeds = np.zeros((ny, nx), bool)
    seeds[sy, sx] = True
    shares = np.full((ny, nx), 2.0)  # only the seed's share counts
    shares[sy, sx] = share
    low, high = ranges - 2.0, ranges + 2.0
    y, x = np.mgrid[:ny, :nx]
    allowed, in_reach = np.zeros((ny, nx), bool), False
    known = np.isfinite(own[sy, sx, 0])
    for py, px in own[sy, sx][None] if known else places:
        reach = np.sqrt((sy - py) * (sy - py) + (sx - px) * (sx - px))
        if not ((known or nearest <= reach <= farthest) and reach > 0.0):
            continue
        in_reach = True
        there = np.sqrt((y - py) * (y - py) + (x - px) * (x - px))
        side = ((sx - px) * (y - py) - (sy - py) * (x - px)) / reach
        allowed |= (share * reach - 1.0 <= there) & (there <= reach + above) \
            & (-right <= side) & (side <= left)
    expected = spread_reference(seeds, within & allowed, ranges, low - np.inf,
                                high + np.inf, steps) if in_reach \
        else spread_reference(seeds, within, ranges, low, high, steps)
    elsewhere = morphology.Viewpoints(places, nearest, farthest, shares, above, own)
    sources = np.empty((ny, nx), np.int64)
    out = morphology.dilate_in_range(seeds, within, ranges, low, high, steps,
                                     np.full((ny, nx), -1, np.int64), (right, left), elsewhere,
                                     sources)
    assert np.array_equal(out, expected)
    assert np.array_equal(sources, np.where(out, sy * nx + sx, -1))


def test_the_rims_shadow_is_as_deep_as_the_lasers_light_over_the_rim_leaves_it():
    # Light from 0.5 m up over a rim at range r reaches d below the floor at (0.5 + d) /
    # 0.5 r: the rim lies at 0.5 / (0.5 + d) of the range of what it lit there, d the
    # deepest a cell shows (its lowest level's bottom, or the lowest bin seen free)
    floor = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.115])
    nlev = np.array([1, 0, 2, 0, 1, 0])
    bottom = np.array([-0.268, 0.0, -0.1, 0.0, 0.02, 0.0])  # no level: the window's zeros
    lowest_free = np.array([-np.inf, -0.2, -0.3, -np.inf, 0.1, 0.015])
    share = _shadow_share(floor, nlev, bottom, lowest_free, 0.5)
    assert np.allclose(share, [0.5 / 0.768, 0.5 / 0.7, 0.5 / 0.8, 1.0, 1.0, 0.5 / 0.6])


def test_a_pit_passed_nearer_than_the_scanner_sees_spreads_no_farther_than_seen():
    # Fresh mixed room 5017 at 0.3 px: the robot passed 1.07 m from its pit's corner,
    # nearer than the floor the scanner sees (`blind_range`), and from there the corner's
    # spread had no line of sight: it ran over the unlit floor towards the path, 2.04
    # cells past the true edge after the last scan
    run = hazard_run(scene=mixed_room(5017), pixel_sigma=0.3)
    assert run["edge_error_cells"] <= 1.0
    assert run["drop_free_any_scan"] == 0


def test_the_floor_beyond_a_hole_seen_from_one_side_is_never_a_drop_off():
    # The first scan of `hazards`, from 1.4 m before the stairwell's near corner: the
    # floor behind the hole is lit along the laser's lines only, and the gaps between
    # them beyond its far wall used to be DROP_OFF (the drop-off spread into them from
    # the wall's hits)
    scene = builtin_scene("hazards")
    raster = truth_raster(scene, low=ROBOT.step_height, high=ROBOT.height)
    step = next(mapped(scene, 1))
    seg = step.seg
    xs, ys = (seg.origin[axis] + (np.arange(seg.shape[1 - axis]) + 0.5) * seg.resolution
              for axis in (0, 1))
    robot = step.ideal.pose_start[:2, 3]
    ranges = np.hypot(xs[None, :] - robot[0], ys[:, None] - robot[1])
    well = next(r for r in scene.floor_regions if r.name == "stairwell")
    inside = well.contains(*np.meshgrid(xs, ys))
    # Farther than the hole by more than two cells: the spread may pass its wall's hits
    # by a cell, and ranges are measured from the centre of the cell the robot stood in
    apart = ndimage.distance_transform_edt(~inside) * seg.resolution
    beyond = (apart <= 1.0) & (ranges > ranges[inside].max() + 2 * seg.resolution)
    floor = truth_classes(seg, raster) == RASTER_FLOOR
    assert (beyond & floor & seg.is_floor).sum() > 50  # the floor there is seen
    assert not (beyond & floor & (seg.state == DROP_OFF)).any()
