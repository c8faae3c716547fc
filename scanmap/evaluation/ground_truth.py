"""Errors of a mapping run against a simulator's ground truth (a recording's `ground_truth/`).

* range: per measured point, its horizontal range from the scanner axis minus the true
  range of the laser point on the same image column of the same frame (the column is
  recovered by projecting the point back into the camera with its measured heading, so
  heading errors do not leak in). `matched` is the fraction of true laser points measured.
* heading: per frame, the decoded heading minus the true one (wrapped).
* trajectory: ATE RMSE of the scan poses after SE(2) alignment (`trajectory.ate_rmse`).
* map: obstacle cells against the truth raster, in the world frame (the map frame is
  placed by the true pose of the first scan: where the robot started). Precision: the
  map's obstacle cells within one cell of a true obstacle, among those on cells the
  truth classes (floor, obstacle or drop-off: not outside, where no robot goes, behind a
  wall, on a platform's top or up a too steep ramp, which the map rightly calls
  obstacles too); recall: true obstacle cells
  with a map obstacle within one cell, among those the map observed (an obstacle or
  free there: unknown is no claim); coverage: the same over all true obstacle cells;
  free precision: the map's free cells that are truly floor (the safety figure).
* drop-offs (where the raster has any: a stairwell, a step down, a hole): the map's free
  cells on a true drop-off, and those more than a cell inside it (goal 0: a cell across
  the edge holds floor hits on its rim half, and the edge is placed within one cell);
  recall: true drop-off cells with a map DROP_OFF within one cell, among those the map
  observed (anything but unknown); the edge error: from each map DROP_OFF cell beside a
  FREE one (8 neighbours: the edge a robot drives up to) to the nearest true drop-off
  cell, in map cells, its largest value and the share within one cell (issue 17: the
  edge within one cell of the truth; on a raster of EDGE_RASTER cells drawn from the
  scene where it is at hand); false drop-offs: the map's
  DROP_OFF cells on true floor more than a cell (1.5 cells, diagonals included) from any
  true drop-off (in a scene without drop-offs, reported alone: every DROP_OFF cell on
  true floor, as the floor past a ramp down seen from afar).
* ramps (where the raster has sloped floor): the F1 of the map's floor (`is_floor`)
  against the true floor (a ramp within the raster's max_slope; one steeper is not
  floor) over the map's cells on sloped floor that hold a hit (`hits`; without them,
  those it does not call unknown), as `benchmarks.bench_hazards` scores ideal scans;
  and of the traversable cells (floor and FREE: not a step's edge, its band seen) over
  the same cells but those a face higher than a step crosses, where the scene is at
  hand (`face_cells`: a ramp's side or end above the floor beside holds floor the robot
  reaches on one side and a face it cannot cross on the other; the raster, sampled at
  the cell's centre, calls it floor, and a map that blocks the face must block one of
  the two cells it runs between).
"""

from __future__ import annotations

import numpy as np

from scanmap.evaluation.trajectory_errors import ate_rmse
from scanmap.navigation import floor, morphology
from scanmap.navigation.distance_field import distance_transform
from scanmap.navigation.floor import Segmentation
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel
from scanmap_driver.sim import (
    RASTER_DROP_OFF,
    RASTER_FLOOR,
    RASTER_OBSTACLE,
    RASTER_OUTSIDE,
    ScanTruth,
    Scene,
    TruthRaster,
    truth_raster,
)
from scanmap_driver.transforms import invert_pose, transform_points, wrap_angle
from scanmap_driver.triangulation import project_head_points


def statistics(values: np.ndarray) -> dict[str, float]:
    """count, mean, median, p95 and max of |values|, and the median signed value."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if not values.size:
        return {"count": 0}
    magnitude = np.abs(values)
    return {"count": int(values.size), "mean_abs": float(magnitude.mean()),
            "median_abs": float(np.median(magnitude)),
            "p95_abs": float(np.percentile(magnitude, 95)), "max_abs": float(magnitude.max()),
            "median": float(np.median(values))}


RANGE_TRUTH_FIELDS = ("frame", "u", "base", "primary", "shadowed")  # `range_errors` reads
GROSS_RANGE = 0.05  # m: a range error beyond the paper's accuracy, counted on its own
EDGE_RASTER = 0.01  # m: cells of the truth raster a drop-off's edge is measured on
FACE_MARGIN = 0.002  # m: `face_cells` samples this far past a cell's edges


def range_errors(scan: Scan, truth: ScanTruth, model: ScannerModel,
                 columns: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, int]:
    """Signed range error (m) of each matched point, and the number of true laser points
    (`truth` needs only the laser fields RANGE_TRUTH_FIELDS); `columns`: `scan_columns`
    of the scan when already at hand."""
    primary = truth.laser["primary"].astype(bool)
    true_key, true_range = _true_columns(truth, primary, model.camera.width)
    if not true_key.size:
        return np.zeros(0), 0
    key, measured = columns or scan_columns(scan, model)
    at = np.minimum(np.searchsorted(true_key, key), len(true_key) - 1)
    found = true_key[at] == key
    return measured[found] - true_range[at[found]], int(primary.sum())


def gross_ranges(scan: Scan, truth: ScanTruth, model: ScannerModel,
                 limit: float = GROSS_RANGE,
                 columns: tuple[np.ndarray, np.ndarray] | None = None) -> int:
    """How many points of the image columns the laser lit lie more than `limit` (m) in
    range from every lit point of their column: not the strongest alone (`range_errors`'
    match), as a column crossing a depth edge shows the stripe twice, both true;
    `columns` as for `range_errors`."""
    true_key, true_range = _true_columns(truth, ~truth.laser["shadowed"].astype(bool),
                                         model.camera.width)
    if not true_key.size:
        return 0
    key, measured = columns or scan_columns(scan, model)
    first = np.searchsorted(true_key, key, side="left")
    end = np.searchsorted(true_key, key, side="right")
    nearest = np.full(len(key), np.inf)
    for offset in range(int((end - first).max(initial=0))):  # a column's few lit points
        at = np.minimum(first + offset, len(true_key) - 1)
        nearest = np.where(first + offset < end,
                           np.minimum(nearest, np.abs(measured - true_range[at])), nearest)
    return int(((end > first) & (nearest > limit)).sum())


def _true_columns(truth: ScanTruth, keep: np.ndarray, width: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(frame x width + column, range in base_link) of the `keep` laser truth points,
    ordered by the first."""
    key = (truth.laser["frame"][keep].astype(np.int64) * width
           + np.rint(truth.laser["u"][keep]).astype(np.int64))
    base = truth.laser["base"][keep]
    order = _ascending(key)  # the simulator writes them frame by frame, column by column
    return key[order], np.hypot(base[:, 0], base[:, 1])[order]


def scan_columns(scan: Scan, model: ScannerModel) -> tuple[np.ndarray, np.ndarray]:
    """(frame x width + image column, range in base_link) of each point of `scan`, the
    column -1 past the image: what `range_errors` and `gross_ranges` match to the truth
    (the projection is most of their time; a caller of both computes it once)."""
    # Frame by frame (the assembly's order), each point turned back into the head by its
    # frame's first heading.
    rows = _ascending(scan.frame_index)
    frame = scan.frame_index[rows].astype(np.int64)
    points = np.asarray(scan.points, dtype=np.float64)[rows]
    first = np.flatnonzero(np.diff(frame, prepend=-1))
    heading = np.repeat(np.asarray(scan.heading, dtype=np.float64)[rows][first],
                        np.diff(first, append=frame.size))
    mount = transform_points(invert_pose(model.head_mount.pose), points)
    c, s = np.cos(heading), np.sin(heading)
    head = np.column_stack([c * mount[:, 0] + s * mount[:, 1],
                            c * mount[:, 1] - s * mount[:, 0], mount[:, 2]])
    u = np.rint(project_head_points(model, head)[:, 0]) if len(head) else np.zeros(0)
    key = frame * model.camera.width + np.nan_to_num(u, nan=-1.0).astype(np.int64)
    return np.where(np.isfinite(u), key, -1), np.hypot(points[:, 0], points[:, 1])


def _ascending(keys: np.ndarray) -> np.ndarray | slice:
    """Indices that sort `keys` (stably), or the whole slice when they are in order
    already (no copy, no sort: the usual case)."""
    if keys.size < 2 or bool((keys[1:] >= keys[:-1]).all()):
        return slice(None)
    return np.argsort(keys, kind="stable")


def heading_errors(scan: Scan, truth: ScanTruth) -> np.ndarray:
    """Decoded minus true heading (rad, wrapped) of each frame that has points."""
    frames, first = np.unique(scan.frame_index, return_index=True)
    inside = frames < len(truth.frame_heading)
    return wrap_angle(scan.heading[first[inside]] - truth.frame_heading[frames[inside]])


def trajectory_errors(poses: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """ATE RMSE (m) after SE(2) alignment, and without alignment once the map is placed by
    the first true pose (`map_to_world`): the error the map itself is drawn with."""
    poses, reference = np.asarray(poses), np.asarray(reference)
    anchored = map_to_world(poses, reference) @ poses
    return {"count": len(poses), "ate_rmse": ate_rmse(poses, reference, "se2"),
            "start_anchored_rmse": ate_rmse(anchored, reference, "none")}


def map_to_world(poses: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The map frame in the world: placed by the true pose of the first scan."""
    return reference[0] @ invert_pose(poses[0])


def map_errors(seg: Segmentation, raster: TruthRaster, world_from_map: np.ndarray,
               scene: Scene | None = None, hits: np.ndarray | None = None
               ) -> dict[str, float]:
    """Obstacle precision, recall, F1, coverage and free precision, and the drop-off
    measures where the raster has drop-offs (module docstring): with the `scene` the
    raster shows, on a raster of EDGE_RASTER cells drawn from it for the same band and
    slope (on the map's own 5 cm cells the true edge is placed only to within half a
    cell: a cell diagonal to a drop-off cell measures 1.41 where the drop-off's corner
    lies 0.85 cells from its centre). `hits`: (ny, nx) bool, the cells holding a hit (the
    ramp F1's cells)."""
    truth_class = _raster_at_cells(raster.classes, raster, seg, world_from_map, -1)
    near_truth = morphology.dilate(raster.classes == RASTER_OBSTACLE)
    near_truth_at = _raster_at_cells(near_truth, raster, seg, world_from_map, False)
    drop_raster = raster
    if scene is not None and (raster.classes == RASTER_DROP_OFF).any():
        drop_raster = truth_raster(scene, EDGE_RASTER, *raster.band, max_slope=raster.max_slope)
    predicted = seg.state == floor.OBSTACLE
    free = seg.state == floor.FREE
    scored = predicted & (truth_class != RASTER_OUTSIDE) & (truth_class >= 0)
    precision = float(near_truth_at[scored].mean()) if scored.any() else float("nan")

    detected, observed = _found(raster, RASTER_OBSTACLE, predicted, free, seg, world_from_map)
    recall = float(detected[observed].mean()) if observed.any() else float("nan")
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {"obstacle_precision": precision, "obstacle_recall": recall, "obstacle_f1": f1,
            "obstacle_coverage": float(detected.mean()) if detected.size else float("nan"),
            "free_precision": float((truth_class[free] == RASTER_FLOOR).mean()) if free.any()
            else float("nan"),
            "free_cells_on_obstacles": int((truth_class[free] == RASTER_OBSTACLE).sum()),
            "band": list(raster.band)} | drop_off_errors(seg, drop_raster, world_from_map) \
        | ramp_errors(seg, raster, world_from_map, truth_class,
                      seg.state != floor.UNKNOWN if hits is None else hits, scene)


def ramp_errors(seg: Segmentation, raster: TruthRaster, world_from_map: np.ndarray,
                truth_class: np.ndarray, hits: np.ndarray, scene: Scene | None = None
                ) -> dict[str, float]:
    """The ramp F1s of the module docstring and the cells they count (empty where the
    raster has no sloped floor); `truth_class`: the raster's class at each map cell."""
    if raster.slope is None or not (raster.slope > 0.0).any():
        return {}
    sloped = _raster_at_cells(raster.slope > 0.0, raster, seg, world_from_map, False)
    cells = sloped & hits
    actual = truth_class == RASTER_FLOOR
    faces = np.zeros(seg.shape, bool) if scene is None else face_cells(
        scene, seg, world_from_map, cells, raster.band[0])
    clear = cells & ~faces
    traversable = seg.is_floor & (seg.state == floor.FREE)
    return {"ramp_cells": int(cells.sum()), "ramp_face_cells": int(faces.sum()),
            "ramp_f1": f1_score(seg.is_floor[cells], actual[cells]),
            "ramp_traversable_f1": f1_score(traversable[clear], actual[clear])}


def face_cells(scene: Scene, seg: Segmentation, world_from_map: np.ndarray,
               cells: np.ndarray, step: float, samples: int = 7) -> np.ndarray:
    """Of `cells` (a mask of `seg`'s), those a face higher than `step` crosses or bounds:
    the scene's floor at `samples` x `samples` points of the cell, its edges included,
    spans more than `step` (a 15 deg slope spans 1.9 cm across a 5 cm cell's diagonal).
    Its edges count: a face a few mm inside a cell puts its hits there, and the samples
    of the cell's inside all lie on one side of it. So does a face on an edge, for both
    cells it runs between (its hits fall either side): the samples reach FACE_MARGIN past
    the edges, where a region's outline, which holds its own edge, put an edge's samples
    on the region's side alone (random room 11106's ramp, its side on a row of cells'
    lower edges: the 12 cells above, on the ramp, were scored, those below were not)."""
    rows, cols = np.nonzero(cells)
    out = np.zeros(seg.shape, bool)
    if not len(rows):  # no ramp cell seen (a short recording): nothing to sample
        return out
    reach = FACE_MARGIN / seg.resolution
    within = np.linspace(-reach, 1.0 + reach, samples)
    dx, dy = (a.ravel() for a in np.meshgrid(within, within))
    x = seg.origin[0] + (cols[:, None] + dx) * seg.resolution
    y = seg.origin[1] + (rows[:, None] + dy) * seg.resolution
    world = transform_points(world_from_map, np.column_stack(
        [x.ravel(), y.ravel(), np.zeros(x.size)]))
    heights = scene.floor_at(world[:, 0], world[:, 1])[0].reshape(len(rows), -1)
    out[rows, cols] = np.ptp(heights, axis=1) > step
    return out


def f1_score(predicted: np.ndarray, actual: np.ndarray) -> float:
    """F1 of boolean `predicted` against `actual` (NaN where neither claims anything)."""
    claims = int(predicted.sum()) + int(actual.sum())
    return 2.0 * int((predicted & actual).sum()) / claims if claims else float("nan")


def drop_off_errors(seg: Segmentation, raster: TruthRaster, world_from_map: np.ndarray
                    ) -> dict[str, float]:
    """The drop-off measures of the module docstring; where the raster has none, only the
    false drop-offs (every DROP_OFF cell on true floor: a ramp down seen from afar)."""
    true_drop = raster.classes == RASTER_DROP_OFF
    drop, free = seg.state == floor.DROP_OFF, seg.state == floor.FREE
    if not true_drop.any():
        on_floor = _raster_at_cells(raster.classes == RASTER_FLOOR, raster, seg,
                                    world_from_map, False)
        return {"false_drop_off_cells": int((drop & on_floor).sum())}
    detected, observed = _found(raster, RASTER_DROP_OFF, drop, seg.state != floor.UNKNOWN,
                                seg, world_from_map)
    edge = drop & morphology.dilate(free)
    distance = distance_transform(true_drop)[0] * (raster.resolution / seg.resolution)
    off_truth = _raster_at_cells(distance, raster, seg, world_from_map, np.inf)
    edge_error = off_truth[edge]
    on_floor = _raster_at_cells(raster.classes == RASTER_FLOOR, raster, seg, world_from_map,
                                False)
    on_drop = _raster_at_cells(true_drop, raster, seg, world_from_map, False)
    inside = morphology.min_filter(on_drop, 3) > 0  # more than a cell from the edge
    return {"free_cells_on_drop_offs": int((free & on_drop).sum()),
            "free_cells_inside_drop_offs": int((free & inside).sum()),
            "drop_off_recall": float(detected[observed].mean()) if observed.any()
            else float("nan"),
            "drop_off_edge_cells": int(edge.sum()),
            "drop_off_edge_error_cells": float(edge_error.max()) if edge.any() else 0.0,
            "drop_off_edge_within_one": float((edge_error <= 1.0).mean()) if edge.any()
            else 1.0,
            "false_drop_off_cells": int((drop & on_floor & (off_truth > 1.5)).sum())}


def _raster_at_cells(values: np.ndarray, raster: TruthRaster, seg: Segmentation,
                     world_from_map: np.ndarray, fill) -> np.ndarray:
    """(ny, nx): `values` (a grid over the raster's cells) at each map cell's centre,
    placed in the world by `world_from_map`; `fill` beyond the raster."""
    ny, nx = seg.shape
    gx, gy = np.meshgrid(seg.origin[0] + (np.arange(nx) + 0.5) * seg.resolution,
                         seg.origin[1] + (np.arange(ny) + 0.5) * seg.resolution)
    cells = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    return _lookup(values, raster.origin, raster.resolution,
                   transform_points(world_from_map, cells), fill).reshape(ny, nx)


def _found(raster: TruthRaster, kind: int, claimed: np.ndarray, other: np.ndarray,
           seg: Segmentation, world_from_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per true cell of `kind`: whether the map `claimed` it within one cell (detected),
    and whether the map observed it (detected, or `other` there)."""
    rows, cols = np.nonzero(raster.classes == kind)
    true_cells = np.column_stack([raster.origin[0] + (cols + 0.5) * raster.resolution,
                                  raster.origin[1] + (rows + 0.5) * raster.resolution,
                                  np.zeros(rows.size)])
    in_map = transform_points(invert_pose(world_from_map), true_cells)
    detected = _lookup(morphology.dilate(claimed), seg.origin, seg.resolution, in_map, False)
    return detected, detected | _lookup(other, seg.origin, seg.resolution, in_map, False)


def _lookup(values: np.ndarray, origin, resolution: float, points: np.ndarray,
            fill) -> np.ndarray:
    """values[row, col] of the cell under each point (x, y) of a grid whose cell [0, 0]
    has its lower-left corner at origin; `fill` outside."""
    cols = np.floor((points[:, 0] - origin[0]) / resolution).astype(np.int64)
    rows = np.floor((points[:, 1] - origin[1]) / resolution).astype(np.int64)
    inside = (rows >= 0) & (rows < values.shape[0]) & (cols >= 0) & (cols < values.shape[1])
    out = np.full(len(points), fill, dtype=np.result_type(values.dtype, np.asarray(fill)))
    out[inside] = values[rows[inside], cols[inside]]
    return out
