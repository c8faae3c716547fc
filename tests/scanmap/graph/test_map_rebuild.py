"""`rebuild_grid` (tiles reserved at once, a base map) against plain insertion scan by scan."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.mapping.mapper import rebuild_grid
from scanmap_driver.transforms import se2_to_pose, transform_points


def kept_rays(ring_ideal: list) -> tuple[np.ndarray, list]:
    """Poses off the truth by a drift, and each scan's points (every 7th) from 0.3 m up;
    one scan not fused (None)."""
    poses = np.array([s.pose_start @ se2_to_pose(0.01 * k, 0.0, 0.002 * k)
                      for k, s in enumerate(ring_ideal)])
    kept = [(s.scan.points[::7].astype(np.float32),
             np.broadcast_to(np.float32([0.0, 0.0, 0.3]), s.scan.points[::7].shape),
             float(s.scan.stamp)) for s in ring_ideal]
    kept[3] = None
    return poses, kept


def plain(grid: HeightGrid, poses: np.ndarray, kept: list) -> HeightGrid:
    """The reference: every scan inserted in order by `HeightGrid.insert`."""
    if grid.config.window is not None:
        grid.recenter(float(poses[-1][0, 3]), float(poses[-1][1, 3]))
    for pose, k in zip(poses, kept, strict=True):
        if k is not None:
            grid.insert(transform_points(pose, k[0]), transform_points(pose, k[1]), k[2])
    return grid


@pytest.mark.parametrize("window", [None, 12.0])
def test_rebuild_equals_plain_insertion(ring_ideal, window):
    config = GridConfig(window=window)
    poses, kept = kept_rays(ring_ideal)
    fast = rebuild_grid(config, poses, kept)
    reference = plain(HeightGrid(config), poses, kept)
    assert fast.tile_count == reference.tile_count > 0
    assert_same(fast, reference)


def test_rebuild_from_a_base_map_equals_plain_insertion_onto_it(ring_ideal):
    config = GridConfig()
    poses, kept = kept_rays(ring_ideal)
    base = plain(HeightGrid(config), poses[:10], kept[:10])
    fast = rebuild_grid(config, poses[10:], kept[10:], base.state())
    assert_same(fast, plain(base, poses[10:], kept[10:]))


def assert_same(a: HeightGrid, b: HeightGrid) -> None:
    assert a.bounds() == b.bounds()
    la, lb = a.layers(), b.layers()
    for name in ("levels", "counts", "nlev", "seen", "updated"):
        np.testing.assert_array_equal(getattr(la, name), getattr(lb, name), err_msg=name)
