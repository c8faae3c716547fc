"""The scan-context descriptor: the same place turned is the same place, at the turn."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap.graph import compare, describe
from scanmap_driver.transforms import se2_to_pose, transform_points


def room(seed: int) -> np.ndarray:
    """Points of a furnished room around the robot: four walls and random boxes' sides."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(-1.0, 1.0, 4000)
    one = np.ones_like(t)
    walls = np.concatenate([np.c_[t * 6, 4 * one], np.c_[t * 6, -3 * one],
                            np.c_[6 * one, t * 4], np.c_[-5 * one, t * 4]])
    boxes = [c + rng.uniform(-0.4, 0.4, (300, 2)) for c in rng.uniform(-4.0, 4.0, (6, 2))]
    xy = np.concatenate([walls, *boxes])
    z = rng.uniform(0.0, 1.5, len(xy))
    return np.c_[xy, z]


@pytest.mark.parametrize("sectors_turned", [0, 1, 17, 30, 59])
def test_turned_by_whole_sectors_same_place_and_the_turn(sectors_turned):
    points = room(0)
    yaw = 2 * np.pi * sectors_turned / 60
    # The robot turned by +yaw sees every point turned by -yaw.
    turned = transform_points(np.linalg.inv(se2_to_pose(0.0, 0.0, yaw)), points)
    a, b = describe(turned, sectors=60), describe(points, sectors=60)
    distance, found = compare(a, b)
    assert distance < 0.02
    assert abs(np.angle(np.exp(1j * (found - yaw)))) < 1e-9
    np.testing.assert_allclose(a.ring_key, b.ring_key, atol=0.02)


@pytest.mark.parametrize("yaw", [0.3, -1.234, 2.9])
def test_any_turn_is_found_within_a_sector_and_beats_another_room(yaw):
    points = room(1)
    turned = transform_points(np.linalg.inv(se2_to_pose(0.0, 0.0, yaw)), points)
    here, there = describe(points), describe(room(2))
    distance, found = compare(describe(turned), here)
    assert abs(np.angle(np.exp(1j * (found - yaw)))) <= 2 * np.pi / 60
    assert distance < compare(describe(turned), there)[0]
