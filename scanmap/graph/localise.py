"""Where a scan lies in a saved map: the start of a new mapping session over a map saved
with its pose graph (a robot mapping a building across days, switched on wherever it was
left or carried to).

Candidates come from the hints first (poses in the map: where the robot stopped, or
where an operator says it stands, as RViz's "2D Pose Estimate" does) and then by place:
the scan-context descriptor of the scan against every keyframe's, by ring key and then
over every rotation, as loops are found. Each is verified as a loop is (`LoopCloser.match`:
ICP onto the candidate's neighbourhood, converged, every direction constrained, enough
points matched closely enough), a hint's within `proximity_radius + gate_radius` of it.
A hint that passes wins; else the best place, unless another place that passes about as
well lies elsewhere: look-alike corridors cannot be told apart by one scan, and a wrong
start would bend the saved map, so that is an error, as is no candidate passing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scanmap.graph.descriptor import compare, describe
from scanmap.graph.loop_closure import LoopCloser
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose

AMBIGUOUS_FITNESS = 0.1  # a second place within this fitness of the best makes it ambiguous


class NotLocalised(MapError):
    """No place of the map matched the scan, or more than one did."""


@dataclass(frozen=True)
class Localisation:
    """A scan located in the map: its pose (4x4, map <- base_link), the keyframe whose
    neighbourhood it matched, how that was found ("hint" or "place"), the ICP fitness
    and inlier RMS (m), and the 3x3 information of the match (x, y, yaw)."""

    pose: np.ndarray
    node: int
    found_by: str
    fitness: float
    inlier_rmse: float
    information: np.ndarray


def localise(closer: LoopCloser, points: np.ndarray,
             hints: Sequence[np.ndarray] = ()) -> Localisation:
    """Locate a scan's (N, 3) points (base_link) in `closer`'s map (see the module
    docstring); raises NotLocalised when no candidate passes or places disagree."""
    closer.finish()
    c = closer.config
    keyframes = closer.keyframes()
    if not keyframes:
        raise NotLocalised("the map holds no keyframe to localise in")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    estimates = closer.corrected_poses()
    nodes = np.array([node for node, _ in keyframes])
    found = [_verified(closer, points, estimates, node, guess, "hint")
             for node, guess in _hinted(estimates, nodes, hints, c.proximity_radius
                                        + c.gate_radius)]
    hinted = [f for f in found if f is not None]
    if hinted:
        return max(hinted, key=lambda f: f.fitness)
    places = [f for f in (_verified(closer, points, estimates, node, guess, "place")
                          for node, guess in _by_place(closer, points, keyframes))
              if f is not None]
    if not places:
        raise NotLocalised(f"no place of the map matched the scan ({len(points)} points; "
                           f"hints tried: {len(hints)})")
    best = max(places, key=lambda f: f.fitness)
    for other in places:
        apart = float(np.linalg.norm(other.pose[:2, 3] - best.pose[:2, 3]))
        turned = abs(pose_to_se2(invert_pose(best.pose) @ other.pose)[2])
        if other.fitness >= best.fitness - AMBIGUOUS_FITNESS and (
                apart > c.gate_radius or turned > c.max_yaw_gate):
            x0, y0, _ = pose_to_se2(best.pose)
            x1, y1, _ = pose_to_se2(other.pose)
            raise NotLocalised(f"the scan matches two places of the map about as well: "
                               f"({x0:.2f}, {y0:.2f}) m, fitness {best.fitness:.2f}, and "
                               f"({x1:.2f}, {y1:.2f}) m, fitness {other.fitness:.2f}; give a "
                               f"hint of where the robot stands")
    return best


def _hinted(estimates: np.ndarray, nodes: np.ndarray, hints: Sequence[np.ndarray],
            reach: float) -> list[tuple[int, np.ndarray]]:
    """(keyframe, guessed pose of the scan in its frame) for each hint within `reach` of a
    keyframe: the nearest one."""
    out = []
    for hint in hints:
        hint = np.asarray(hint, dtype=np.float64)
        distances = np.linalg.norm(estimates[nodes, :2, 3] - hint[:2, 3], axis=1)
        k = int(np.argmin(distances))
        if distances[k] <= reach:
            out.append((int(nodes[k]), invert_pose(estimates[nodes[k]]) @ hint))
    return out


def _by_place(closer: LoopCloser, points: np.ndarray, keyframes: list
              ) -> list[tuple[int, np.ndarray]]:
    """(keyframe, guessed pose of the scan in its frame) for the keyframes whose
    descriptors are nearest the scan's (`place_candidates` by ring key, then within
    `max_descriptor_distance` over every rotation)."""
    c = closer.config
    query = describe(points, c.rings, c.sectors, c.descriptor_radius)
    keys = np.array([descriptor.ring_key for _, descriptor in keyframes])
    order = np.argsort(np.linalg.norm(keys - query.ring_key, axis=1))
    out = []
    for k in order[:2 * c.place_candidates]:
        node, descriptor = keyframes[k]
        distance, yaw = compare(query, descriptor)
        if distance <= c.max_descriptor_distance:
            out.append((node, se2_to_pose(0.0, 0.0, yaw)))
    return out


def _verified(closer: LoopCloser, points: np.ndarray, estimates: np.ndarray, node: int,
              guess: np.ndarray, how: str) -> Localisation | None:
    """The candidate verified by `LoopCloser.match`, a hint also within its gate."""
    c = closer.config
    result = closer.match(points, node, guess)
    if result is None:
        return None
    moved = float(np.linalg.norm(result.pose[:2, 3] - guess[:2, 3]))
    turned = abs(pose_to_se2(invert_pose(guess) @ result.pose)[2])
    if how == "hint" and (moved > c.proximity_radius + c.gate_radius
                          or turned > c.max_yaw_gate):
        return None
    return Localisation(estimates[node] @ result.pose, node, how, float(result.fitness),
                        float(result.inlier_rmse), closer.loop_information(result))
