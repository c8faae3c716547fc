"""examples/planner.py: an optimal A* path, clear of the costmap's obstacles and the scene's."""

from __future__ import annotations

import itertools
import json

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import dijkstra

from scanmap import Mapper
from scanmap.evaluation.ground_truth import map_to_world
from scanmap.mapping.config import MapperConfig
from scanmap.navigation.costmap import INSCRIBED, inflate
from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.transforms import transform_points

from ..scanmap.scene_footprints import footprint_distance
from .conftest import run_example


@pytest.fixture(scope="module")
def office_map(tmp_path_factory):
    """A map of the office from ideal scans of its first six poses, and the true start."""
    ideal = list(ideal_scans(builtin_scene("office"), seed=6, scans=6))
    mapper = Mapper(reference_scanner(), MapperConfig(update_obstacles=False), offline=True)
    mapper.map_scans(scan.scan for scan in ideal)
    path = tmp_path_factory.mktemp("office_map") / "map.npz"
    mapper.save(path)
    return path, ideal[0].pose_start


def test_plans_a_collision_free_path_through_the_mapped_office(office_map, tmp_path):
    map_file, true_start = office_map
    out = tmp_path / "plan"
    result = run_example("planner", "--map", map_file, "--out", out)
    assert "path of" in result.stdout
    plan = json.loads((out / "plan.json").read_text())
    cells = np.array(plan["cells"])
    assert plan["found"] and len(cells) > 20 and plan["length_m"] > 1.0
    steps = np.abs(np.diff(cells, axis=0))
    assert steps.max() == 1 and (steps.sum(axis=1) > 0).all()  # 8-connected, no repeats

    mapper = Mapper.load(map_file)
    seg = mapper.segment()
    costs = inflate(seg)
    start = np.array(plan["start"])
    xy = np.array(plan["path"])
    away = np.hypot(*(xy - start).T) > seg.robot.radius  # the start's footprint is cleared
    assert (costs[cells[away, 0], cells[away, 1]] < INSCRIBED).all()
    assert plan["max_cost"] < INSCRIBED

    # Against the scene itself: the robot's centre keeps its radius from every object.
    world_from_map = map_to_world(mapper.trajectory().poses, true_start[None])
    world = transform_points(world_from_map, np.column_stack([xy, np.zeros(len(xy))]))
    clearance = footprint_distance(builtin_scene("office"), world[:, :2])
    assert clearance.min() > seg.robot.radius - 0.05

    image = cv2.imread(str(out / "plan.png"))
    assert image.shape[:2] == (4 * seg.shape[0], 4 * seg.shape[1])


def test_maps_a_recording_itself_and_plans_to_a_given_goal(office_recording, tmp_path):
    out = tmp_path / "plan"
    result = run_example("planner", "--recording", office_recording, "--out", out,
                         "--workers", 1, "--goal", 0.0, 0.0)  # the start: one cell
    assert "path of 0.00 m" in result.stdout
    assert (out / "map.npz").is_file() and len(Mapper.load(out / "map.npz")) == 1


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_astar_finds_the_cheapest_path(examples_on_path, seed):
    """A* on random costmaps against Dijkstra on the same graph (scipy)."""
    import planner

    rng = np.random.default_rng(seed)
    costs = rng.choice([0, 0, 0, 50, 200, 252, 253, 254, 255], size=(9, 11)).astype(np.uint8)
    costs[0, 0] = costs[-1, -1] = 0
    path = planner.astar(costs, (0, 0), (8, 10))
    ny, nx = costs.shape
    graph = lil_matrix((ny * nx, ny * nx))
    for y in range(ny):
        for x in range(nx):
            for dy, dx in planner.STEPS:
                yy, xx = y + dy, x + dx
                if 0 <= yy < ny and 0 <= xx < nx and costs[yy, xx] < INSCRIBED \
                        and costs[y, x] < INSCRIBED:
                    graph[y * nx + x, yy * nx + xx] = np.hypot(dy, dx) * (
                        1.0 + 3.0 * costs[yy, xx] / (INSCRIBED - 1))
    best = dijkstra(graph.tocsr(), indices=0)[-1]
    if not np.isfinite(best):
        assert path is None
        return
    assert path[0] == (0, 0) and path[-1] == (8, 10)
    cost = sum(np.hypot(b[0] - a[0], b[1] - a[1]) * (1.0 + 3.0 * costs[b] / (INSCRIBED - 1))
               for a, b in itertools.pairwise(path))
    assert abs(cost - best) < 1e-9
