"""A planar pose graph and its robust optimisation (GTSAM).

Nodes are scan poses (4x4, base_link in map); an edge says "node j seen from node i is
`measurement`" with an information matrix over the body-frame increment (x, y, yaw) of
that relative pose. Odometry edges (consecutive scans, from registration) are trusted
as Gaussian; loop edges go through a Cauchy kernel, whose influence fades once a
residual exceeds `loop_kernel` sigmas: a false loop that slipped past verification
pulls on the map with a bounded force instead of bending it.

Why GTSAM (not Open3D's `global_optimization`): Open3D builds a dense 6N x 6N system,
which a run of a thousand scans cannot afford; GTSAM's sparse Levenberg-Marquardt over
SE(2) `Pose2` factors (the planar pose registration estimates) solves such a graph in
tens of milliseconds, and takes the robust kernels as noise models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scanmap_driver.errors import MapError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose


@dataclass(frozen=True, eq=False)
class Edge:
    """Node `target` seen from node `source`: measurement (4x4) with information (3x3)
    over (x, y, yaw); loop: a loop closure (robust kernel) rather than odometry."""

    source: int
    target: int
    measurement: np.ndarray
    information: np.ndarray
    loop: bool = False


class PoseGraph:
    """Nodes and edges; `optimise` returns corrected poses and leaves the graph as it is.

    fixed: the first nodes held where they are (at least node 0): a map loaded without a
    graph, whose scans the new graph extends but cannot move.
    """

    def __init__(self) -> None:
        self.poses: list[np.ndarray] = []
        self.edges: list[Edge] = []
        self.fixed = 1

    def __len__(self) -> int:
        return len(self.poses)

    def add_node(self, pose: np.ndarray) -> int:
        """Append a node at `pose` (its initial estimate); returns its id."""
        self.poses.append(np.asarray(pose, dtype=np.float64))
        return len(self.poses) - 1

    def add_edge(self, edge: Edge) -> None:
        """Add a constraint between two existing nodes."""
        if not (0 <= edge.source < len(self) and 0 <= edge.target < len(self)) \
                or edge.source == edge.target:
            raise MapError(f"PoseGraph: edge {edge.source} -> {edge.target} needs two distinct "
                           f"nodes of {len(self)}")
        if edge.information.shape != (3, 3) or not np.isfinite(edge.information).all():
            raise MapError("PoseGraph: an edge's information must be a finite 3x3 matrix")
        self.edges.append(edge)

    @property
    def loops(self) -> list[Edge]:
        """The loop-closure edges."""
        return [e for e in self.edges if e.loop]

    def optimise(self, initial: np.ndarray | None = None, loop_kernel: float = 3.0,
                 max_iterations: int = 50) -> np.ndarray:
        """(N, 4, 4) poses minimising all edges' errors, the `fixed` first nodes held.

        initial: (N, 4, 4) start (default the nodes' poses); z, roll and pitch of each
        node are kept from it, and fixed nodes wholly (constants, not variables; an edge
        from one is a prior on the other node). loop_kernel: Cauchy scale of loop edges
        (sigmas; inf: none).
        """
        import gtsam

        start = np.array(self.poses if initial is None else initial, dtype=np.float64)
        if len(start) != len(self):
            raise MapError(f"PoseGraph.optimise: {len(start)} initial poses for {len(self)} "
                           "nodes")
        fixed = min(max(self.fixed, 1), len(self))
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for i in range(fixed, len(self)):
            values.insert(i, gtsam.Pose2(*pose_to_se2(start[i])))
        kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(min(loop_kernel, 1e300))
        for edge in self.edges:
            source, target = edge.source, edge.target
            measurement = gtsam.Pose2(*pose_to_se2(edge.measurement))
            information = edge.information
            if target < fixed <= source:  # seen the other way round: the fixed node first
                adjoint = np.linalg.inv(measurement.AdjointMap())
                source, target, measurement = target, source, measurement.inverse()
                information = adjoint.T @ information @ adjoint
            if target < fixed:
                continue  # between two fixed nodes: nothing to optimise
            noise = gtsam.noiseModel.Gaussian.Information(information)
            if edge.loop and np.isfinite(loop_kernel):  # inf: Gaussian loop edges
                noise = gtsam.noiseModel.Robust.Create(kernel, noise)
            if source < fixed:  # a fixed node is a constant: the edge is a prior
                anchor = gtsam.Pose2(*pose_to_se2(start[source]))
                graph.add(gtsam.PriorFactorPose2(target, anchor.compose(measurement), noise))
            else:
                graph.add(gtsam.BetweenFactorPose2(source, target, measurement, noise))
        out = start.copy()
        if fixed == len(self):
            return out
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        for i in range(fixed, len(self)):
            p = result.atPose2(i)
            planar = se2_to_pose(p.x(), p.y(), p.theta())
            # Keep the start's z, roll, pitch: the graph moves the pose in the plane only.
            out[i] = planar @ invert_pose(se2_to_pose(*pose_to_se2(start[i]))) @ start[i]
        return out


def planar_information(covariance: np.ndarray, floor: tuple[float, float]) -> np.ndarray:
    """3x3 information over (x, y, yaw) of a 6x6 registration covariance (x, y, z, rx, ry,
    rz), its sigmas raised to at least `floor` (m, rad): ICP's own covariance ignores
    wrong correspondences and is too sure of itself."""
    planar = np.asarray(covariance, dtype=np.float64)[np.ix_([0, 1, 5], [0, 1, 5])]
    planar = (planar + planar.T) / 2.0 + np.diag([floor[0] ** 2, floor[0] ** 2, floor[1] ** 2])
    return np.linalg.inv(planar)
