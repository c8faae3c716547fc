"""A step down to a floor the robot reaches round its end (a sunken floor joined to the
rest by a ramp): the lower floor is floor, not missing, so the step's cells are no
drop-off, and no robot crosses the step: no two FREE cells side by side lie more than a
step apart. Against the simulator's truth, in the terrain rooms that showed it, and
beside a sunken floor the robot cannot reach, which stays a drop-off."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from benchmarks.bench_hazards import ROBOT, hazard_run, mapped
from benchmarks.random_rooms import terrain_room
from scanmap.navigation import DROP_OFF, FREE
from scanmap.navigation.floor._band_kernels import free_steps as free_steps_kernel
from scanmap.navigation.morphology import dilate
from scanmap_driver.sim import Scene, builtin_scene
from scanmap_driver.sim.scene import FloorRegion

SUNKEN = FloorRegion(polygon=((5.57, 0.92), (6.77, 0.92), (6.77, 2.12), (5.57, 2.12)),
                     height=-0.118, name="sunken floor")
RAMP = FloorRegion(polygon=((4.87, 1.07), (5.57, 1.07), (5.57, 1.97), (4.87, 1.97)),
                   height=-0.059, gradient=(-0.16771, 0.0), name="ramp down")


@pytest.mark.parametrize("seed", [3102, 3105])
def test_a_step_down_to_a_floor_reached_round_its_end_is_no_drop_off(seed):
    # Seen from beyond its rim after the last scan, a cell of the sunken floor's step
    # was DROP_OFF, its lower half seen free below the floor: 58 and 79 cells from any
    # true drop-off, the edge's error
    run = hazard_run(scene=terrain_room(seed))
    assert run["drop_false"] == 0
    assert run["edge_error_cells"] <= 1.0
    assert run["drop_free_any_scan"] == 0


def sunken_floor_scene(regions: tuple[FloorRegion, ...]) -> Scene:
    """An open floor holding `regions`, driven past them 1 m off."""
    poses = np.array([[x, 0.0, 0.0] for x in np.arange(3.0, 9.01, 0.4)])
    return replace(builtin_scene("corridor"), objects=(), people=(), floor_regions=regions,
                   scan_poses=poses)


def step_pairs(heights: np.ndarray, exempt: np.ndarray | None = None) -> int:
    """Pairs of cells side by side (8 neighbours) whose heights (NaN: none) lie more than a
    step apart, but those with both cells `exempt`."""
    exempt = np.zeros(heights.shape, bool) if exempt is None else exempt
    pairs = 0
    for a, b in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                 ((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                 ((slice(1, None), slice(1, None)), (slice(None, -1), slice(None, -1))),
                 ((slice(1, None), slice(None, -1)), (slice(None, -1), slice(1, None)))):
        with np.errstate(invalid="ignore"):
            apart = np.abs(heights[a] - heights[b]) > ROBOT.step_height
        pairs += int((apart & ~(exempt[a] & exempt[b])).sum())
    return pairs


def free_steps(seg) -> int:
    """FREE cells side by side more than a step apart: a way across the step."""
    return step_pairs(np.where(seg.state == FREE, seg.floor_height, np.nan))


def free_steps_reference(free, heights, step, stood):
    """`_band_kernels.free_steps` in numpy: each cell against its neighbours shifted in."""
    ny, nx = free.shape
    padded = np.pad(np.where(free, heights, np.nan), 1, constant_values=np.nan)
    centre = padded[1:-1, 1:-1]
    upper, lower = np.zeros((ny, nx), bool), np.zeros((ny, nx), bool)
    with np.errstate(invalid="ignore"):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                other = padded[1 + dy:1 + dy + ny, 1 + dx:1 + dx + nx]
                upper |= centre - other > step
                lower |= other - centre > step
    return lower & ~stood | upper & ~lower & ~stood & dilate(lower & stood)


@settings(max_examples=100, deadline=None)
@given(heights=arrays(np.float32, st.tuples(st.integers(1, 8), st.integers(1, 8)),
                      elements=st.sampled_from([0.0, 0.04, -0.03, -0.12, 0.2, np.nan])),
       data=st.data())
def test_the_rule_leaves_no_free_cells_side_by_side_a_step_apart(heights, data):
    """Of every such pair one leaves FREE, never a cell the robot stood on (a pair it
    stood on both of stays); as the plain numpy search takes them."""
    stood = data.draw(arrays(np.bool_, heights.shape))
    free = data.draw(arrays(np.bool_, heights.shape))
    taken = free_steps_kernel(free, heights, ROBOT.step_height, stood)
    assert np.array_equal(taken, free_steps_reference(free, heights, ROBOT.step_height,
                                                      stood))
    assert not (taken & (stood | ~free)).any()
    assert step_pairs(np.where(free & ~taken, heights, np.nan), stood) == 0


def test_the_step_down_to_a_sunken_floor_is_no_drop_off_once_reached_and_never_crossed():
    segs = [step.seg for step in mapped(sunken_floor_scene((RAMP, SUNKEN)))]
    # the ramp seen, the sunken floor is floor: no drop-off anywhere (before, its step's
    # cells took a scan more: 22 at the third)
    assert not any((seg.state == DROP_OFF).any() for seg in segs[2:])
    # free to free across the ramp's side and the sunken floor's far end, 10-12 cm down
    # (2-8 pairs a scan from the sixth), before one cell of each pair was an edge
    assert [free_steps(seg) for seg in segs] == [0] * len(segs)


@pytest.mark.parametrize("seed", [3102, 3105])
def test_no_free_cell_lies_a_step_above_a_free_cell_beside_it(seed):
    assert all(free_steps(step.seg) == 0 for step in mapped(terrain_room(seed)))


def test_a_sunken_floor_no_ramp_reaches_stays_a_drop_off():
    run = hazard_run(scene=sunken_floor_scene((SUNKEN,)))
    assert run["drop_free_any_scan"] == 0
    assert run["edge_error_any_scan"] <= 1.0
    assert run["drop_found"] >= 0.85 * run["drop_cells"]
