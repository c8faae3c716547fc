"""Rebuilding the grid at corrected poses after loop closure, without the frames.

Each fused scan keeps one ray per grid cell in base_link (`scan_contribution`); after an
optimisation the grid is fused again from them at the new poses. `rebuild_grid` does it
whole; `GridRebuilder` resumes from a copy of the grid before the first scan that moved
(exact: the same grid as `rebuild_grid` within its tolerance); `SubmapRebuilder` keeps
the grids of runs of consecutive scans (submaps) and merges them, each moved whole by its
correction (`HeightGrid.merge`), fusing again from rays only the submaps the correction
bent and the scans after the last whole submap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.packed import PackedGrid
from scanmap.registration.voxel_hash import COORD_LIMIT, first_per_voxel
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import invert_pose, transform_points


@dataclass(frozen=True, eq=False)
class Contribution:
    """What a rebuild keeps of a fused scan, in base_link (float32, placed again at the
    scan's corrected pose): the rays' ends, their origins as rows of `origin_table` (a
    scan's rays start from a few camera positions, one a frame: 2 bytes a ray instead of
    12), the scan's time, the floor its laser lines crossed unlit
    (`scanmap.grid.unlit`), and the laser's emitter for each row of the table, where the
    scan was fused with the laser's rays (`HeightGrid.insert`'s `lasers`; else none)."""

    points: np.ndarray  # (N, 3) float32
    origin_table: np.ndarray  # (F, 3) float32
    origin_index: np.ndarray  # (N,) uint16, or uint32 beyond 65,536 origins
    stamp: float
    unlit: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    laser_table: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))

    @classmethod
    def of_rays(cls, points: np.ndarray, origins: np.ndarray, stamp: float,
                unlit: np.ndarray | None = None, lasers: np.ndarray | None = None
                ) -> Contribution:
        """From (N, 3) ray ends and origins (and (K, 3) unlit floor, (N, 3) laser
        emitters): each run of rays with equal origins and emitters (a frame's rays come
        together) becomes one row of the tables."""
        origins = np.asarray(origins, np.float32).reshape(-1, 3)
        sources = origins if lasers is None else np.hstack(
            [origins, np.asarray(lasers, np.float32).reshape(-1, 3)])
        starts = np.ones(len(origins), bool)
        starts[1:] = (sources[1:] != sources[:-1]).any(axis=1)
        index = np.cumsum(starts) - 1
        kind = np.uint16 if len(index) == 0 or index[-1] < 2**16 else np.uint32
        unlit = np.zeros((0, 3)) if unlit is None else unlit
        return cls(np.asarray(points, np.float32).reshape(-1, 3), origins[starts],
                   index.astype(kind), float(stamp),
                   np.asarray(unlit, np.float32).reshape(-1, 3),
                   np.zeros((0, 3), np.float32) if lasers is None else sources[starts, 3:])

    @property
    def origins(self) -> np.ndarray:
        """(N, 3) float32: each ray's origin."""
        return self.origin_table[self.origin_index]

    @property
    def lasers(self) -> np.ndarray | None:
        """(N, 3) float32: each ray's laser emitter; None if not kept."""
        return self.laser_table[self.origin_index] if len(self.laser_table) else None

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays."""
        return self.points.nbytes + self.origin_table.nbytes + self.origin_index.nbytes \
            + self.unlit.nbytes + self.laser_table.nbytes

    def placed(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ends, origins) of its rays at `pose` (4x4), float64, in map."""
        return (transform_points(pose, self.points),
                transform_points(pose, self.origin_table)[self.origin_index])

    def placed_lasers(self, pose: np.ndarray) -> np.ndarray | None:
        """(N, 3) float64 in map: each ray's laser emitter at `pose`; None if not kept."""
        if not len(self.laser_table):
            return None
        return transform_points(pose, self.laser_table)[self.origin_index]


def scan_contribution(points: np.ndarray, origins: np.ndarray, pose: np.ndarray,
                      stamp: float, resolution: float, unlit: np.ndarray | None = None,
                      lasers: np.ndarray | None = None) -> Contribution:
    """What a rebuild keeps of a fused scan: one ray per grid-sized voxel, and one unlit
    floor point (`Contribution`). points, origins, unlit, lasers (the laser's emitters,
    if the scan was fused with them): the scan's in map at `pose`."""
    cell = one_per_voxel(points, resolution)
    to_base = invert_pose(pose)
    unlit = np.zeros((0, 3)) if unlit is None else unlit
    dark = one_per_voxel(unlit, resolution)
    return Contribution.of_rays(transform_points(to_base, points[cell]),
                                transform_points(to_base, origins[cell]), stamp,
                                transform_points(to_base, unlit[dark]),
                                None if lasers is None
                                else transform_points(to_base, lasers[cell]))


def rebuild_grid(config: GridConfig, poses: np.ndarray,
                 contributions: list[Contribution | None],
                 base: dict[str, np.ndarray] | None = None) -> HeightGrid:
    """A grid of every scan's kept (points, ray origins, time) in base_link, placed at its
    pose (None: a scan that was not fused); a rolling window centres on the last pose.
    base: a grid's `state()` to start from (default empty)."""
    grid = HeightGrid(config) if base is None else HeightGrid.from_state(config, base,
                                                                          "base map")
    if config.window is not None:
        grid.recenter(float(poses[-1][0, 3]), float(poses[-1][1, 3]))
    _reserve_kept(grid, poses, contributions)
    for pose, kept in zip(poses, contributions, strict=True):
        insert_kept(grid, pose, kept)
    return grid


class GridRebuilder:
    """`rebuild_grid` again after each optimisation, redoing only the scans that moved.

    An optimisation moves the scans after a loop's older end and leaves those before it
    where they were (the first node is fixed, and a stretch no loop reaches is not bent):
    after a loop back to a recent place, most of the map has not moved. The rebuilder
    keeps copies of the grid it built (checkpoints) with the poses it placed the scans
    at; a rebuild resumes from the newest checkpoint before the first scan whose kept
    rays moved more than `tolerance` cells from where the grid has them, and fuses the
    scans from there: the scans before it stay where they were, each within that
    tolerance of its new pose. tolerance 0: only scans whose pose did not change at all
    are reused, and the grid equals `rebuild_grid`'s.

    A copy costs time and memory in proportion to the grid, a scan's fusion in
    proportion to its rays: a checkpoint is taken once fusing since the last one took
    `ratio` times what copying the grid is expected to take (at the copy speed measured
    so far), and at the end of a rebuild on the same condition; the checkpoints are
    thinned (every other older one goes) to at most `max_bytes` together. The 3-D
    scanner's grid of an office (4.6 MB, 2.4 ms a scan) gets one every 15 scans or so
    (its first, whole rebuild takes 13% longer than `rebuild_grid`'s; after a loop that
    moved the last quarter of 200 scans, 0.15 s instead of 0.48); a CARMEN building's
    (hundreds of sparse 2-D tiles, 280 MB, 0.5 ms a scan) none, and every rebuild is
    whole, as `rebuild_grid`. With a rolling window (`config.window`)
    every rebuild is whole (the window follows the last pose).

    base: a grid's `state()` every rebuild starts from (as `rebuild_grid`'s). Called from
    one thread at a time (the Mapper's rebuild thread); `reused`: the scans the last
    rebuild did not fuse again.
    """

    def __init__(self, config: GridConfig, base: dict[str, np.ndarray] | None = None,
                 tolerance: float = 0.25, ratio: float = 8.0,
                 max_bytes: int = 256 << 20) -> None:
        self.config, self.base, self.tolerance = config, base, float(tolerance)
        self.ratio, self.max_bytes = float(ratio), int(max_bytes)
        self.reused = 0
        self._checkpoints: list[tuple[int, HeightGrid]] = []  # (scans fused, grid then)
        self._copy_rate = 1e9  # bytes a second a copy took (measured from the first)
        self._placed = np.zeros((0, 4, 4))  # the poses the last rebuild placed scans at
        self._kept: list = []  # the contributions it fused (the same objects are reused)
        self._reach: list[float] = []  # per scan, the farthest kept point or origin (m)

    def rebuild(self, poses: np.ndarray,
                contributions: list[Contribution | None]
                ) -> HeightGrid:
        """The grid of every scan's kept rays at `poses` (see the class docstring)."""
        c = self.config
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        if len(contributions) != len(poses):
            raise MapError(f"GridRebuilder: {len(contributions)} contributions for "
                           f"{len(poses)} poses")
        first = self._first_moved(poses, contributions) if c.window is None else 0
        self._checkpoints = [(k, g) for k, g in self._checkpoints if k <= first]
        if self._checkpoints:
            start, grid = self._checkpoints[-1][0], self._checkpoints[-1][1].copy()
        else:
            start = 0
            grid = HeightGrid(c) if self.base is None else HeightGrid.from_state(
                c, self.base, "base map")
            if c.window is not None:
                grid.recenter(float(poses[-1][0, 3]), float(poses[-1][1, 3]))
        placed = np.concatenate([self._placed[:start], poses[start:]])
        if not start:  # from a checkpoint, most tiles are there: insert allocates the rest
            _reserve_kept(grid, placed, contributions)
        fusing = 0.0  # seconds spent fusing since the last checkpoint
        for k in range(start, len(poses) + 1):
            if c.window is None and k > start \
                    and fusing >= self.ratio * grid.used_bytes / self._copy_rate:
                self._checkpoint(k, grid)
                fusing = 0.0
            if k < len(poses):
                began = time.perf_counter()
                insert_kept(grid, placed[k], contributions[k])
                fusing += time.perf_counter() - began
        self._placed, self._kept, self.reused = placed, list(contributions), start
        self._reach = self._reach[:start]
        return grid

    def _checkpoint(self, k: int, grid: HeightGrid) -> None:
        """Keep a copy of `grid` (k scans fused); thin the older copies to `max_bytes`."""
        began = time.perf_counter()
        copy = grid.copy()
        self._copy_rate = copy.used_bytes / max(time.perf_counter() - began, 1e-6)
        self._checkpoints.append((k, copy))
        while self._checkpoints and sum(g.used_bytes for _, g in self._checkpoints) \
                > self.max_bytes:
            if len(self._checkpoints) == 1:
                self._checkpoints = []
            else:
                *older, newest = self._checkpoints
                self._checkpoints = older[::2] + [newest]

    def _first_moved(self, poses: np.ndarray, contributions: list) -> int:
        """Index of the first scan to fuse again: moved beyond the tolerance, or not
        fused as it is now by the last rebuild."""
        n = min(len(poses), len(self._placed))
        same = next((k for k in range(n) if contributions[k] is not self._kept[k]), n)
        self._reach += [_reach(contributions[k]) for k in range(len(self._reach), same)]
        moved = _moved(self._placed[:same], poses[:same], np.asarray(self._reach[:same]),
                       self.tolerance * self.config.resolution)
        return int(np.argmax(moved)) if moved.any() else same


class SubmapRebuilder:
    """The grid after each optimisation from submaps: the grids of `scans` consecutive
    scans each, merged in order, each moved whole by its correction.

    A correction bends a long run smoothly, so that within a few metres of travel it is
    a rigid motion: a submap whose scans all moved, within `tolerance` cells at each kept
    ray's end, by the motion of its first scan (taken planar: x, y and yaw) is merged
    moved by it (`HeightGrid.merge`: a pass over its cells instead of its rays; for the
    3-D scanner's office, 0.23 s per 1000 scans against 5.1 s, `bench_loop_closure`); one
    it bent is fused again from its scans' kept rays at their new poses and kept so. The
    scans after the last whole submap are fused from their rays. `prepare` builds the
    submaps of scans mapped so far (the Mapper calls it in its rebuild thread as each
    fills, and after loading a map), so that a rebuild after a loop finds them built.
    Submaps count the scans that reached each cell (`HeightGrid(count_visits=True)`).

    What merging changes against `rebuild_grid` (`HeightGrid.merge`): a submap's scans
    clear an earlier submap's levels by a miss per scan that reached the cell, not per
    ray through the level, and levels hit in `static_scans` scans or more (walls; also
    the floor where a person stood) stay. A submap moved by a turn is resampled: its
    levels land in the cells their mean hits move to, and a cell is seen free only at
    heights free in every submap cell under it (so a wall whose level moved to the next
    cell leaves its own unknown, never free). Submaps each placed up to 0.3 m and 3 deg
    off and merged with their corrections, against the truth: the office (24 scans,
    submaps of 8) has no free cell on an obstacle (fusing every ray at the true poses: 4)
    and obstacle F1 1.0 with 2.4 % fewer free cells; the people scene (60 scans, submaps
    of 25) no free cell on an obstacle either, and 105 obstacle cells on true floor
    against 85: people one submap saw and the next saw through clear less
    (`test_grid_merge` holds these on 24 scans of each).

    base: a grid's `state()` every rebuild starts from. Called from one thread at a time;
    `reused`: the scans the last rebuild took from submaps it did not build again.
    """

    def __init__(self, config: GridConfig, base: dict[str, np.ndarray] | None = None,
                 scans: int = 25, tolerance: float = 0.25) -> None:
        if config.window is not None:
            raise MapError("SubmapRebuilder: a grid with a rolling window is rebuilt whole "
                           "(GridRebuilder)")
        if not (isinstance(scans, int) and scans >= 1):
            raise MapError(f"SubmapRebuilder: scans must be an integer >= 1, got {scans!r}")
        self.config, self.base, self.scans = config, base, scans
        self.tolerance = float(tolerance)
        self.reused = 0
        self._submaps: list[_Submap] = []

    def prepare(self, poses: np.ndarray, contributions: list[Contribution | None]) -> None:
        """Build the submaps of the whole runs of `scans` in `contributions` that have
        none yet, at `poses`."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        for j in range(len(poses) // self.scans):
            self._submap(j, poses, contributions)

    def rebuild(self, poses: np.ndarray, contributions: list[Contribution | None]
                ) -> HeightGrid:
        """The grid of every scan's kept rays at `poses` (see the class docstring)."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        if len(contributions) != len(poses):
            raise MapError(f"SubmapRebuilder: {len(contributions)} contributions for "
                           f"{len(poses)} poses")
        grid = HeightGrid(self.config) if self.base is None else HeightGrid.from_state(
            self.config, self.base, "base map")
        whole = len(poses) // self.scans
        self.reused = 0
        for j in range(whole):
            submap, motion = self._submap(j, poses, contributions)
            grid.merge(submap.grid, motion)
        for k in range(whole * self.scans, len(poses)):
            insert_kept(grid, poses[k], contributions[k])
        return grid

    def _submap(self, j: int, poses: np.ndarray, contributions: list[Contribution | None]
                ) -> tuple[_Submap, np.ndarray]:
        """Submap j at `poses`: the kept one and the planar motion that moves it there
        (counted in `reused`), or one built again there and no motion."""
        first, last = j * self.scans, (j + 1) * self.scans
        kept = contributions[first:last]
        if j < len(self._submaps):
            submap = self._submaps[j]
            if all(a is b for a, b in zip(submap.kept, kept, strict=True)):
                motion = _planar(poses[first] @ invert_pose(submap.placed[0]))
                if not _moved(motion @ submap.placed, poses[first:last], submap.reach,
                              self.tolerance * self.config.resolution).any():
                    self.reused += self.scans
                    return submap, motion
        grid = HeightGrid(self.config, count_visits=True)
        _reserve_kept(grid, poses[first:last], kept)  # its tiles exactly: no spare slots
        for pose, k in zip(poses[first:last], kept, strict=True):
            insert_kept(grid, pose, k)
        submap = _Submap(kept, poses[first:last].copy(), np.array([_reach(k) for k in kept]),
                         grid.packed())
        self._submaps[j:j + 1] = [submap]
        return submap, np.eye(4)


@dataclass(frozen=True, eq=False)
class _Submap:
    """A run of scans fused into a grid of its own: their contributions (the same
    objects), the poses they were placed at, their reach (m) and the grid, packed (what
    a merge reads, in a fifth of the memory)."""

    kept: list[Contribution | None]
    placed: np.ndarray
    reach: np.ndarray
    grid: PackedGrid


def _planar(pose: np.ndarray) -> np.ndarray:
    """The x, y and yaw of a 4x4 pose, as a 4x4 pose."""
    yaw = np.arctan2(pose[1, 0], pose[0, 0])
    out = np.eye(4)
    out[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    out[:2, 3] = pose[:2, 3]
    return out


def insert_kept(grid: HeightGrid, pose: np.ndarray,
                 kept: Contribution | None) -> None:
    """Fuse one scan's kept rays at `pose`."""
    if kept is not None:
        grid.insert(*kept.placed(pose), kept.stamp,
                    unlit=transform_points(pose, kept.unlit.astype(np.float64)),
                    lasers=kept.placed_lasers(pose))


def _reserve_kept(grid: HeightGrid, poses: np.ndarray,
                  contributions: list[Contribution | None]) -> None:
    """Allocate the tiles the kept rays at `poses` need, at once (`HeightGrid.reserve`)."""
    grid.reserve(kept.placed(pose)
                 for pose, kept in zip(poses, contributions, strict=True) if kept is not None)


def one_per_voxel(points: np.ndarray, voxel: float) -> np.ndarray:
    """Indices of one finite point per occupied voxel (the first), in order."""
    first, whole = first_per_voxel(points, voxel)
    if not whole:
        raise MapError(f"a scan's points span {COORD_LIMIT} voxels of {voxel} m or more: "
                       "not one scan's worth")
    return first


def _reach(kept: Contribution | None) -> float:
    """The farthest kept point or ray origin from the scan's base_link (m)."""
    if kept is None:
        return 0.0
    return float(np.sqrt(max(
        np.max(np.sum(np.square(kept.points, dtype=np.float64), axis=1), initial=0.0),
        np.max(np.sum(np.square(kept.origin_table, dtype=np.float64), axis=1),
               initial=0.0))))


def _moved(old: np.ndarray, new: np.ndarray, reach: np.ndarray, limit: float) -> np.ndarray:
    """Per scan placed at `old` instead of `new` (K, 4, 4): whether one of its kept rays'
    ends lies farther than `limit` (m) from where `new` puts it (`reach`: per scan, m)."""
    shift = np.linalg.norm(new[:, :3, 3] - old[:, :3, 3], axis=1)
    cosine = (np.einsum("kij,kij->k", old[:, :3, :3], new[:, :3, :3]) - 1.0) / 2.0
    chord = np.sqrt(np.clip(2.0 - 2.0 * cosine, 0.0, None))  # |R_new - R_old| on a vector
    return (shift + chord * reach > limit) & ~(new == old).all(axis=(1, 2))
