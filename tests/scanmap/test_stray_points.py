"""Lone points below the floor (`scanmap.mapping.stray_points`): the compiled search
against a plain one, and the Mapper leaving them out of the grid."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.grid import _kernels as gk
from scanmap.mapping import Mapper
from scanmap.mapping import mapper as mapper_module
from scanmap.mapping.stray_points import lone_low_points
from scanmap_driver import reference_scanner
from scanmap_driver.scan import Scan
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.transforms import transform_points


def scan_of(points: np.ndarray, frames: np.ndarray) -> Scan:
    n = len(points)
    return Scan(points=points, colors=np.zeros((n, 3), np.uint8), time=frames * 0.02,
                heading=frames * 0.1, frame_index=frames, range_sigma=np.full(n, 0.01))


def plain(points: np.ndarray, frames: np.ndarray, depth: float, radius: float) -> np.ndarray:
    """Every pair of points compared: the reference."""
    gap = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    near = (gap <= radius) & (frames[:, None] == frames[None, :])
    np.fill_diagonal(near, False)
    return (points[:, 2] < -depth) & ~near.any(axis=1)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 60), frames=st.integers(1, 4),
       radius=st.floats(0.01, 0.3))
def test_it_matches_the_plain_search_in_any_order(seed, n, frames, radius):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.3, 0.3, (n, 3)).astype(np.float32)
    frame = rng.integers(0, frames, n).astype(np.int32)
    expected = plain(points.astype(np.float64), frame, 0.05, radius)
    assert np.array_equal(lone_low_points(scan_of(points, frame), 0.05, radius), expected)
    order = rng.permutation(n)
    assert np.array_equal(lone_low_points(scan_of(points[order], frame[order]), 0.05, radius),
                          expected[order])


def test_a_run_along_the_stripe_stays_and_a_lone_point_goes():
    # A far wall's top 10 cm down, seen along the stripe (points 7 mm apart); a lone
    # point 8 cm down 27 cm past the floor's last point; a lone point above the floor;
    # a point 8 cm down whose only neighbour lies in the next frame
    wall = np.column_stack([np.full(20, 3.0), np.arange(20) * 0.007, np.full(20, -0.1)])
    floor = np.array([[2.0, 0.0, 0.0], [2.0, 0.007, 0.0]])
    points = np.vstack([wall, floor, [[2.27, 0.0, -0.08]], [[1.0, 1.0, 0.5]],
                        [[1.5, -1.0, -0.08]], [[1.5, -1.01, -0.08]]]).astype(np.float32)
    frames = np.array([0] * 23 + [0, 0, 1], np.int32)
    lone = lone_low_points(scan_of(points, frames), 0.05, 0.05)
    assert np.flatnonzero(lone).tolist() == [22, 24, 25]


def test_the_mapper_leaves_a_lone_point_below_the_floor_out_of_the_grid(monkeypatch):
    # One point 8 cm below the office's floor, 27 cm past a floor point of the last scan
    # (as a peak thrown off the stripe at an edge lands): the grid keeps no level below
    # the floor in its cell; with the filter off (the control) it does
    scans = [ideal.scan for ideal in ideal_scans(builtin_scene("office"), seed=3, scans=2)]
    last = scans[-1]
    floor = np.flatnonzero((np.abs(last.points[:, 2]) < 0.01)
                           & (np.hypot(last.points[:, 0], last.points[:, 1]) > 2.5))[0]
    p = last.points[floor].astype(np.float64)
    stray = p + np.array([*(0.27 * p[:2] / np.hypot(p[0], p[1])), -0.08])
    take = np.append(np.arange(len(last)), floor)
    moved = Scan(points=np.vstack([last.points, stray[None]]), colors=last.colors[take],
                 time=last.time[take], heading=last.heading[take],
                 frame_index=last.frame_index[take], range_sigma=last.range_sigma[take],
                 index=last.index, stamp=last.stamp, odom_start=last.odom_start,
                 odom_end=last.odom_end)

    def lowest_at_stray(mapper: Mapper) -> float:
        at = transform_points(mapper.trajectory().poses[-1], stray[None])[0]
        layers = mapper.grid.layers((at[0] - 0.01, at[1] - 0.01, at[0] + 0.01, at[1] + 0.01))
        levels = layers.levels[..., 0, gk.LO][layers.nlev > 0]
        return float(levels.min()) if levels.size else np.inf

    filtered = Mapper(reference_scanner(), offline=True)
    filtered.map_scans([scans[0], moved])
    assert lowest_at_stray(filtered) > -0.05
    monkeypatch.setattr(mapper_module, "lone_low_points",
                        lambda scan, depth, radius: np.zeros(len(scan), bool))
    unfiltered = Mapper(reference_scanner(), offline=True)
    unfiltered.map_scans([scans[0], moved])
    assert lowest_at_stray(unfiltered) < -0.05
