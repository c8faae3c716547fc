"""ObstacleMap.travel: how far the robot's circle can drive ahead before it touches a cell not
known free, against a brute-force sweep and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.navigation import _kernels as nk
from scanmap.navigation.floor import DROP_OFF, FREE, OBSTACLE, UNKNOWN, RobotShape, Segmentation
from scanmap.navigation.obstacles import ObstacleMap, ObstacleSnapshot, QueryStatus
from scanmap_driver.errors import MapError

RES = 0.05
ROBOT = RobotShape(radius=0.25)


def obstacle_map(state: np.ndarray, origin=(-1.0, -1.0), clock=lambda: 0.0) -> ObstacleMap:
    ny, nx = state.shape
    seg = Segmentation(origin=origin, resolution=RES, robot=ROBOT,
                       floor_height=np.zeros((ny, nx), np.float32), is_floor=state == FREE,
                       planes=(), state=state, points=np.zeros((ny, nx, 2), np.float32),
                       band_logodds=np.zeros((ny, nx), np.float32), updated=np.zeros((ny, nx)))
    obstacles = ObstacleMap(ROBOT, max_age=1.0, clock=clock)
    obstacles.publish(ObstacleSnapshot.from_segmentation(seg, 0.0))
    return obstacles


def swept_reference(state, origin, x, y, yaw, radius, max_distance, step=1e-3):
    """The first t on a `step` grid at which the disc moved t along yaw overlaps a square
    not FREE (cells beyond the window: UNKNOWN), max_distance if none."""
    pad = math.ceil((max_distance + 2 * radius) / RES) + 2
    padded = np.pad(state, pad, constant_values=UNKNOWN)
    iy, ix = np.nonzero(padded != FREE)
    x0 = origin[0] + (ix - pad) * RES
    y0 = origin[1] + (iy - pad) * RES
    for t in np.arange(0.0, max_distance + step / 2, step):
        cx, cy = x + t * math.cos(yaw), y + t * math.sin(yaw)
        dx = np.clip(cx, x0, x0 + RES) - cx
        dy = np.clip(cy, y0, y0 + RES) - cy
        inside = dx * dx + dy * dy < radius * radius
        if inside.any():
            return t, int(padded[iy[inside][0], ix[inside][0]])
    return max_distance, FREE


@settings(deadline=None, max_examples=60)
@given(seed=st.integers(0, 2**31), x=st.floats(-0.6, 0.6), y=st.floats(-0.6, 0.6),
       yaw=st.floats(-math.pi, math.pi), radius=st.floats(0.01, 0.4),
       fraction=st.floats(0.0, 0.05))
def test_travel_is_the_brute_force_sweep(seed, x, y, yaw, radius, fraction):
    rng = np.random.default_rng(seed)
    state = np.where(rng.random((40, 40)) < fraction,
                     rng.choice([UNKNOWN, OBSTACLE, DROP_OFF], (40, 40)), FREE).astype(np.uint8)
    geo = np.array([-1.0, -1.0, RES, 40, 40])
    distance, kind = nk.travel_kernel(x, y, yaw, radius, 1.5, state, geo)
    truth, truth_kind = swept_reference(state, (-1.0, -1.0), x, y, yaw, radius, 1.5)
    assert truth - 1e-3 - 1e-9 <= distance <= truth + 1e-9
    if distance < 1.5 - 1e-3:  # what it meets (another cell could be met at the same t)
        assert kind != FREE and truth_kind != FREE


def test_a_wall_ahead_and_a_post_beside_the_path_in_closed_form():
    state = np.full((40, 40), FREE, np.uint8)
    state[:, 30] = OBSTACLE  # a wall x in [0.5, 0.55]
    obstacles = obstacle_map(state)
    ahead = obstacles.travel((0.0, 0.0, 0.0))
    assert ahead.distance == pytest.approx(0.5 - ROBOT.radius)
    assert (ahead.kind, ahead.status) == (OBSTACLE, QueryStatus.OK)
    slanted = obstacles.travel((0.0, 0.0, math.radians(30)))
    assert slanted.distance == pytest.approx((0.5 - ROBOT.radius) / math.cos(math.radians(30)))
    state = np.full((40, 40), FREE, np.uint8)
    state[23, 30] = UNKNOWN  # a square x in [0.5, 0.55], y in [0.15, 0.2]
    post = obstacle_map(state).travel((0.0, 0.0, 0.0))
    assert post.distance == pytest.approx(0.5 - math.sqrt(ROBOT.radius**2 - 0.15**2))
    assert (post.kind, post.status) == (UNKNOWN, QueryStatus.UNKNOWN)
    beside = obstacle_map(state).travel((0.0, -0.1, 0.0), 0.7)  # passes 0.25 beside it
    assert beside.distance == 0.7 and beside.kind == FREE and beside.status == QueryStatus.OK
    behind = obstacle_map(state).travel((0.0, 0.0, math.pi), 0.5)  # moving away from it
    assert behind.distance == 0.5


def test_touching_now_gives_zero_and_the_window_edge_is_unknown():
    state = np.full((40, 40), FREE, np.uint8)
    state[20, 24] = OBSTACLE  # under the robot's rim at (0.2, 0)
    assert obstacle_map(state).travel((0.0, 0.0, math.pi)).distance == 0.0
    edge = obstacle_map(np.full((40, 40), FREE, np.uint8)).travel((0.0, 0.0, 0.0), 3.0)
    assert edge.distance == pytest.approx(1.0 - ROBOT.radius)  # the window ends at x = 1
    assert edge.status == QueryStatus.UNKNOWN
    huge = obstacle_map(np.full((40, 40), FREE, np.uint8)).travel((0.0, 0.0, 0.7), 1e6)
    assert huge.distance == pytest.approx((1.0 - ROBOT.radius) / math.cos(0.7))
    outside = obstacle_map(np.full((40, 40), FREE, np.uint8)).travel((5.0, 5.0, 0.0), 1e6)
    assert outside.distance == 0.0 and outside.status == QueryStatus.UNKNOWN


def test_far_from_the_origin_the_answer_is_the_same():
    state = np.full((40, 40), FREE, np.uint8)
    state[:, 30] = OBSTACLE
    far = obstacle_map(state, origin=(1e5 - 1.0, -2e5 - 1.0)).travel((1e5, -2e5, 0.0))
    assert far.distance == pytest.approx(0.5 - ROBOT.radius, abs=1e-9)


def test_bad_data_and_arguments():
    now = [0.0]
    obstacles = obstacle_map(np.full((40, 40), FREE, np.uint8), clock=lambda: now[0])
    for pose in ((math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, math.nan)):
        answer = obstacles.travel(pose)
        assert (answer.distance, answer.status) == (0.0, QueryStatus.INVALID)
    now[0] = 5.0
    assert obstacles.travel((0.0, 0.0, 0.0)).status == QueryStatus.STALE
    assert obstacles.travel((0.0, 0.0, 0.0)).distance == 0.0
    now[0] = 0.0
    obstacles.set_fault("camera unplugged")
    assert obstacles.travel((0.0, 0.0, 0.0)).status == QueryStatus.FAULTED
    obstacles.clear_fault()
    assert ObstacleMap().travel((0.0, 0.0, 0.0)).distance == 0.0  # nothing published
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(MapError, match="max_distance"):
            obstacles.travel((0.0, 0.0, 0.0), bad)
    with pytest.raises(MapError, match=r"pose must be \(x, y, yaw\)"):
        obstacles.travel((0.0, 0.0))
