"""The 2.5D grid: insertion speed against OctoMap, distance field, queries, and accuracy on
the simulator's office (ideal scans, scored against its truth raster and its geometry).

    .venv/bin/python -m benchmarks.bench_grid [--quick]

Rows:
* insert: one 20,000-point scan with ray clearing at 5 cm (steady state, grid already
  holding the office), ours (bundled rays, and every ray traced) against OctoMap's
  insertPointCloud at 0.05 m with each frame's camera centre as origin, same points.
* distance field: exact EDT of a 20 m x 20 m window (400 x 400), against scipy's and
  OpenCV's, all scored against a k-d tree search for the nearest blocked cell.
* distance(): per point, batches of 1e6; obstacle_distance(), the same batch, against a
  SciPy k-d tree over the snapshot's obstacle points (built beforehand, as our distance
  field is: the query alone is timed), which also gives the exact distance it is scored
  against; nearest(): one call from Python while another thread inserts scans (median
  and p99).
* window read: `HeightGrid.layers` of an 8 m window after 10 and after 10,000 scans of a
  robot driving (what the grid keeps per scan must not slow each scan's read).
* accuracy: obstacle-cell F1 in the robot band (recall over the cells true points in the
  band fell in), floor precision/recall (recall over the cells true floor points fell
  in), FREE cells on true obstacles, nearest-obstacle distance error (p95) at random
  floor points against the exact scene geometry; OctoMap's F1 as the peer. The error
  column is the fair figure, the strict one is beside it: fair leaves out the cells an
  object's face only grazes (`mixed_cells`: a face on a cell edge, whose class rounding
  decides), and, for distances, the queries whose nearest object no scan saw (after few
  scans, part of the room is unseen: a map cannot know it, and its clearance, which
  counts unknown space, stays below the truth there).
Every peer runs in a process of its own with a time limit (`run_isolated`): a crash or a
hang is reported as that peer's failure, in its place.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.isolation import PeerFailed, run_isolated
from benchmarks.timing import first_call_time, median_time
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.rays import scan_rays
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor import DROP_OFF, FREE, OBSTACLE, UNKNOWN, RobotShape, segment
from scanmap.navigation.obstacles import ObstacleMap
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.raster import FLOOR, truth_raster
from scanmap_driver.sim.raster import OBSTACLE as TRUE_OBSTACLE
from scanmap_driver.sim.scene import Box, load_scene

OFFICE = Path(__file__).resolve().parents[1] / "scanmap_driver" / "sim" / "scenes" / "office.json"
ROBOT = RobotShape()
EDGE_TOLERANCE = 0.002  # m: a face this close to a cell edge only grazes the cell
SEEN_TOLERANCE = 0.01  # m: a query's nearest object was seen if a true hit is this close


def office_rays(quick: bool) -> tuple[object, list[tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         np.ndarray]]]:
    """The office scene and, per ideal scan: map points, origins, frame index, true points."""
    scene = load_scene(OFFICE)
    model = reference_scanner()
    out = []
    for ideal in ideal_scans(scene, model, scans=6 if quick else None):
        points, origins = scan_rays(ideal.scan, model, ideal.frame_poses)
        pose = ideal.frame_poses[ideal.scan.frame_index]
        true = np.einsum("nij,nj->ni", pose[:, :3, :3], ideal.true_points) + pose[:, :3, 3]
        out.append((points, origins, ideal.scan.frame_index, true))
    return scene, out


def cells_of(points: np.ndarray, origin: np.ndarray, res: float, shape) -> tuple:
    """Row, column of each point, keeping those inside the raster."""
    col = np.floor((points[:, 0] - origin[0]) / res).astype(int)
    row = np.floor((points[:, 1] - origin[1]) / res).astype(int)
    keep = (row >= 0) & (row < shape[0]) & (col >= 0) & (col < shape[1])
    return row[keep], col[keep]


def f1(predicted: np.ndarray, truth: np.ndarray, observable: np.ndarray,
       scored: np.ndarray) -> tuple[float, float]:
    """F1 over the `scored` cells, with recall over the observable truth cells and over
    every truth cell."""
    predicted, truth = predicted & scored, truth & scored
    precision = (predicted & truth).sum() / max(predicted.sum(), 1)
    scores = []
    for reference in (truth & observable, truth):
        recall = (predicted & reference).sum() / max(reference.sum(), 1)
        scores.append(2 * precision * recall / max(precision + recall, 1e-12))
    return scores[0], scores[1]


def mixed_cells(scene, reference) -> np.ndarray:
    """Cells that an object's face only grazes: their truth class flips when every object
    grows or shrinks by EDGE_TOLERANCE, so the face lies on (or within 2 mm of) a cell
    edge. The office's walls, cabinet, shelf and sideboard have their faces on multiples
    of 5 cm: whether the cell beside a face holds a zero-area sliver of it is settled by
    floating-point rounding in the raster and by range noise in the map. These cells are
    "don't care" in the fair figures (both the map's and the truth's class ignored) and
    scored in the strict ones; a face crossing a cell is never excused."""
    return object_cells(scene, reference, EDGE_TOLERANCE) \
        != object_cells(scene, reference, -EDGE_TOLERANCE)


def object_cells(scene, reference, delta: float) -> np.ndarray:
    """(rows, cols) of `reference`'s cells that the scene's objects in the robot's band
    overlap once each has grown by `delta` (m) on every side; shrunk (delta < 0), the
    cells some object reaches more than -delta into (an object no thicker than -2 delta
    reaches into none)."""
    objects = [replace(o, size=(o.size[0] + 2 * delta, o.size[1] + 2 * delta, o.size[2]))
               if isinstance(o, Box) else replace(o, radius=o.radius + delta)
               for o in scene.objects]
    objects = [o for o in objects
               if (min(o.size[:2]) if isinstance(o, Box) else o.radius) > 1e-9]  # not a plane
    raster = truth_raster(replace(scene, objects=objects), 0.05, ROBOT.step_height,
                          ROBOT.height)
    out = np.zeros(reference.classes.shape, bool)  # on the reference's cells
    dx, dy = np.rint((raster.origin - reference.origin) / 0.05).astype(int)
    ny, nx = raster.classes.shape
    rows = slice(max(dy, 0), min(dy + ny, out.shape[0]))
    cols = slice(max(dx, 0), min(dx + nx, out.shape[1]))
    out[rows, cols] = (raster.classes == TRUE_OBSTACLE)[rows.start - dy:rows.stop - dy,
                                                        cols.start - dx:cols.stop - dx]
    return out


def true_distance(scene, q: np.ndarray) -> np.ndarray:
    """Exact distance from (x, y) to the nearest object footprint in the robot band."""
    best = np.full(len(q), np.inf)
    for obj in scene.objects:
        height = obj.size[2] if isinstance(obj, Box) else obj.height
        if not (obj.center[2] + height / 2 > ROBOT.step_height
                and obj.center[2] - height / 2 < ROBOT.height):
            continue
        d = q - np.array(obj.center[:2])
        if isinstance(obj, Box):
            c, s = math.cos(obj.yaw), math.sin(obj.yaw)
            local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
            outside = np.maximum(np.abs(local) - np.array(obj.size[:2]) / 2, 0.0)
            best = np.minimum(best, np.hypot(outside[:, 0], outside[:, 1]))
        else:
            best = np.minimum(best, np.maximum(np.hypot(d[:, 0], d[:, 1]) - obj.radius, 0.0))
    return best


@dataclass(frozen=True)
class Truth:
    """The office's truth raster and what the scans could see of it (same cells)."""

    raster: object
    observable: np.ndarray  # cells a true point in the robot band fell in
    floor_seen: np.ndarray  # cells a true floor point fell in
    scored: np.ndarray  # cells not mixed (mixed_cells)
    band_points: np.ndarray  # (N, 2) the true points in the band

    @classmethod
    def of(cls, scene, scans) -> Truth:
        raster = truth_raster(scene, 0.05, ROBOT.step_height, ROBOT.height)
        shape = raster.classes.shape
        true_points = np.vstack([t for *_, t in scans])
        in_band = (true_points[:, 2] > ROBOT.step_height) & (true_points[:, 2] < ROBOT.height)
        observable = np.zeros(shape, bool)
        observable[cells_of(true_points[in_band], raster.origin, 0.05, shape)] = True
        floor_seen = np.zeros(shape, bool)
        floor_seen[cells_of(true_points[np.abs(true_points[:, 2]) < 0.01], raster.origin,
                            0.05, shape)] = True
        return cls(raster, observable, floor_seen, ~mixed_cells(scene, raster),
                   true_points[in_band, :2])

    def obstacle_f1(self, predicted: np.ndarray) -> dict[str, float]:
        """F1 of predicted obstacle cells: fair (mixed cells not scored) and strict."""
        true_obstacle = self.raster.classes == TRUE_OBSTACLE
        everything = np.ones(true_obstacle.shape, bool)
        fair, _ = f1(predicted, true_obstacle, self.observable, self.scored)
        strict, strict_all = f1(predicted, true_obstacle, self.observable, everything)
        return {"f1": fair, "f1_strict": strict, "f1_strict_all_truth_cells": strict_all}


def floor_scores(seg, truth: Truth, scored: np.ndarray) -> tuple[float, float, int]:
    """Floor precision, recall (over true floor cells a true floor point fell in) and the
    FREE cells on true obstacles, over the `scored` cells."""
    true_floor = truth.raster.classes == FLOOR
    is_floor = seg.is_floor & scored
    precision = (is_floor & true_floor).sum() / max(is_floor.sum(), 1)
    reference = true_floor & truth.floor_seen & scored
    recall = (is_floor & reference).sum() / max(reference.sum(), 1)
    free_on_obstacle = (seg.state == FREE) & (truth.raster.classes == TRUE_OBSTACLE) & scored
    return float(precision), float(recall), int(free_on_obstacle.sum())


def accuracy_rows(scene, scans, grid: HeightGrid, octomap_f1: dict | None,
                  octomap_failed: str | None = None) -> list[dict]:
    """Score the grid against the truth raster and the scene geometry."""
    truth = Truth.of(scene, scans)
    ny, nx = truth.raster.classes.shape
    x0, y0 = map(float, truth.raster.origin)
    obstacles = ObstacleMap(ROBOT, max_age=1e9, clock=lambda: grid.stamp)
    snap = obstacles.update(grid, (x0, y0, x0 + nx * 0.05, y0 + ny * 0.05))
    seg = snap.segmentation
    assert seg.shape == (ny, nx)
    scores = truth.obstacle_f1(seg.state == OBSTACLE)
    precision, recall, free_on_obstacle = floor_scores(seg, truth, truth.scored)
    strict = floor_scores(seg, truth, np.ones((ny, nx), bool))
    true_floor = truth.raster.classes == FLOOR
    rows_f, cols_f = np.nonzero(true_floor)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(rows_f), min(20000, len(rows_f)), replace=False)
    q = np.column_stack([x0 + (cols_f[pick] + rng.random(len(pick))) * 0.05,
                         y0 + (rows_f[pick] + rng.random(len(pick))) * 0.05])
    truth_d = true_distance(scene, q)
    keep = truth_d > 0.0
    q, truth_d = q[keep], truth_d[keep]
    error = np.abs(obstacles.obstacle_distance(q) - truth_d)
    nearest_seen = cKDTree(truth.band_points).query(q)[0] <= truth_d + SEEN_TOLERANCE
    clearance = obstacles.distance(q)
    peers = {}
    if octomap_f1 is not None:
        peers["octomap"] = {"error": 1.0 - octomap_f1["f1"], "f1_strict": octomap_f1["f1_strict"]}
    elif octomap_failed:
        peers["octomap"] = {"failed": octomap_failed}
    settings = (f"office, {len(scans)} ideal scans, band {ROBOT.step_height}-{ROBOT.height} m; "
                f"fair: {int((~truth.scored).sum())} cells a face only grazes not scored")
    return [
        {"stage": "grid accuracy", "method": "obstacle cells", "settings": settings,
         "median_s": None, "error": 1.0 - scores["f1"],
         "error_unit": "1 - F1 (observable cells, fair)", **scores,
         "mixed_cells": int((~truth.scored).sum()),
         "unknown_fraction_of_floor": float((seg.state[true_floor] == UNKNOWN).mean()),
         "free_fraction_of_floor": float((seg.state[true_floor] == FREE).mean()),
         "peers": peers},
        {"stage": "grid accuracy", "method": "floor cells", "settings": settings,
         "median_s": None, "error": 1.0 - min(precision, recall),
         "error_unit": "1 - min(precision, recall) (fair)", "precision": precision,
         "recall": recall, "precision_strict": strict[0], "recall_strict": strict[1],
         "free_on_true_obstacle_cells": free_on_obstacle,
         "free_on_true_obstacle_cells_strict": strict[2], "peers": {}},
        {"stage": "grid accuracy", "method": "nearest obstacle distance", "settings": settings
         + f", and queries whose nearest object no scan saw ({1 - nearest_seen.mean():.1%})",
         "median_s": None, "error": float(np.percentile(error[nearest_seen], 95)),
         "error_unit": "m (p95, fair)", "p95_strict": float(np.percentile(error, 95)),
         "median_error": float(np.median(error)),
         "clearance_over_truth_max": float((clearance - truth_d).max()),
         "clearance_equals_obstacle_fraction": float(np.mean(clearance >= truth_d - 0.03)),
         "peers": {}},
    ]


def octomap_frames(scan) -> list[tuple[np.ndarray, np.ndarray]]:
    """The scan as OctoMap takes it, one point cloud per camera frame: its points
    (contiguous float64) and its camera centre. Split before timing: a user gets the
    frames one by one."""
    points, origins, frames, _ = scan
    return [(np.ascontiguousarray(points[frames == f]), origins[frames == f][0])
            for f in np.unique(frames)]


def octomap_peer(scans, timed_frames, repeats: int) -> dict:
    """OctoMap as a user of this scanner would run it, every scan of `scans` inserted:
    insertPointCloud per frame with that frame's camera centre as origin (the head turns
    the camera 7 cm round the axis), whole beams (maxrange -1: the scanner already drops
    points beyond its 4 m range; a shorter maxrange would turn its far points into free
    space), inner nodes updated (lazy_eval off: a user then has a map to query). Returns
    the occupied voxel centres of the plain tree (before any timing) and the median CPU
    time of inserting `timed_frames` into a tree already holding the office, plain and
    with `discretize` (OctoMap's option to trace one ray per endpoint voxel). OctoMap runs
    on one core here (this build's OpenMP loop uses one thread: CPU time equals wall
    time). Run in a process of its own (`run_isolated`)."""
    import octomap

    occupied, seconds = None, {}
    for name, discretize in (("octomap 0.05 m", False), ("octomap 0.05 m, discretize", True)):
        tree = octomap.OcTree(0.05)

        def insert(frames, tree=tree, discretize=discretize) -> None:
            for points, origin in frames:
                tree.insertPointCloud(points, origin, discretize=discretize)

        for scan in scans:
            insert(octomap_frames(scan))
        if occupied is None:
            occupied = np.asarray(tree.extractPointCloud()[0])
        seconds[name] = median_time(lambda i=insert: i(timed_frames), repeats=repeats,
                                    clock=time.thread_time)
    return {"occupied": occupied, "median_s": seconds}


def octomap_f1(occupied: np.ndarray, truth_scene, scans) -> dict[str, float]:
    """OctoMap's occupied voxels in the robot band, projected to 2-D cells, scored."""
    truth = Truth.of(truth_scene, scans)
    band = (occupied[:, 2] > ROBOT.step_height) & (occupied[:, 2] < ROBOT.height)
    predicted = np.zeros(truth.raster.classes.shape, bool)
    predicted[cells_of(occupied[band], truth.raster.origin, 0.05, predicted.shape)] = True
    return truth.obstacle_f1(predicted)


def timed_scan(scans, n: int = 20_000):
    """The middle scan cut (or repeated) to exactly n rays, whole frames first."""
    points, origins, frames, true = scans[len(scans) // 2]
    index = np.arange(n) % len(points)
    return points[index], origins[index], frames[index], true[index]


def insertion_rows(scans, grid_config: GridConfig, quick: bool, octomap: dict) -> list[dict]:
    """Insertion of one 20,000-ray scan into a grid (and OctoMaps) already holding the
    office: CPU time on one core (time.thread_time), which the other jobs sharing the
    machine disturb less than wall time. `octomap`: `octomap_peer`'s answer or a failure."""
    scan = timed_scan(scans)
    points, origins, _, _ = scan
    frames = len(octomap_frames(scan))
    rows = []
    repeats = 5 if quick else 30
    peers = ({name: {"median_s": t} for name, t in octomap["median_s"].items()}
             if "median_s" in octomap else {"octomap 0.05 m": octomap})
    for label, config in (("bundled rays (default)", grid_config),
                          ("every ray traced", GridConfig(bundle_run=0))):
        grid = HeightGrid(config)
        compile_s = first_call_time(lambda g=grid: g.insert(points[:10], origins[:10], -1.0))
        for k, (p, o, _, _) in enumerate(scans):
            grid.insert(p, o, float(k))
        stamp = [len(scans)]

        def insert(g=grid, stamp=stamp) -> None:
            stamp[0] += 1
            g.insert(points, origins, float(stamp[0]))

        ours = median_time(insert, repeats=repeats, clock=time.thread_time)
        rows.append({"stage": "grid insert", "method": f"numba, {label}",
                     "settings": f"20,000 rays ({frames} frames), 5 cm cells, office, "
                                 "map already built; CPU time, one core",
                     "median_s": ours, "error": None, "compile_s": compile_s,
                     "peers": peers})
    return rows


def scipy_edt(free: np.ndarray, repeats: int) -> tuple[float, np.ndarray]:
    """scipy's exact EDT of `free` (with nearest indices, as ours): median CPU time and the
    distances. Run in a process of its own (`run_isolated`)."""
    from scipy import ndimage

    seconds = median_time(lambda: ndimage.distance_transform_edt(free, return_indices=True),
                          repeats=repeats, clock=time.thread_time)
    return seconds, ndimage.distance_transform_edt(free)


def cv2_edt(free: np.ndarray, repeats: int) -> tuple[float, np.ndarray]:
    """OpenCV's distanceTransform of `free` (L2, precise mask; no nearest index): median
    CPU time and the distances. Run in a process of its own (`run_isolated`)."""
    import cv2

    image = free.astype(np.uint8)
    seconds = median_time(lambda: cv2.distanceTransform(image, cv2.DIST_L2,
                                                        cv2.DIST_MASK_PRECISE),
                          repeats=repeats, clock=time.thread_time)
    return seconds, cv2.distanceTransform(image, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


EDT_PEERS = {"scipy edt": scipy_edt, "cv2 distanceTransform (no index)": cv2_edt}


def exact_distance(blocked: np.ndarray) -> np.ndarray:
    """Distance (cells) from every cell to the nearest blocked cell, by a k-d tree search:
    the truth the transforms are scored against."""
    rows, cols = np.indices(blocked.shape)
    cells = np.column_stack([rows.ravel(), cols.ravel()])
    distance, _ = cKDTree(cells[blocked.ravel()]).query(cells)
    return distance.reshape(blocked.shape)


def field_rows(grid: HeightGrid, quick: bool) -> list[dict]:
    """EDT of a 20 m x 20 m window around the office (blocked = not known free)."""
    layers = grid.layers((-8.0, -10.0, 12.0, 10.0))
    seg = segment(layers, ROBOT)
    blocked = seg.state != 1
    assert blocked.shape == (400, 400)
    first = first_call_time(lambda: distance_transform(blocked))
    ours = median_time(lambda: distance_transform(blocked), repeats=5 if quick else 30,
                       clock=time.thread_time)
    exact = exact_distance(blocked)
    peers = {}
    for name, peer in EDT_PEERS.items():
        try:
            seconds, distance = run_isolated(peer, ~blocked, 3 if quick else 10)
            peers[name] = {"median_s": seconds, "error": float(np.abs(distance - exact).max())}
        except PeerFailed as exc:  # a peer that fails is reported in its place
            peers[name] = {"failed": str(exc)}
    distance, _ = distance_transform(blocked)
    return [{"stage": "distance field", "method": "numba Felzenszwalb-Huttenlocher",
             "settings": "20 m x 20 m at 5 cm (400 x 400), with nearest index, CPU time",
             "median_s": ours, "error": float(np.abs(distance - exact).max()),
             "error_unit": "cells (max vs k-d tree nearest blocked cell)",
             "compile_s": first, "peers": peers}]


def kdtree_distance(targets: np.ndarray, queries: np.ndarray,
                    repeats: int) -> tuple[float, np.ndarray]:
    """SciPy's k-d tree over `targets` (built once, untimed), queried for every row of
    `queries` on one thread: median CPU time of the query and the distances. Run in a
    process of its own (`run_isolated`)."""
    tree = cKDTree(targets)
    seconds = median_time(lambda: tree.query(queries, workers=1), repeats=repeats,
                          clock=time.thread_time)
    return seconds, tree.query(queries, workers=1)[0]


def query_rows(grid: HeightGrid, scans, quick: bool) -> list[dict]:
    clock = [grid.stamp]
    obstacles = ObstacleMap(ROBOT, max_age=1e9, clock=lambda: clock[0])
    obstacles.update(grid)
    q = np.random.default_rng(1).uniform([-1.0, -2.5], [5.0, 2.5], (1_000_000, 2))
    obstacles.distance(q[:10])
    obstacles.obstacle_distance(q[:10])
    repeats = 3 if quick else 10
    batch = median_time(lambda: obstacles.distance(q), repeats=repeats, clock=time.thread_time)
    rows = [{"stage": "distance query", "method": "distance(points), numba",
             "settings": "batch of 1e6 points, CPU time", "median_s": batch / len(q),
             "error": None,
             "peers": {}}]
    ours = median_time(lambda: obstacles.obstacle_distance(q), repeats=repeats,
                       clock=time.thread_time)
    seg = obstacles.snapshot.segmentation
    targets = seg.points[(seg.state == OBSTACLE) | (seg.state == DROP_OFF)]  # as the field
    distance = obstacles.obstacle_distance(q)
    try:
        seconds, exact = run_isolated(kdtree_distance, targets, q, repeats)
        peer = {"median_s": seconds / len(q), "error": 0.0}
        error = float(np.abs(distance - exact).max())
    except PeerFailed as exc:  # reported in its place; ours then goes unscored
        peer, error = {"failed": str(exc)}, None
    rows.append({"stage": "distance query", "method": "obstacle_distance(points), numba",
                 "settings": f"batch of 1e6 points, {len(targets)} obstacle cells, CPU time",
                 "median_s": ours / len(q), "error": error,
                 "error_unit": "m (max vs the k-d tree's exact distance)",
                 "peers": {"scipy cKDTree (built beforehand)": peer}})
    stop = threading.Event()

    def mapper() -> None:
        k = 1000
        while not stop.is_set():
            for points, origins, _, _ in scans:
                if stop.is_set():
                    break
                k += 1
                grid.insert(points, origins, float(k))

    thread = threading.Thread(target=mapper)
    thread.start()
    try:
        obstacles.nearest(1.0, 0.5)
        times = np.empty(20_000 if quick else 200_000)
        for i in range(len(times)):
            start = time.perf_counter()
            obstacles.nearest(1.0, 0.5)
            times[i] = time.perf_counter() - start
    finally:
        stop.set()
        thread.join()
    rows.append({"stage": "nearest query", "method": "nearest(x, y) from Python",
                 "settings": "while another thread inserts scans",
                 "median_s": float(np.median(times)), "p99_s": float(np.percentile(times, 99)),
                 "error": None, "peers": {}})
    return rows


def window_read_rows(quick: bool) -> list[dict]:
    """`HeightGrid.layers` of an 8 m window round the robot after a long run: a robot
    driving 0.4 m a scan up and down 40 m of corridor (two hits a scan, its path given as
    where it stood), read after 10 scans and after many. What a grid keeps per scan (its
    time, where the robot stood) must not make each scan's read slower as the run goes
    on (`scanmap.grid.growing`)."""
    grid = HeightGrid(GridConfig(extent=100.0))
    hits = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.2]])
    rows, done = [], 0
    for scans in (10, 2_000 if quick else 10_000):
        while done < scans:
            x = 0.4 * (done % 100)
            path = np.column_stack([np.linspace(x, x + 0.4, 17), np.zeros(17)])
            grid.insert(hits + [x, 0.0, 0.0], np.array([x, 0.0, 1.0]), float(done),
                        stood=path)
            done += 1
        x = 0.4 * (done % 100)
        window = (x - 4.0, -4.0, x + 4.0, 4.0)
        rows.append({"stage": "grid window read", "method": "HeightGrid.layers, 8 m window",
                     "settings": f"after {scans} scans of a robot driving 0.4 m a scan "
                                 "(its path kept); CPU time, one core",
                     "median_s": median_time(lambda w=window: grid.layers(w), repeats=20,
                                             clock=time.thread_time),
                     "error": None, "peers": {}})
    return rows


def run(quick: bool = False) -> list[dict]:
    """Every row of this module (see its docstring)."""
    scene, scans = office_rays(quick)
    config = GridConfig()
    grid = HeightGrid(config)
    for k, (points, origins, _, _) in enumerate(scans):
        grid.insert(points, origins, float(k))
    try:
        octomap = run_isolated(octomap_peer, scans, octomap_frames(timed_scan(scans)),
                               3 if quick else 7)
        octomap_scores = octomap_f1(octomap["occupied"], scene, scans)
    except PeerFailed as exc:  # a peer that fails is reported in its place
        octomap, octomap_scores = {"failed": str(exc)}, None
    rows = accuracy_rows(scene, scans, grid, octomap_scores, octomap.get("failed"))
    rows += insertion_rows(scans, config, quick, octomap)
    rows += field_rows(grid, quick)
    rows += query_rows(grid, scans, quick)
    rows += window_read_rows(quick)
    return rows


if __name__ == "__main__":
    import argparse

    from benchmarks.report import markdown_table

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="6 scans, fewer repeats")
    table = run(quick=parser.parse_args().quick)
    print(markdown_table(table))
    for row in table:
        extra = {k: v for k, v in row.items() if k not in
                 ("stage", "method", "settings", "median_s", "error", "error_unit", "peers")}
        print(row["stage"], "|", row["method"], "|", extra)
