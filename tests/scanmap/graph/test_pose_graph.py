"""The pose-graph optimiser against closed forms: a straight chain is linear least squares."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from scanmap.graph import Edge, PoseGraph, planar_information
from scanmap_driver.transforms import pose_to_se2, se2_to_pose


def chain(loop_measurement: float, loop: bool) -> PoseGraph:
    """Three nodes on the x axis: odometry 0->1 and 1->2 of 1 m each (sigma 0.1 m), and
    a direct 0->2 measurement (sigma 0.05 m); all headings 0."""
    graph = PoseGraph()
    for x in (0.0, 0.9, 2.2):
        graph.add_node(se2_to_pose(x, 0.05, 0.01))
    odometry = np.diag([100.0, 100.0, 1e4])
    graph.add_edge(Edge(0, 1, se2_to_pose(1.0, 0.0, 0.0), odometry))
    graph.add_edge(Edge(1, 2, se2_to_pose(1.0, 0.0, 0.0), odometry))
    graph.add_edge(Edge(0, 2, se2_to_pose(loop_measurement, 0.0, 0.0),
                        np.diag([400.0, 400.0, 1e4]), loop=loop))
    return graph


def test_gaussian_edges_give_the_weighted_least_squares_solution():
    graph = chain(2.3, loop=False)
    graph.poses[0] = np.eye(4)
    # x0 = 0 fixed; minimise 100 (x1 - 1)^2 + 100 (x2 - x1 - 1)^2 + 400 (x2 - 2.3)^2.
    normal = np.array([[200.0, -100.0], [-100.0, 500.0]])
    x1, x2 = np.linalg.solve(normal, [100.0 - 100.0, 100.0 + 400.0 * 2.3])
    poses = graph.optimise()
    np.testing.assert_allclose([pose_to_se2(p) for p in poses],
                               [[0, 0, 0], [x1, 0, 0], [x2, 0, 0]], atol=1e-6)


def test_a_false_loop_barely_moves_the_chain():
    graph = chain(2.0 + 5.0, loop=True)  # 5 m wrong: a hundred sigmas
    graph.poses[0] = np.eye(4)
    poses = graph.optimise(loop_kernel=3.0)
    # The chain is a spring of stiffness 50 (two of 100 in series); the loop's Cauchy
    # force on whitened residual r = 20 (7 - x2) is r / (1 + r^2 / 9), times 20 per metre.
    def balance(x2: float) -> float:
        r = 20.0 * (7.0 - x2)
        return 50.0 * (x2 - 2.0) - 20.0 * r / (1.0 + r * r / 9.0)

    assert poses[2][0, 3] == pytest.approx(brentq(balance, 2.0, 2.5), abs=1e-4)
    assert poses[2][0, 3] - 2.0 < 0.05
    assert abs(chain(2.0 + 5.0, loop=False).optimise()[2][0, 3] - 2.0) > 1.0  # Gaussian: bent


def test_planar_information_floors_the_sigmas():
    covariance = np.zeros((6, 6))
    covariance[0, 0], covariance[1, 1], covariance[5, 5] = 1e-6, 4e-6, 1e-8
    information = planar_information(covariance, (0.02, 0.005))
    np.testing.assert_allclose(np.linalg.inv(information),
                               np.diag([1e-6 + 4e-4, 4e-6 + 4e-4, 1e-8 + 2.5e-5]))


@pytest.mark.parametrize("fixed", [1, 2])
def test_an_edge_onto_a_fixed_node_counts_as_one_from_it(fixed):
    # The loop measured the other way round (2 -> 0, -2.3 m): the same least squares.
    graph = chain(2.3, loop=False)
    graph.poses[0], graph.poses[1] = np.eye(4), se2_to_pose(0.9, 0.0, 0.0)
    loop = graph.edges.pop()
    graph.edges.append(type(loop)(2, 0, se2_to_pose(-2.3, 0.0, 0.0), loop.information))
    graph.fixed = fixed
    held = pose_to_se2(graph.poses[1])
    poses = graph.optimise()
    if fixed == 1:
        x1, x2 = np.linalg.solve([[200.0, -100.0], [-100.0, 500.0]], [0.0, 100.0 + 920.0])
        expected = [[0, 0, 0], [x1, 0, 0], [x2, 0, 0]]
    else:  # node 1 held at its start; node 2 between its two springs
        x2 = (100.0 * (held[0] + 1.0) + 400.0 * 2.3) / 500.0
        expected = [[0, 0, 0], held, [x2, 0, 0]]
    np.testing.assert_allclose([pose_to_se2(p) for p in poses], expected, atol=1e-6)
