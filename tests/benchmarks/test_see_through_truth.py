"""The see-through truth of the people benchmark: the band's height bins a ray passes
through in each cell (`band_crossed`), against the closed form of a straight ray, and
those the map's levels hold (`band_held`), against interval overlap."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from benchmarks.bench_hazards import BAND_BIN, ROBOT, band_crossed, band_held, share_of_bits
from scanmap.grid.height_grid import CellLayers
from scanmap.navigation.floor import Segmentation

RES = 0.05


def window(nx: int = 60, ny: int = 8) -> Segmentation:
    """An empty segmentation window from the origin (only its geometry is used)."""
    shape = (ny, nx)
    return Segmentation(origin=(0.0, 0.0), resolution=RES, robot=ROBOT,
                        floor_height=np.zeros(shape, np.float32), is_floor=np.zeros(shape, bool),
                        planes=(), state=np.zeros(shape, np.uint8),
                        points=np.zeros(shape + (2,), np.float32),
                        band_logodds=np.zeros(shape, np.float32), updated=np.zeros(shape))


def closed_form(x0: float, z0: float, x1: float, z1: float, nx: int) -> np.ndarray:
    """Per cell along x: the bins of heights the segment (x0, z0)-(x1, z1) spans there."""
    bins = round((ROBOT.height - ROBOT.step_height) / BAND_BIN)
    out = np.zeros(nx, np.uint64)
    for col in range(nx):
        a, b = max(col * RES, x0), min((col + 1) * RES, x1)
        if a >= b:
            continue
        za, zb = sorted(z0 + (np.array([a, b]) - x0) / (x1 - x0) * (z1 - z0))
        lo = max(int(np.floor((za - ROBOT.step_height) / BAND_BIN)), 0)
        hi = min(int(np.floor((zb - ROBOT.step_height) / BAND_BIN)), bins - 1)
        for level in range(lo, hi + 1):
            out[col] |= np.uint64(1) << np.uint64(level)
    return out


@settings(max_examples=40, deadline=None)
@given(z0=st.floats(0.9, 1.0), z1=st.floats(0.0, 0.5), length=st.floats(1.0, 2.9))
def test_a_descending_ray_crosses_the_bins_of_its_heights_in_each_cell(z0, z1, length):
    """Away from the ends (where a bin is cut short of the 1 cm sampling step), every cell
    holds exactly the bins the straight ray spans there."""
    x0, y = 0.012, 0.125
    seg = window()
    mask = band_crossed(np.array([[x0 + length, y, z1]]), np.array([[x0, y, z0]]), seg)
    row = int(y / RES)
    assert not np.delete(mask, row, axis=0).any()  # no other row of cells
    truth = closed_form(x0, z0, x0 + length, z1, seg.shape[1])
    for col in range(1, int((x0 + length) / RES) - 1):
        got, want = int(mask[row, col]), int(truth[col])
        assert got & ~want == 0  # never a bin the ray did not span
        # a bin the ray crosses wholly in the cell spans >= 2.5 cm of it (slope <= 1), so
        # the 1 cm samples find it; the first and last may be cut short
        spanned = [b for b in range(64) if want >> b & 1]
        inner = sum(1 << b for b in spanned[1:-1])
        assert got & inner == inner


def test_a_horizontal_ray_above_the_band_crosses_nothing_and_shares_are_counted():
    seg = window()
    above = band_crossed(np.array([[2.5, 0.2, 1.2]]), np.array([[0.0, 0.2, 1.2]]), seg)
    assert not above.any()
    inside = band_crossed(np.array([[2.5, 0.2, 0.5]]), np.array([[0.0, 0.2, 0.5]]), seg)
    level = int((0.5 - ROBOT.step_height) / BAND_BIN)
    assert (inside[4, :49] == np.uint64(1) << np.uint64(level)).all()
    bins = round((ROBOT.height - ROBOT.step_height) / BAND_BIN)
    share = share_of_bits(np.array([0, 1, (1 << bins) - 1], np.uint64), bins)
    np.testing.assert_allclose(share, [0.0, 1.0 / bins, 1.0])


@settings(max_examples=60, deadline=None)
@given(spans=st.lists(st.tuples(st.floats(-0.3, 1.3), st.floats(0.0, 0.6)), min_size=3,
                      max_size=3),
       used=st.integers(0, 3))
@example(spans=[(1.0, 0.0), (0.0, 0.0), (0.0, 0.0)], used=1)  # on a bin's edge: (1.0 -
# 0.05) / 0.025 is 37.99999999999999, and the bin below it was taken as held
def test_the_bins_a_cell_holds_are_those_its_levels_in_use_overlap(spans, used):
    """A level [lo, hi] holds bin b when it overlaps [step + b * BAND_BIN, step + (b + 1) *
    BAND_BIN); levels past nlev and heights outside the band hold nothing."""
    levels = np.zeros((1, 1, 3, 5), np.float32)
    for k, (lo, thickness) in enumerate(spans):
        levels[0, 0, k, :2] = lo, lo + thickness
    layers = CellLayers(origin=(0.0, 0.0), resolution=RES, z_min=-0.35, mask_dz=0.025,
                        levels=levels, counts=np.zeros((1, 1, 3, 2), np.uint32),
                        nlev=np.array([[used]], np.uint8), seen=np.zeros((1, 1), np.uint64),
                        updated=np.zeros((1, 1)))
    bins = round((ROBOT.height - ROBOT.step_height) / BAND_BIN)
    want = 0
    for lo, hi in levels[0, 0, :used, :2].astype(float):
        for b in range(bins):
            bottom = ROBOT.step_height + b * BAND_BIN
            if lo < bottom + BAND_BIN and hi >= bottom:
                want |= 1 << b
    assert int(band_held(layers)[0, 0]) == want
