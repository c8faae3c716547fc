"""What a grid keeps per scan over a long run: `GrowingArray` against numpy's
concatenation, the places stood read back in a window, and a patrol's places."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.grid.growing import GrowingArray
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.navigation.floor.segmentation import _footprint_cells

chunks = st.lists(st.integers(0, 40), max_size=30)


@settings(max_examples=50, deadline=None)
@given(chunks)
def test_rows_appended_read_as_their_concatenation(sizes):
    rng = np.random.default_rng(len(sizes))
    parts = [rng.normal(size=(n, 2)) for n in sizes]
    grown = GrowingArray(np.zeros((0, 2)))
    views = []
    for part in parts:
        grown.extend(part)
        views.append(grown.array)
    expected = np.concatenate([np.zeros((0, 2)), *parts])
    assert len(grown) == len(expected)
    np.testing.assert_array_equal(grown.array, expected)
    for view, end in zip(views, np.cumsum(sizes), strict=True):  # later appends leave it
        np.testing.assert_array_equal(view, expected[:end])


def test_one_dimensional_rows_copies_and_bad_rows():
    times = GrowingArray(np.array([np.nan]))
    for t in range(100):
        times.append(float(t))
    copy = times.copy()
    times.append(100.0)
    assert len(copy) == 101 and len(times) == 102
    np.testing.assert_array_equal(times.array[1:], np.arange(101.0))
    with pytest.raises(ValueError, match="shape"):
        GrowingArray(np.zeros((0, 2))).extend(np.zeros((3, 3)))
    with pytest.raises(ValueError):
        times.array[0] = 1.0  # a read-only view: the rows change only by appending


def test_a_long_runs_window_holds_only_the_places_stood_inside_it():
    """After a long run, the window's `stood` holds exactly the places inside it and its
    cells' update times are their scans' (what the grid kept per scan, read back)."""
    grid = HeightGrid(GridConfig(extent=50.0))
    places = []
    for k in range(300):
        x = 0.4 * (k % 50)
        path = np.column_stack([np.linspace(x, x + 0.4, 9), np.zeros(9)])  # 5 cm apart
        grid.insert(np.array([[x + 1.0, 0.5, 0.0]]), np.array([x, 0.0, 1.0]), 10.0 + k,
                    stood=path)
        places.append(path)
    layers = grid.layers((2.0, -2.0, 6.0, 2.0))
    every = np.unique(np.concatenate(places), axis=0)
    inside = every[(every[:, 0] >= 2.0) & (every[:, 0] < 6.0)]
    np.testing.assert_array_equal(np.unique(layers.stood.round(9), axis=0),
                                  np.unique(inside.round(9), axis=0))  # a path's end is the
    # next one's start, but for the rounding of 0.4 * k
    crossing = [k for k in range(300) if 0.4 * (k % 50) < 6.0 and 0.4 * (k % 50) + 1.0 >= 2.0]
    assert np.nanmax(layers.updated) == 10.0 + max(crossing)  # the last ray through it


def test_a_patrol_adds_places_stood_with_the_area_not_with_the_passes():
    """A robot driving the same 4 m fifty times, its path a few mm off each time, keeps
    a place per quarter-cell bin its paths crossed, not each pass's places, and its
    footprint covers the cells the footprints of every place passed cover but for a few
    on its rim."""
    rng = np.random.default_rng(7)
    grids = {passes: HeightGrid(GridConfig(extent=50.0)) for passes in (1, 50)}
    every = []
    for passes, grid in grids.items():
        for k in range(passes):
            path = np.column_stack([np.linspace(0.0, 4.0, 161), np.zeros(161)])
            path += rng.normal(0.0, 0.003, path.shape) if k else 0.0
            grid.insert(np.array([[5.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), float(k),
                        stood=path)
            every.append(path) if passes == 50 else None
    one, many = (grid.layers((-1.0, -1.0, 5.0, 1.0)) for grid in grids.values())
    passed_places = sum(len(path) for path in every)  # 8,050
    assert len(one.stood) > 90 and len(many.stood) <= 0.1 * passed_places
    kept = _footprint_cells(many, 0.25)
    passed = _footprint_cells(replace(many, stood=np.concatenate(every)), 0.25)
    assert (kept <= passed).all() and (passed & ~kept).sum() <= 0.03 * passed.sum()
