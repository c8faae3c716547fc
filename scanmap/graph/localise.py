"""Where a scan lies in a saved map: the start of a new mapping session over a map saved
with its pose graph (a robot mapping a building across days, switched on wherever it was
left or carried to).

A `Session` holds the new session's scans, registered in a frame of their own, and
locates the newest with those of the last `context_distance` of travel (`localise`) after
each; the session is located once a location is confirmed by a later one that agrees
(`localise_agreement`) from `localise_travel` further on, with new scans in its context,
or at once near a hint.

Candidates come from the hints first (poses in the map: where the robot stopped, or
where an operator says it stands, as RViz's "2D Pose Estimate" does) and then by place:
the scan-context descriptor of the scans against every keyframe's, by ring key and then
over every rotation, as loops are found but more of them (`localise_candidates`,
`localise_descriptor_distance`): a loop has a proximity search besides. A place gives
the heading alone, and the scans may lie half a `keyframe_distance` from the keyframe,
beyond what ICP pairs: the scans within that travel of it are candidates too, at its
heading. Each is verified as a loop is
(`LoopCloser.match`: ICP onto the candidate's neighbourhood, converged, every direction
constrained), but with more points matched more closely (`localise_fitness`,
`localise_rmse`), since no pose gate backs it; a hint's within `proximity_radius +
gate_radius` of it.
A hint that passes wins; else the best place, unless another place that matches about
as well (as a loop would match: `min_fitness`, `max_rmse`) lies elsewhere: look-alike
corridors cannot be told apart by one scan, and a wrong start would bend the saved map,
so that is an error, as is no candidate passing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scanmap.graph.descriptor import compare, describe
from scanmap.graph.loop_closure import LoopCloser, LoopClosureConfig
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose, transform_points

AMBIGUOUS_FITNESS = 0.1  # a second place within this fitness of the best makes it ambiguous
NEIGHBOURS = 5  # scans near a place keyframe tried as where the robot stands


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
    hinted = [f for f in found if f is not None and _strict(f, c)]
    if hinted:
        return max(hinted, key=lambda f: f.fitness)
    places = [f for f in (_verified(closer, points, estimates, node, guess, "place")
                          for node, guess in _by_place(closer, points, keyframes, estimates))
              if f is not None]
    if not any(_strict(f, c) for f in places):
        raise NotLocalised(f"no place of the map matched the scan ({len(points)} points; "
                           f"hints tried: {len(hints)})")
    best = max((f for f in places if _strict(f, c)), key=lambda f: f.fitness)
    for other in places:  # as a loop would match, if not as well as a location must
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


class Session:
    """A new session's scans until located in `closer`'s map (module docstring). hints:
    poses (4x4, map) of the robot at the session's first scan."""

    def __init__(self, closer: LoopCloser, hints: Sequence[np.ndarray] = ()) -> None:
        self.closer = closer
        self.hints = [np.asarray(h, dtype=np.float64) for h in hints]
        self._points: list[np.ndarray] = []
        self._poses: list[np.ndarray] = []
        # The location to confirm: map <- session, and the session pose it was found at.
        self._guess: tuple[np.ndarray, np.ndarray] | None = None

    def add(self, points: np.ndarray, pose: np.ndarray, registered: bool = True
            ) -> Localisation:
        """The newest scan's (N, 3) points (its frame) at `pose` (the session's frame;
        `registered`: by ICP, not only predicted): where it lies in the map once the
        session is located; NotLocalised until then."""
        pose = np.asarray(pose, dtype=np.float64)
        if registered or not self._poses:
            self._points.append(np.asarray(points))
            self._poses.append(pose)
        c = self.closer.config
        to_newest = invert_pose(self._poses[0]) @ pose
        found = localise(self.closer, recent_context(self._points, self._poses,
                                                     c.context_distance),
                         [hint @ to_newest for hint in self.hints])
        if found.found_by == "hint":
            return found
        frame = found.pose @ invert_pose(pose)
        if self._guess is None:
            self._guess = (frame, pose)
            raise NotLocalised(f"located once; to be confirmed {c.localise_travel:.1f} m on")
        guess, at = self._guess
        x, y, yaw = pose_to_se2(invert_pose(guess @ pose) @ found.pose)
        if np.hypot(x, y) > c.localise_agreement or abs(yaw) > c.localise_yaw_agreement:
            self._guess = (frame, pose)
            raise NotLocalised(f"the last two locations lie {np.hypot(x, y):.2f} m and "
                               f"{np.degrees(abs(yaw)):.1f} deg apart")
        travelled = float(np.linalg.norm(pose[:2, 3] - at[:2, 3]))
        if travelled < c.localise_travel:
            raise NotLocalised(f"located twice alike; to be confirmed "
                               f"{c.localise_travel - travelled:.1f} m on")
        return found


def recent_context(points: Sequence[np.ndarray], poses: Sequence[np.ndarray],
                   distance: float) -> np.ndarray:
    """(N, 3) the points of the scans (each (Ni, 3) in its own frame, at `poses` in one
    frame, newest last) within `distance` of travel before the newest, in its frame: what
    a new session's scans so far say about the place it is in."""
    to_newest = invert_pose(poses[-1])
    parts, travelled = [np.zeros((0, 3))], 0.0
    for k in range(len(poses) - 1, -1, -1):
        if k < len(poses) - 1:
            travelled += float(np.linalg.norm(poses[k + 1][:2, 3] - poses[k][:2, 3]))
        if travelled > distance:
            break
        parts.append(transform_points(to_newest @ poses[k], points[k]))
    return np.concatenate(parts)


def _strict(found: Localisation, c: LoopClosureConfig) -> bool:
    """Whether a match is close enough to locate the scans (`localise_fitness`, `_rmse`)."""
    return found.fitness >= c.localise_fitness and found.inlier_rmse <= c.localise_rmse


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


def _by_place(closer: LoopCloser, points: np.ndarray, keyframes: list,
              estimates: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(node, guessed pose of the scan in its frame) for the keyframes whose descriptors
    are nearest the scan's (`localise_candidates` by ring key, then within
    `localise_descriptor_distance` over every rotation), and for the nearest
    `place_candidates` of them also up to NEIGHBOURS scans within `keyframe_distance` of
    travel, at the heading the descriptor gives."""
    c = closer.config
    query = describe(points, c.rings, c.sectors, c.descriptor_radius)
    keys = np.array([descriptor.ring_key for _, descriptor in keyframes])
    order = np.argsort(np.linalg.norm(keys - query.ring_key, axis=1))
    places = []
    for k in order[:c.localise_candidates]:
        node, descriptor = keyframes[k]
        distance, yaw = compare(query, descriptor)
        if distance <= c.localise_descriptor_distance:
            places.append((distance, node, yaw))
    out: dict[int, np.ndarray] = {}
    for rank, (_, node, yaw) in enumerate(sorted(places)):
        heading = estimates[node] @ se2_to_pose(0.0, 0.0, yaw)  # the robot at the keyframe
        nearby = closer.neighbours(node, c.keyframe_distance) \
            if rank < c.place_candidates else [node]
        for j in nearby[:NEIGHBOURS]:
            guess = invert_pose(estimates[j]) @ heading
            guess[:3, 3] = 0.0  # the robot at scan j, heading as at the keyframe
            out.setdefault(j, guess)
    return list(out.items())


def _verified(closer: LoopCloser, points: np.ndarray, estimates: np.ndarray, node: int,
              guess: np.ndarray, how: str) -> Localisation | None:
    """The candidate verified by `LoopCloser.match` as a loop is (`_strict` tells whether
    it locates the scans), a hint also within its gate."""
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
