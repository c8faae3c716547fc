"""The Mapper: scans in; a registered, fused map and a current obstacle field out.

Per scan (`add`): register it against the local map of the previous scans
(`ScanOdometry`: odometry prior, de-skew, degeneracy), fuse its rays into the 2.5D grid
- each ray from the camera centre of its frame, at the pose of its frame, since the
robot may move during a 2 s scan (`scan_motion`) - and publish a new obstacle snapshot
around the robot (`ObstacleMap`), so a controller polling from another thread always
reads the newest consistent map. A scan whose registration failed is recorded in the
trajectory with its predicted pose but not fused: a smeared map is worse than a stale
one, and a stale obstacle field says so.

Loop closure (`MapperConfig.loop_closure.enabled`): each registered scan also goes to a
`LoopCloser`, which finds and verifies loops and optimises the pose graph in its own
thread. Poses are registration's poses moved by the newest correction. When an
optimisation has finished, the next `add` starts rebuilding the grid in the background
from each fused scan's points and ray origins kept in base_link (one per grid cell),
without the frames (`scanmap.mapping.rebuild`): by default from submaps of
`rebuild_submap_scans` scans, built in the same background thread as they fill and
merged each moved whole by its correction (`SubmapRebuilder`), else fusing every kept
ray again from where the previous rebuild has the scans before the first that moved
(`GridRebuilder`). The first `add` after the rebuild has finished fuses into it the
scans mapped meanwhile, swaps it in and moves every pose. Until then the map and the
obstacle queries stay as they were.

Scans come live from the `Scanner` (`start(ContinuousScanning(...))`: a background
thread, `mapping_thread`), from a recording or from processed scan files
(`scan_input.ScanSource`, offline at full speed: `map_scans`). `save` writes the whole
map to one `.npz` (`mapper_file`); `Mapper.load` reads it and resumes mapping: the next
scan registers against the points the robot saw last. Loop closure resumes the saved
graph; over a map saved without one it starts a new graph, the loaded scans fixed and
the loaded grid the base every rebuild starts from.

Clocks: obstacle queries are STALE when the newest scan is older than `max_age` by the
mapper's clock: `time.monotonic` by default (the live scanner's clock); `offline=True`
uses the data's own time (that of the obstacle field being read), for maps built from
files.
"""

from __future__ import annotations

import collections
import itertools
import math
import os
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from scanmap.graph import LoopCloser
from scanmap.graph.localise import Localisation, NotLocalised, Session
from scanmap.grid.height_grid import HeightGrid, InsertStats
from scanmap.grid.rays import laser_origins, scan_rays
from scanmap.grid.swept import swept_frames
from scanmap.grid.unlit import line_returns, unlit_floor
from scanmap.io.trajectory import Trajectory
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.rebuild import (
    Contribution,
    GridRebuilder,
    SubmapRebuilder,
    insert_kept,
    one_per_voxel,
    scan_contribution,
)
from scanmap.mapping.scan_motion import frame_poses
from scanmap.mapping.state_file import MapperState, load_state, save_state
from scanmap.mapping.stray_points import lone_low_points
from scanmap.mapping.thread import MappingThread
from scanmap.mapping.warm_up import warm_up
from scanmap.navigation.floor import Segmentation, segment
from scanmap.navigation.obstacles import ObstacleMap
from scanmap.registration import RegistrationResult, ScanOdometry
from scanmap.stage_clock import StageClock
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel, reference_scanner
from scanmap_driver.transforms import invert_pose, transform_points

_NO_POSE = np.full((4, 4), np.nan)


@dataclass(frozen=True, eq=False)
class MapUpdate:
    """What `Mapper.add` did with one scan.

    pose: base_link in map at the scan's start; registration: the full result; fused:
    whether its rays went into the grid; insert: the grid's account of them (None when not
    fused); timing: wall and CPU seconds per stage ("register", "fuse", "obstacles").
    """

    index: int
    stamp: float
    pose: np.ndarray
    registration: RegistrationResult
    fused: bool
    insert: InsertStats | None
    timing: StageClock


class Mapper:
    """Registers and fuses scans; `obstacles` answers queries from any thread."""

    def __init__(self, model: ScannerModel | None = None, config: MapperConfig | None = None,
                 *, clock: Callable[[], float] = time.monotonic, offline: bool = False,
                 initial_pose: np.ndarray | None = None) -> None:
        self.model = model or reference_scanner()
        config = config or MapperConfig()  # the floor rules take this scanner's geometry:
        self.config = replace(config, floor=config.floor.for_scanner(self.model))
        c = self.config
        self.grid = HeightGrid(c.grid)
        self.registration = ScanOdometry(c.registration, c.noise, initial_pose)
        self.obstacles = ObstacleMap(c.robot, c.max_age, clock=self._data_time if offline
                                     else clock, floor_params=c.floor)
        self._lock = threading.Lock()
        self._stamps: list[float] = []
        self._poses: list[np.ndarray] = []
        self._published = 0  # the scans whose map the obstacle queries answer from
        self._index: list[int] = []
        self._status: list[str] = []
        self._odometry: list[np.ndarray] = []
        self._recent: collections.deque[tuple[np.ndarray, np.ndarray]] = collections.deque(
            maxlen=c.resume_scans)  # (points in map, range sigma) of the newest fused scans
        self._kept: list[tuple[np.ndarray, np.ndarray]] = []  # overhead points, colours
        self._position = (math.nan, math.nan)  # where the robot was at the newest scan
        self.loop_closer = LoopCloser(c.loop_closure, c.registration) \
            if c.loop_closure.enabled else None
        self._applied = 0  # the loop closer's optimisations the map follows
        self._rebuilder = ThreadPoolExecutor(1, "scanmap-map-rebuild") \
            if self.loop_closer is not None else None
        self._rebuild: tuple[Future, np.ndarray] | None = None  # (grid, its poses)
        # Per scan, with loop closure: its fused points and ray origins in base_link (one
        # per grid cell) and its time, to rebuild the grid at corrected poses; None when
        # the scan was not fused.
        self._contributions: list[Contribution | None] = []
        # With loop closure over a map loaded without a graph: that map's grid (`state()`),
        # which every rebuild starts from.
        self._base: dict[str, np.ndarray] | None = None
        # The rebuild thread's, over _base; its submaps are built as scans come.
        self._rebuilds: GridRebuilder | SubmapRebuilder | None = None
        # A loaded map to locate the new session in first (`load(localise=True)`): its
        # path and the Session; the scans registered meanwhile; then where it was found.
        self._start: tuple[str, Session] | None = None
        self._pending: list[tuple[Scan, RegistrationResult]] = []  # registered, not located
        self.localisation: Localisation | None = None
        self._session = np.eye(4)  # map <- registration frame: moved once located

    # -- mapping -------------------------------------------------------------------------
    def add(self, scan: Scan) -> MapUpdate:
        """Register, fuse and publish one scan (see the module docstring)."""
        clock = StageClock()
        with self._lock:
            closer = self.loop_closer
            if closer is not None and (self._rebuild or closer.version != self._applied):
                with clock.stage("loop_closure"):
                    self._follow_graph()
            with clock.stage("register"):
                result = self.registration.register(scan)
            if self._start is not None:
                with clock.stage("localise"):
                    self._localise(scan, result)
                for kept, kept_result in self._pending[:-1]:
                    self._record(kept, kept_result, StageClock())
                self._pending = []
            pose, fused, stats = self._record(scan, result, clock)
        if fused and self.config.update_obstacles:
            with clock.stage("obstacles"):
                self.obstacles.update(self.grid, self._obstacle_bounds())
        self._published = len(self._poses)
        return MapUpdate(int(scan.index), float(scan.stamp), pose, result, fused, stats, clock)

    def _record(self, scan: Scan, result: RegistrationResult, clock: StageClock
                ) -> tuple[np.ndarray, bool, InsertStats | None]:
        """Put a registered scan in the graph, the trajectory and, if registered, the grid
        (call with the lock held): (its pose in the map, fused, the grid's account)."""
        closer = self.loop_closer
        pose = self._session @ result.pose
        if closer is not None:
            closer.add(pose, result, scan.points)
            pose = closer.correction() @ pose
            self._contributions.append(None)
        self._stamps.append(float(scan.stamp))
        self._poses.append(pose)
        self._index.append(int(scan.index))
        self._status.append(result.status.value)
        self._odometry.append(scan.odom_start if scan.has_odometry else _NO_POSE)
        fused = result.ok and len(scan) > 0
        stats = None
        if fused:  # a MapError here (beyond the extent) leaves the pose recorded
            with clock.stage("fuse"):
                stats = self._fuse(scan, pose)
        if closer is not None:
            self._prepare_submaps()
        return pose, fused, stats

    @property
    def localising(self) -> bool:
        """Whether the session is still to be located in the loaded map."""
        return self._start is not None

    def _localise(self, scan: Scan, result: RegistrationResult) -> None:
        """Locate the session in the loaded map (`scanmap.graph.localise.Session`): once
        located, registration goes on in the map frame (`_session`) and the first scan's
        graph node hangs on the keyframe matched; until then NotLocalised, naming the map,
        with the scan kept (call with the lock held)."""
        path, session = self._start
        self._pending.append((scan, result))
        try:
            found = session.add(scan.points, result.pose, result.ok)
        except NotLocalised as exc:
            raise NotLocalised(f"{path}: {exc}; scan {scan.index} is kept, to be mapped once "
                               f"the session is located") from None
        self._start = None
        self.localisation = found
        self._session = found.pose @ invert_pose(result.pose)
        self.loop_closer.join(found.node, found.information)
        self._recent.clear()

    def close_loops(self) -> None:
        """Wait for loop closure to process every scan, then move the map to its newest
        optimisation (offline, after the last scan; live, the next `add` does it)."""
        if self.loop_closer is None:
            return
        with self._lock:
            self._settle()
        if self.config.update_obstacles and len(self):
            self.obstacles.update(self.grid, self._obstacle_bounds())
        self._published = len(self._poses)

    def _settle(self) -> None:
        """Wait for the loop closer and every rebuild (call with the lock held)."""
        self.loop_closer.finish()
        while self._rebuild is not None or self.loop_closer.version != self._applied:
            self._follow_graph(wait=True)

    def _follow_graph(self, wait: bool = False) -> None:
        """Keep the map on the loop closer's newest optimisation (call with the lock held):
        swap in a finished rebuild (`wait`: wait for it), with the scans fused since it
        started; start a rebuild for a newer optimisation."""
        closer = self.loop_closer
        if self._rebuild is not None and (wait or self._rebuild[0].done()):
            future, poses = self._rebuild
            self._rebuild = None
            grid = future.result()
            n = len(poses)
            correction = poses[-1] @ invert_pose(closer.graph.poses[n - 1])
            for k in range(n, len(self._contributions)):
                self._poses[k] = correction @ closer.graph.poses[k]
                insert_kept(grid, self._poses[k], self._contributions[k])
            self._poses[:n] = list(poses)
            self.grid = grid
        if self._rebuild is None and closer.version != self._applied:
            self._applied = closer.version
            poses = closer.corrected_poses()
            self._rebuild = (self._rebuilder.submit(self._grid_rebuilder().rebuild, poses,
                                                    self._contributions[:len(poses)]), poses)

    def _grid_rebuilder(self) -> GridRebuilder | SubmapRebuilder:
        """The rebuild thread's rebuilder over the current base map (call with the lock
        held): submaps unless configured off or the grid has a rolling window."""
        if self._rebuilds is None or self._rebuilds.base is not self._base:
            c = self.config
            if c.rebuild_submap_scans is None or c.grid.window is not None:
                self._rebuilds = GridRebuilder(c.grid, self._base)
            else:
                self._rebuilds = SubmapRebuilder(c.grid, self._base, c.rebuild_submap_scans)
        return self._rebuilds

    def _prepare_submaps(self, resumed: bool = False) -> None:
        """When the newest scan completes a submap (`resumed`: a loaded map's scans), have
        the rebuild thread build them at the current poses, off the per-scan path (call
        with the lock held)."""
        rebuilder = self._grid_rebuilder()
        n = len(self._contributions)
        if isinstance(rebuilder, SubmapRebuilder) and n >= rebuilder.scans \
                and (resumed or n % rebuilder.scans == 0):
            self._rebuilder.submit(rebuilder.prepare, np.array(self._poses[:n]),
                                   self._contributions[:n])

    def _fuse(self, scan: Scan, pose: np.ndarray) -> InsertStats:
        c = self.config
        stray = lone_low_points(scan, c.robot.step_height, c.grid.resolution)
        if stray.any():  # a peak thrown off the stripe, not a hole (`stray_points`)
            scan = scan.select(~stray)
        poses = frame_poses(scan, pose)
        points, origins = scan_rays(scan, self.model, poses)
        lasers = laser_origins(scan, self.model, poses) if c.laser_rays else None
        returns = line_returns(scan, self.model)
        unlit = unlit_floor(scan, self.model, poses, returns)
        last = poses if poses.ndim == 2 else poses[scan.frame_index.max()]
        if c.grid.window is not None:
            self.grid.recenter(float(last[0, 3]), float(last[1, 3]))
        stats = self.grid.insert(points, origins, float(scan.time.max()),
                                 stood=poses[..., :2, 3].reshape(-1, 2),  # its whole path
                                 unlit=unlit, lasers=lasers,
                                 swept=swept_frames(scan, self.model, poses, returns)
                                 if c.swept else None)
        self._position = (float(last[0, 3]), float(last[1, 3]))
        self._recent.append((points, scan.range_sigma))
        if self.loop_closer is not None:
            self._contributions[-1] = scan_contribution(points, origins, pose,
                                                        float(scan.time.max()),
                                                        c.grid.resolution, unlit, lasers)
        if c.keep_points is not None:
            keep = one_per_voxel(points, c.keep_points)
            self._kept.append((points[keep].astype(np.float32), scan.colors[keep]))
        return stats

    def _obstacle_bounds(self) -> tuple[float, float, float, float] | None:
        window = self.config.obstacle_window
        if window is None:
            return None
        x, y = self._position
        return (x - 0.5 * window, y - 0.5 * window, x + 0.5 * window, y + 0.5 * window)

    def map_scans(self, scans: Iterable[Scan], progress: Callable[[MapUpdate], None] | None
                  = None) -> list[MapUpdate]:
        """Map scans in order, as fast as they come (items may also carry `.scan`)."""
        updates = []
        for item in scans:
            updates.append(self.add(getattr(item, "scan", item)))
            if progress:
                progress(updates[-1])
        return updates

    def start(self, source: Iterable | None = None, capacity: int = 4) -> MappingThread:
        """Map in a background thread: scans from `source` (a `ContinuousScanning`, any
        iterable of scans) or pushed with `submit`. Returns the `MappingThread`."""
        thread = MappingThread(self, source, capacity)
        thread.start()
        return thread

    def warm_up(self) -> None:
        """Compile every kernel now (`warm_up`), not on the first live scan."""
        warm_up(Mapper(self.model, self.config, offline=True))

    # -- reading -------------------------------------------------------------------------
    def _data_time(self) -> float:
        """Offline "now": the time of the obstacle field queries read (never stale)."""
        snapshot = self.obstacles.snapshot
        return self.grid.stamp if snapshot is None else snapshot.stamp

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def latest_pose(self) -> np.ndarray | None:
        """base_link in map at the start of the newest scan the obstacle queries answer
        from (None before the first scan): a controller asks the map of the scan whose
        pose it reads. A scan being fused and segmented shows once its map is published;
        its pose a fusion earlier put the robot where the map before it had not seen it
        stand, and the corridor's controller crept for one or two polls at every scan."""
        poses, published = self._poses, self._published
        return poses[published - 1] if published else None

    def trajectory(self) -> Trajectory:
        """One pose per scan, in order: base_link in map when the scan started."""
        with self._lock:
            return Trajectory(np.array(self._stamps), np.array(self._poses).reshape(-1, 4, 4))

    @property
    def statuses(self) -> list[str]:
        """Registration status of each scan (`registration.RegistrationStatus` values)."""
        return list(self._status)

    @property
    def scan_indices(self) -> list[int]:
        """Index of each mapped scan in its recording."""
        return list(self._index)

    def segment(self, bounds: tuple[float, float, float, float] | None = None) -> Segmentation:
        """Floor and obstacle layers of the map (inside bounds; default all of it)."""
        return segment(self.grid.layers(bounds), self.config.robot, self.config.floor)

    def kept_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The points kept for the overhead view (float32 (K, 3) in map, RGB (K, 3))."""
        with self._lock:
            return self._kept_points()

    def _kept_points(self) -> tuple[np.ndarray, np.ndarray]:
        if not self._kept:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
        return (np.concatenate([p for p, _ in self._kept]),
                np.concatenate([c for _, c in self._kept]))

    # -- files ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str], segmentation: Segmentation | None = None
             ) -> None:
        """Write the whole map to one .npz, atomically; safe while mapping continues.

        segmentation: derived obstacle/floor layers to store too (e.g. `segment()`).
        """
        with self._lock:
            if self.loop_closer is not None:
                self._settle()  # the graph of every scan so far, the map on it
            state = self._state()
        save_state(path, state, segmentation)

    def _state(self) -> MapperState:
        last = self._poses[-1] if self._poses else np.eye(4)
        to_base = invert_pose(last)
        if self._recent:
            resume = transform_points(to_base, np.concatenate([p for p, _ in self._recent]))
            sigma = np.concatenate([s for _, s in self._recent])
        else:
            resume, sigma = np.zeros((0, 3)), np.zeros(0)
        points, colours = self._kept_points()
        return MapperState(
            grid=self.grid, config=self.config, model=self.model,
            stamps=np.array(self._stamps, np.float64),
            poses=np.array(self._poses, np.float64).reshape(-1, 4, 4),
            index=np.array(self._index, np.int64), status=np.array(self._status, str),
            odometry=np.array(self._odometry, np.float64).reshape(-1, 4, 4),
            resume_points=resume, resume_sigma=sigma, points=points, point_colors=colours,
            loop_closure=self._loop_state())

    def _loop_state(self) -> dict[str, np.ndarray]:
        """The loop closer's graph and the per-scan kept points (none without loop closure)."""
        if self.loop_closer is None:
            return {}
        kept = [k for k in self._contributions if k is not None]
        empty = np.zeros((0, 3), np.float32)
        base = {} if self._base is None else {f"base_{k}": v for k, v in self._base.items()}
        lasers = [empty if not len(k.points) else k.lasers for k in kept]  # none: no rays
        emitters = {"kept_lasers": np.concatenate([empty, *lasers])} \
            if self.config.laser_rays and all(e is not None for e in lasers) else {}
        return {**self.loop_closer.state(), **base, **emitters,
                "kept_points": np.concatenate([empty, *(k.points for k in kept)]),
                "kept_origins": np.concatenate([empty, *(k.origins for k in kept)]),
                "kept_sizes": np.array([-1 if k is None else len(k.points)
                                        for k in self._contributions], np.int64),
                "kept_stamps": np.array([k.stamp for k in kept], np.float64),
                "kept_unlit": np.concatenate([empty, *(k.unlit for k in kept)]),
                "kept_unlit_sizes": np.array([len(k.unlit) for k in kept], np.int64)}

    def _resume_loops(self, state: MapperState) -> None:
        """Continue the saved pose graph; a map saved without one starts a new graph whose
        first nodes are its scans, fixed, and its grid the base every rebuild starts from."""
        self.loop_closer.close()
        c = self.config
        loops = state.loop_closure
        if not loops:
            self.loop_closer = LoopCloser.extending(state.poses, c.loop_closure, c.registration)
            self._contributions = [None] * len(state.poses)
            self._base = state.grid.state()
            return
        self.loop_closer = LoopCloser.restore(loops, c.loop_closure, c.registration)
        self._contributions = _split_kept(loops)
        base = {k[len("base_"):]: v for k, v in loops.items() if k.startswith("base_")}
        self._base = base or None
        self._prepare_submaps(resumed=True)

    @classmethod
    def load(cls, path: str | os.PathLike[str], *, clock: Callable[[], float] = time.monotonic,
             offline: bool = False, config: MapperConfig | None = None,
             localise: bool = False, hint: np.ndarray | None = None) -> Mapper:
        """A Mapper continuing the map saved at `path`.

        The next scan registers against the newest scans saved with the map, with the
        odometry of the last scan as the prior's reference: keep the robot's odometry
        running between sessions (or give scans without odometry). config: replaces the
        saved settings except the grid's.

        localise: the robot may have been moved since: the new session's scans are
        registered in a frame of their own and located in the map (`scanmap.graph.localise`:
        near `hint`, a 4x4 pose in the map where the robot stands at the first scan, or
        where it stopped, else by place), the newest with those of the last
        `context_distance` of travel; then mapping goes on in the map. Needs a map saved
        with loop closure (its keyframes). Until located, `add` raises NotLocalised,
        naming the file; the scans are kept and mapped once it is.
        """
        state = load_state(path)
        config = state.config if config is None else replace(config, grid=state.config.grid)
        if localise and not (config.loop_closure.enabled and state.loop_closure):
            raise NotLocalised(f"{path}: to localise in a map it must have been saved with "
                               f"loop closure on (its keyframes are the places looked up)")
        last = state.poses[-1] if len(state.poses) else None
        mapper = cls(state.model, config, clock=clock, offline=offline, initial_pose=last)
        mapper.grid = state.grid
        mapper._stamps = state.stamps.tolist()
        mapper._poses = list(state.poses)
        mapper._published = len(mapper._poses)
        mapper._index = state.index.tolist()
        mapper._status = state.status.tolist()
        mapper._odometry = list(state.odometry)
        if len(state.points):
            mapper._kept = [(state.points, state.point_colors)]
        if mapper.loop_closer is not None:
            mapper._resume_loops(state)
        if localise:  # a new session: registered in its own frame until located
            hints = [np.asarray(hint, dtype=np.float64)] if hint is not None else \
                [] if last is None else [last]
            mapper._start = (os.fspath(path), Session(mapper.loop_closer, hints))
            mapper.registration = ScanOdometry(config.registration, config.noise)
        elif last is not None and len(state.resume_points):
            odometry = state.odometry[-1]
            mapper.registration.register_points(
                state.resume_points, stamp=float(state.stamps[-1]),
                odometry=odometry if np.isfinite(odometry).all() else None,
                range_sigma=state.resume_sigma)
            mapper._recent.append((transform_points(last, state.resume_points),
                                   state.resume_sigma))
            mapper._position = (float(last[0, 3]), float(last[1, 3]))
            if config.update_obstacles:
                mapper.obstacles.update(mapper.grid, mapper._obstacle_bounds())
        return mapper


def _split_kept(loops: dict[str, np.ndarray]) -> list[Contribution | None]:
    """The per-scan kept points of a map file's loop-closure arrays, as the Mapper keeps
    them (without unlit floor or laser emitters in a file written before they were
    kept)."""
    sizes = loops["kept_sizes"]
    fused = sizes >= 0
    bounds = np.cumsum(sizes[fused])[:-1]
    points = iter(np.split(loops["kept_points"], bounds))
    origins = iter(np.split(loops["kept_origins"], bounds))
    stamps = iter(loops["kept_stamps"].tolist())
    unlit_sizes = loops.get("kept_unlit_sizes", np.zeros(int(fused.sum()), np.int64))
    unlit = iter(np.split(loops.get("kept_unlit", np.zeros((0, 3), np.float32)),
                          np.cumsum(unlit_sizes)[:-1]))
    lasers = iter(np.split(loops["kept_lasers"], bounds)) if "kept_lasers" in loops \
        else itertools.repeat(None)
    return [Contribution.of_rays(next(points), next(origins), next(stamps), next(unlit),
                                 next(lasers)) if f else None for f in fused]
