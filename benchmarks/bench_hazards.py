"""What a planar lidar misses, against the simulator's truth: drop-offs, ramps, steps, dark
and glass surfaces (the built-in `hazards` scene) and people walking past (`people`).

    .venv/bin/python -m benchmarks.bench_hazards [--quick] [--scene FILE ...] [--random N]
        [--mixed N] [--step N] [--ramp N] [--terrain N] [--approach N] [--people N]
        [--rendered N] [--rendered-approach N]
        [--first SEED] [--pixel-sigma PX] [--step-height M] [--max-slope DEG]
        [--rendered-people]

With `--scene`, the same measures on other scenes (scene files, as `scanmap simulate`
takes them); with `--random N`, `--mixed N`, `--step N`, `--ramp N`, `--terrain N`,
`--approach N` or `--people N`, on N random hazard rooms, mixed rooms, rooms with one step
down just deeper than the robot's step, rooms with turned ramps near max_slope, rooms with
floors reached by ramps, a dock and a stair, rooms with a hazard across the path driven
at head-on, or rooms with people (`random_rooms`, seeds
from `--first`, 1 by default): a method must hold on scenes it was not built on; with
`--pixel-sigma`, the drop-off and ramp rooms scanned with that laser peak noise (px);
with `--step-height` and `--max-slope`, those rooms and scenes measured for a robot that
climbs that step and that slope (the map's rules and the truth both read them);
with `--rendered N`, N random and N mixed rooms through the whole pipeline (below), with
`--rendered-approach N` N approach rooms.

Ideal scans fused at their true frame poses (registration is scored elsewhere), segmented
over the scene's bounds after every scan, for the default robot (5 cm step, 15 deg
slope), but for the whole pipeline's row. Rows:

* drop-off cells free: true drop-off cells reported FREE or traversable. Strict: all of
  them; the gate: those more than one cell inside the drop-off (a cell across the edge
  holds floor hits on its rim half, and the edge is placed within one cell).
* drop-off edge error: for every DROP_OFF cell next to a FREE cell (the edge a robot
  drives up to), the distance (cells) from its centre to the nearest true drop-off, on
  a truth raster of EDGE_RASTER cells (the map's cells' own raster places the true edge
  only to within half a cell: a cell diagonal to a drop-off cell measured 1.41 where
  the drop-off's corner lies 0.85 cells from its centre); the maximum and the share
  within one cell.
* false drop-offs: DROP_OFF cells on true floor more than 1.5 cells from any true
  drop-off (on the same raster), after the worst scan: on `hazards`, over the placements
  and over the random rooms (a robot that sees a drop-off where there is none will not
  drive there).
* ramp F1: floor (`is_floor`) against truth over the observed cells (any hit) of the
  sloped floor regions, a ramp within max_slope and one steeper; the traversable F1 the
  same of floor and FREE (not a step's edge, its band seen), but for the cells a face
  higher than a step crosses (`evaluation.face_cells`: the truth, sampled at the
  cell's centre, has no face between two floors).
* placed anew: the same scene shifted within a cell and turned (`Scene.moved`), so its
  edges fall inside cells and at angles to them, not on the cells' boundaries as built:
  the worst free drop-off count after any scan, the worst edge, the least and the mean
  ramp F1 over PLACEMENTS placements.
* random rooms: the same measures on RANDOM_ROOMS rooms drawn afresh (`random_rooms`: two
  holes, a step down, a pit, a platform, a low step and two ramps, sizes, depths, slopes
  and angles drawn from each seed): the rooms with a drop-off cell free after some scan,
  the worst such count and edge, the least and the mean ramp F1.
* ghost cells: cells within SEE_THROUGH of the robot (farther, nothing sees through the
  space a person left) that a person left at least three scans ago (free in the static
  truth, not a sliver of a static face, and since then no person within EDGE_TOLERANCE
  of the cell: a side that grazes the cell puts its noisy hits there) and the map still
  calls OBSTACLE, summed over the scans; `left_cells` counts the cells checked. Nearer
  than about 1.6 m no camera ray crosses the band's low heights (the camera is 1 m up),
  so `left_cells_seen_through` counts only the cells whose band the later scans' camera
  rays did cross (SEE_THROUGH_SHARE of its height bins, sampled along the rays
  independently of the grid's ray tracing), and `ghost_cells_seen_through` those of
  them still OBSTACLE although the rays crossed every band bin where the map holds a
  level: the issue's "an obstacle that later scans see through clears within three
  scans". `left_cells_lit_through` and `ghost_cells_lit_through` count the same with
  the laser's rays too, from its emitter 0.5 m lower (the light's path was free: the
  map clears along it what was seen briefly, near its hits, `HeightGrid.insert`).
* wall erosion and recall: static obstacle cells once OBSTACLE that a later scan calls
  anything else (and of those, FREE), but for the cells a face only grazes
  (`bench_grid.mixed_cells`: within 2 mm of the cell's edge, a sliver whose truth
  rounding settles; strict: all; deep: only the cells an object reaches more than
  DEEP_CUT into), and the final share of observed static obstacle
  cells that are OBSTACLE, with people and without (the same scans of the empty
  corridor).
* rooms with people: the ghost and erosion measures on PEOPLE_ROOMS rooms drawn afresh
  (`random_rooms.people_room`: cabinets turned against the walls, people walking past
  and standing), summed over them, and the rooms where a wall or cabinet eroded.
* `--rendered-people`: the ghost and erosion measures on `people` through its rendered
  frames (`rendered_steps`: extraction and decoding as `scanmap map` does them, fused at
  the true poses), where the stripe fades with range and drops out.
* through the whole pipeline: `hazards`, RENDERED_ROOMS random rooms and as many mixed
  rooms with their
  webcam frames rendered (`scanmap simulate`: the stripe's blur, noise and the encoder
  disk) and mapped by `scanmap map` (extraction, decoding, registration), the map placed
  in the world by the first true pose: after the last scan, drop-off cells free more
  than a cell inside, the edge error and false drop-offs as above, and the report's
  obstacle F1 and ramp floor F1 (as above, over the ramps' cells holding a hit); the
  time is the command's mapping loop per scan (wall).
* time per scan: fusing one scan (about 29k points, 5 cm cells: the rays in the map and
  the grid's insertion) and segmenting the 8 m x 8 m window around the robot (median CPU
  time of the thread, so what else shares the machine does not count).
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from benchmarks.bench_grid import EDGE_TOLERANCE, mixed_cells, object_cells
from benchmarks.random_rooms import (
    FAMILIES,
    approach_room,
    mixed_room,
    people_room,
    random_room,
)
from scanmap.datasets.recordings import ScanSource
from scanmap.evaluation.ground_truth import (
    EDGE_RASTER,
    drop_off_errors,
    f1_score,
    face_cells,
)
from scanmap.grid.height_grid import CellLayers, GridConfig, HeightGrid
from scanmap.grid.rays import laser_origins, scan_rays
from scanmap.grid.swept import swept_frames
from scanmap.grid.unlit import line_returns, unlit_floor
from scanmap.navigation.floor import (
    DROP_OFF,
    FREE,
    OBSTACLE,
    FloorConfig,
    RobotShape,
    Segmentation,
    segment,
)
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.ideal import IdealScan, ideal_scans
from scanmap_driver.sim.raster import DROP_OFF as TRUE_DROP_OFF
from scanmap_driver.sim.raster import FLOOR as TRUE_FLOOR
from scanmap_driver.sim.raster import OBSTACLE as TRUE_OBSTACLE
from scanmap_driver.sim.raster import TruthRaster, truth_raster
from scanmap_driver.sim.scene import Scene, builtin_scene, resolve_scene
from scanmap_driver.sim.simulate import simulate_recording

ROBOT = RobotShape()
MODEL = reference_scanner()  # built once, as a Mapper builds its model (0.4 ms a build)
PARAMS = FloorConfig().for_scanner(MODEL)  # the floor rules with this scanner's geometry
MARGIN = 0.5  # m of window around the scene's bounds
WINDOW = 8.0  # m, side of the window segmented per scan for the timing
SEE_THROUGH = 2.0  # m from the robot within which a person's former cells are checked
BAND_BIN = 0.025  # m, height bins of the robot's band for the see-through truth
BAND_BINS = round((ROBOT.height - ROBOT.step_height) / BAND_BIN)  # bins in the band
RAY_STEP = 0.01  # m, sampling step along the true rays for the see-through truth
SEE_THROUGH_SHARE = 0.95  # share of the band's bins crossed: the cell was seen through
DEEP_CUT = 0.01  # m: eroded wall cells an object reaches deeper into are counted apart
PLACEMENTS = 8  # placements of the hazards scene on the cells (`placed_run`)
RANDOM_ROOMS = 12  # random hazard rooms measured (`random_run`)
PEOPLE_ROOMS = 6  # rooms with people measured (`people_rooms_run`)
RENDERED_ROOMS = 3  # random and mixed rooms each rendered and mapped (`rendered_rooms`)
CELL = GridConfig().resolution  # m


@dataclass(frozen=True)
class Step:
    """The map after one scan: the grid's window over the scene and its segmentation."""

    index: int
    ideal: IdealScan
    layers: CellLayers
    seg: Segmentation

    @property
    def hits(self) -> np.ndarray:
        """(ny, nx) bool: cells holding any hit."""
        return self.layers.nlev > 0


def scene_window(scene: Scene) -> tuple[float, float, float, float]:
    """The scene's bounds grown by MARGIN."""
    low, high = scene.bounds()
    return (low[0] - MARGIN, low[1] - MARGIN, high[0] + MARGIN, high[1] + MARGIN)


def fuse(grid: HeightGrid, ideal: IdealScan) -> None:
    """Insert one ideal scan at its true frame poses, with the floor it saw unlit and the
    levels its laser swept unlit, as `Mapper` does."""
    points, origins = scan_rays(ideal.scan, MODEL, ideal.frame_poses)
    returns = line_returns(ideal.scan, MODEL)
    grid.insert(points, origins, float(ideal.scan.time.max()),
                unlit=unlit_floor(ideal.scan, MODEL, ideal.frame_poses, returns),
                lasers=laser_origins(ideal.scan, MODEL, ideal.frame_poses),
                swept=swept_frames(ideal.scan, MODEL, ideal.frame_poses, returns))


def mapped(scene: Scene, scans: int | None = None, seed: int = 0,
           params: FloorConfig = PARAMS, pixel_sigma: float | None = None,
           robot: RobotShape = ROBOT) -> Iterator[Step]:
    """Map the scene scan by scan, segmenting its window after each for `robot`;
    `pixel_sigma`: the laser peak's noise (px), the scanner model's by default."""
    grid = HeightGrid(GridConfig(extent=50.0))
    bounds = scene_window(scene)
    for index, ideal in enumerate(ideal_scans(scene, seed=seed, scans=scans,
                                              pixel_sigma=pixel_sigma)):
        fuse(grid, ideal)
        layers = grid.layers(bounds)
        yield Step(index, ideal, layers, segment(layers, robot, params))


def rendered_steps(scene: Scene, scans: int | None = None, seed: int = 0) -> Iterator[Step]:
    """`mapped` on the scene's webcam frames: rendered (`simulate_recording`), the scans
    assembled from them as `scanmap map` does (laser extraction, encoder decoding), fused
    at the true poses (no registration: the frames' effect alone). Each Step's `ideal`
    holds the assembled scan with the ideal scan's truth (the robot stands still during
    a scan in these scenes)."""
    grid = HeightGrid(GridConfig(extent=50.0))
    bounds = scene_window(scene)
    with tempfile.TemporaryDirectory(prefix="scanmap-rendered-") as scratch:
        recording = simulate_recording(scene, f"{scratch}/rec", MODEL, seed=seed,
                                       scans=scans, workers=2)
        for index, (ideal, item) in enumerate(zip(ideal_scans(scene, seed=seed, scans=scans),
                                                  ScanSource.open(recording, MODEL),
                                                  strict=True)):
            assembled = replace(ideal, scan=item.scan, frame_poses=ideal.pose_start)
            fuse(grid, assembled)
            layers = grid.layers(bounds)
            yield Step(index, assembled, layers, segment(layers, ROBOT, PARAMS))


def truth_classes(seg: Segmentation, raster: TruthRaster) -> np.ndarray:
    """(ny, nx) true class at each segmentation cell's centre (OUTSIDE beyond the raster)."""
    ny, nx = seg.shape
    x = seg.origin[0] + (np.arange(nx) + 0.5) * seg.resolution
    y = seg.origin[1] + (np.arange(ny) + 0.5) * seg.resolution
    gx, gy = np.meshgrid(x, y)
    return raster.class_at(np.column_stack([gx.ravel(), gy.ravel()])).reshape(ny, nx)


def traversable(seg: Segmentation) -> np.ndarray:
    """Cells a planner may drive on: floor and FREE."""
    return seg.is_floor & (seg.state == FREE)


def drop_measures(seg: Segmentation, truth: np.ndarray, raster: TruthRaster
                  ) -> dict[str, float]:
    """Drop-off cells reported free (strict and more than a cell inside) and the edge
    error (`evaluation.drop_off_errors` on `raster`, of any resolution, the map at the
    true poses); `truth` is the true class at each of `seg`'s cells."""
    return {**_drop_figures(drop_off_errors(seg, raster, np.eye(4))),
            "drop_found": int(((seg.state == DROP_OFF) & (truth == TRUE_DROP_OFF)).sum()),
            "drop_cells": int((truth == TRUE_DROP_OFF).sum())}


def _drop_figures(errors: dict[str, float]) -> dict[str, float]:
    """The drop-off figures of `evaluation.drop_off_errors`' measures by this module's
    names; a scene without drop-offs has none free and no edge to place."""
    return {"drop_free_strict": errors.get("free_cells_on_drop_offs", 0),
            "drop_free": errors.get("free_cells_inside_drop_offs", 0),
            "edge_cells": errors.get("drop_off_edge_cells", 0),
            "edge_error_cells": errors.get("drop_off_edge_error_cells", 0.0),
            "edge_within_one": errors.get("drop_off_edge_within_one", 1.0),
            "drop_false": errors["false_drop_off_cells"]}


def ramp_f1(seg: Segmentation, truth: np.ndarray, hits: np.ndarray, scene: Scene,
            traversable: bool = False) -> float:
    """F1 of floor against true floor over the observed cells of the sloped regions (NaN
    without any); with `traversable`, of floor and FREE (not a step's edge, its band
    seen), but for the cells a face higher than a step crosses (`face_cells`). Cells an
    object's face only grazes are not scored (`bench_grid.mixed_cells`, as for the walls'
    figures: a corridor's wall 1 mm past the edge of the cells of a ramp that runs wall to
    wall puts its noisy hits in them, an obstacle)."""
    ny, nx = seg.shape
    x = seg.origin[0] + (np.arange(nx) + 0.5) * seg.resolution
    y = seg.origin[1] + (np.arange(ny) + 0.5) * seg.resolution
    gx, gy = np.meshgrid(x, y)
    ramps = np.zeros((ny, nx), bool)
    for region in scene.floor_regions:
        if any(region.gradient):
            ramps |= region.contains(gx, gy)
    cells = ramps & hits
    if not cells.any():  # no ramp, or none seen
        return float("nan")
    raster = truth_raster(scene, CELL, seg.robot.step_height, seg.robot.height)
    cells &= truth_classes(seg, replace(raster, classes=mixed_cells(scene, raster).astype(
        np.uint8))) == 0
    floor = seg.is_floor
    if traversable:
        floor = floor & (seg.state == FREE)
        cells &= ~face_cells(scene, seg, np.eye(4), cells, seg.robot.step_height)
    return f1_score(floor[cells], truth[cells] == TRUE_FLOOR)


def hazard_run(scans: int | None = None, seed: int = 0, scene: Scene | None = None,
               pixel_sigma: float | None = None, robot: RobotShape = ROBOT,
               params: FloorConfig = PARAMS) -> dict[str, float]:
    """The drop-off and ramp measures on a scene with hazards (the built-in `hazards`)
    after its last scan, the worst counts of free and of false drop-off cells, the worst
    edge error and the least share of the edge within one cell over all scans (scans with
    `mapped`'s `pixel_sigma`), for `robot` with `params` (its step and slope the truth's)."""
    scene = scene or builtin_scene("hazards")
    raster, fine = (truth_raster(scene, resolution, robot.step_height, robot.height,
                                 max_slope=params.max_slope) for resolution in (CELL, EDGE_RASTER))
    worst, edge_worst, within_worst, false_worst = 0, 0.0, 1.0, 0
    for step in mapped(scene, scans, seed, params, pixel_sigma, robot):
        truth = truth_classes(step.seg, raster)
        measures = drop_measures(step.seg, truth, fine)
        worst = max(worst, measures["drop_free"])
        false_worst = max(false_worst, measures["drop_false"])
        edge_worst = max(edge_worst, measures["edge_error_cells"])
        within_worst = min(within_worst, measures["edge_within_one"])
    return {**measures, "drop_free_any_scan": worst, "edge_error_any_scan": edge_worst,
            "edge_within_one_any_scan": within_worst, "drop_false_any_scan": false_worst,
            "ramp_f1": ramp_f1(step.seg, truth, step.hits, scene),
            "ramp_traversable_f1": ramp_f1(step.seg, truth, step.hits, scene, True)}


def rendered_run(scene: Scene | None = None, scans: int | None = None,
                 seed: int = 0) -> dict[str, float]:
    """The drop-off measures of `hazard_run` after the last scan, through the whole
    pipeline: the scene's webcam frames rendered (`simulate_recording`) and mapped by
    `scanmap map` (`map_to_folder`: extraction, encoder decoding, registration), as its
    report gives them against the recording's truth (the map placed by the first true
    pose, the edge on a 1 cm raster), with its obstacle F1, ATE and the points whose
    range is more than GROSS_RANGE off."""
    scene = scene or builtin_scene("hazards")
    with tempfile.TemporaryDirectory(prefix="scanmap-rendered-") as scratch:
        recording = simulate_recording(scene, f"{scratch}/rec", reference_scanner(),
                                       seed=seed, scans=scans, workers=2)
        report = map_to_folder(recording, f"{scratch}/map", workers=2)
    errors = report["errors"]["map"]
    figures = _drop_figures(errors)
    del figures["edge_cells"]
    return {"scans": report["input"]["scans"], **figures,
            "drop_recall": errors.get("drop_off_recall", math.nan),
            "obstacle_f1": errors["obstacle_f1"],
            "ramp_f1": errors.get("ramp_f1", math.nan),
            "ramp_traversable_f1": errors.get("ramp_traversable_f1", math.nan),
            "ate_m": report["errors"]["trajectory_m"]["ate_rmse"],
            "range_gross": report["errors"]["range_m"].get("gross", 0),
            "seconds_per_scan": report["mapping"]["seconds_per_scan"]}


def rendered_rooms(count: int, first: int = 1, scans: int | None = None,
                   draws: tuple[Callable[[int], Scene], ...] = (random_room, mixed_room)
                   ) -> dict[str, dict[str, float]]:
    """`rendered_run` on `count` rooms of each family of `draws` (by default random hazard
    rooms and mixed rooms: black-lined holes, black carpet, glass, dim light; seeds
    `first` on), by room, and the worst over them (the least recall and ramp F1 of the
    rooms that have drop-offs and saw a ramp)."""
    rooms = {f"{draw.__name__}({seed})": rendered_run(draw(seed), scans)
             for draw in draws for seed in range(first, first + count)}
    runs = list(rooms.values())
    worst = {"rooms": len(runs), **{key: max((r[key] for r in runs), default=0) for key in (
        "drop_free", "drop_free_strict", "edge_error_cells", "drop_false", "range_gross")},
        **{key: min((r[key] for r in runs), default=math.nan) for key in (
            "edge_within_one", "obstacle_f1")},
        **{key: min((r[key] for r in runs if not math.isnan(r[key])), default=math.nan)
           for key in ("drop_recall", "ramp_f1", "ramp_traversable_f1")}}
    return rooms | {"worst": worst}


def near(step: Step) -> np.ndarray:
    """(ny, nx) cells whose centres lie within SEE_THROUGH of the robot at the step's scan."""
    seg = step.seg
    ny, nx = seg.shape
    x = seg.origin[0] + (np.arange(nx) + 0.5) * seg.resolution - step.ideal.pose_start[0, 3]
    y = seg.origin[1] + (np.arange(ny) + 0.5) * seg.resolution - step.ideal.pose_start[1, 3]
    return np.hypot(*np.meshgrid(x, y)) <= SEE_THROUGH


def band_crossed(points: np.ndarray, origins: np.ndarray, seg: Segmentation) -> np.ndarray:
    """(ny, nx) uint64: the band's height bins (BAND_BIN from the step height up) that the
    rays from `origins` to `points` pass through in each cell of `seg`, sampled every
    RAY_STEP along them up to, not at, the hit."""
    ny, nx = seg.shape
    out = np.zeros(ny * nx, np.uint64)
    delta = points - origins
    samples = np.maximum((np.hypot(delta[:, 0], delta[:, 1]) / RAY_STEP).astype(int), 1)
    for rays in np.array_split(np.arange(len(points)), max(len(points) // 2000, 1)):
        ray = np.repeat(rays, samples[rays])
        start = np.cumsum(samples[rays]) - samples[rays]
        t = (np.arange(len(ray)) - np.repeat(start, samples[rays])) / samples[ray]
        p = origins[ray] + t[:, None] * delta[ray]
        col = np.floor((p[:, 0] - seg.origin[0]) / seg.resolution).astype(np.int64)
        row = np.floor((p[:, 1] - seg.origin[1]) / seg.resolution).astype(np.int64)
        level = np.floor((p[:, 2] - ROBOT.step_height) / BAND_BIN).astype(np.int64)
        ok = (row >= 0) & (row < ny) & (col >= 0) & (col < nx) & (level >= 0) & (level < BAND_BINS)
        np.bitwise_or.at(out, row[ok] * nx + col[ok],
                         np.left_shift(np.uint64(1), level[ok].astype(np.uint64)))
    return out.reshape(ny, nx)


def crossed_by_scan(step: Step) -> tuple[np.ndarray, np.ndarray]:
    """`band_crossed` by the scan's camera rays, and by its laser's (from the emitter:
    the light's path is free as well, `HeightGrid.insert`)."""
    scan, poses = step.ideal.scan, step.ideal.frame_poses
    points, origins = scan_rays(scan, MODEL, poses)
    return (band_crossed(points, origins, step.seg),
            band_crossed(points, laser_origins(scan, MODEL, poses), step.seg))


def band_held(layers: CellLayers) -> np.ndarray:
    """(ny, nx) uint64: the band's height bins (as `band_crossed`) that the map's levels
    overlap in each cell: where it holds something the robot would hit."""
    in_use = np.arange(layers.levels.shape[2]) < layers.nlev[..., None]
    bottom, top = (layers.levels[..., i].astype(np.float64) for i in (0, 1))
    lo, hi = (np.floor((z - ROBOT.step_height) / BAND_BIN).astype(np.int64)
              for z in (bottom, top))
    # the first bin whose top lies above the level's bottom and the last whose bottom
    # lies at or under its top, to the bins' edges exactly (the division rounds either
    # way where a level ends on one)
    lo += (bottom >= _bin_bottom(lo) + BAND_BIN).astype(np.int64)
    lo -= (bottom < _bin_bottom(lo - 1) + BAND_BIN).astype(np.int64)
    hi -= (top < _bin_bottom(hi)).astype(np.int64)
    hi += (top >= _bin_bottom(hi + 1)).astype(np.int64)
    lo, top = np.clip(lo, 0, BAND_BINS).astype(np.uint64), np.clip(hi + 1, 0, BAND_BINS)
    one = np.uint64(1)
    spans = np.where(in_use & (top > lo), (one << top.astype(np.uint64)) - (one << lo),
                     np.uint64(0))  # bits lo .. top - 1 of each level
    return np.bitwise_or.reduce(spans, axis=2)


def _bin_bottom(index: np.ndarray) -> np.ndarray:
    """The bottom (m) of the band's height bins `index`."""
    return ROBOT.step_height + index * BAND_BIN


def share_of_bits(mask: np.ndarray, bits: int) -> np.ndarray:
    """Share of the low `bits` bits set in each element of a uint64 array."""
    count = np.zeros(mask.shape, np.int64)
    for bit in range(bits):
        count += ((mask >> np.uint64(bit)) & np.uint64(1)).astype(np.int64)
    return count / bits


def placements(count: int, seed: int = 1) -> list[tuple[float, float, float]]:
    """`count` placements (dx, dy m, yaw rad) of a scene on the cells: shifts within a
    cell, the first half square to the cells, the rest turned by up to 45 deg."""
    rng = np.random.default_rng(seed)
    shifts = rng.uniform(0.0, CELL, (count, 2))
    yaws = np.where(np.arange(count) < count // 2, 0.0, rng.uniform(-np.pi / 4, np.pi / 4, count))
    return [(float(x), float(y), float(a)) for (x, y), a in zip(shifts, yaws, strict=True)]


def placed_run(count: int, scans: int | None = None) -> dict[str, float]:
    """`hazard_run` on the built-in `hazards` scene moved to `placements(count)`: the worst
    and the mean over them (a method must not hold only where the edges meet the cells'
    boundaries)."""
    runs = [hazard_run(scans, scene=builtin_scene("hazards").moved(*placed))
            for placed in placements(count)]
    return {"placements": count, **worst_over(runs)}


def worst_over(runs: list[dict[str, float]]) -> dict[str, float]:
    """Over `hazard_run` results: the most free drop-off cells after any scan, the worst
    edge and the least share of it within one cell (after the last scan and after any),
    the least and the mean ramp F1 (over the runs that saw a ramp; NaN if none did)."""
    f1 = [r["ramp_f1"] for r in runs if not math.isnan(r["ramp_f1"])]
    traversable = [r["ramp_traversable_f1"] for r in runs
                   if not math.isnan(r["ramp_traversable_f1"])]
    return {"drop_free_any_scan": max(r["drop_free_any_scan"] for r in runs),
            "drop_false_any_scan": max(r["drop_false_any_scan"] for r in runs),
            "edge_error_cells": max(r["edge_error_cells"] for r in runs),
            "edge_within_one": min(r["edge_within_one"] for r in runs),
            "edge_error_any_scan": max(r["edge_error_any_scan"] for r in runs),
            "edge_within_one_any_scan": min(r["edge_within_one_any_scan"] for r in runs),
            "ramp_f1_min": min(f1, default=math.nan),
            "ramp_f1_mean": float(np.mean(f1)) if f1 else math.nan,
            "ramp_traversable_f1_min": min(traversable, default=math.nan)}


def random_run(count: int, scans: int | None = None) -> dict[str, float]:
    """`hazard_run` on `count` random hazard rooms (`random_rooms.random_room`, seeds 1 to
    count): the worst and the mean over them, and the rooms with a free drop-off cell."""
    return rooms_summary([hazard_run(scans, scene=random_room(seed))
                          for seed in range(1, count + 1)])


def rooms_summary(runs: list[dict[str, float]]) -> dict[str, float]:
    """`worst_over` rooms (`random_run`), the rooms with a free drop-off cell after some
    scan and the most after the last."""
    return {"rooms": len(runs),
            "rooms_with_free_drop_off": sum(r["drop_free_any_scan"] > 0 for r in runs),
            "drop_free": max(r["drop_free"] for r in runs), **worst_over(runs)}


def person_cells(scene: Scene, truth_shape_of: Segmentation, scans: int) -> np.ndarray:
    """(scans, ny, nx) cells each scan's people cover (obstacles of `at_scan` not static),
    or come within EDGE_TOLERANCE of: a person's side that grazes a cell's edge puts its
    noisy hits in the cell (as a wall's does, `bench_grid.mixed_cells`), so such a cell
    is not free while the person stands there."""
    static = truth_classes(truth_shape_of, truth_raster(scene)) == TRUE_OBSTACLE
    scene = replace(scene, people=tuple(replace(p, radius=p.radius + EDGE_TOLERANCE)
                                        for p in scene.people))
    return np.array([(truth_classes(truth_shape_of, truth_raster(scene.at_scan(k)))
                      == TRUE_OBSTACLE) & ~static for k in range(scans)])


def people_run(scans: int | None = None, seed: int = 0, linger: int = 3,
               scene: Scene | None = None, rendered: bool = False, empty_run: bool = True
               ) -> dict[str, float]:
    """Ghost cells and wall erosion on a scene with people (the built-in `people`); wall
    recall with the people and, with `empty_run`, without them (the scene mapped a
    second time; NaN without it, the same figure for a scene without people, mapped
    once); `rendered`: through rendered frames (`rendered_steps`), else ideal scans."""
    scene = scene or builtin_scene("people")
    count = len(scene.scan_poses) if scans is None else scans
    raster = truth_raster(scene)
    grazes = replace(raster, classes=mixed_cells(scene, raster).astype(np.uint8))
    cut = replace(raster, classes=object_cells(scene, raster, -DEEP_CUT).astype(np.uint8))
    ghosts, checked, eroded, freed, deep, strict, recall = 0, 0, 0, 0, 0, 0, {}
    seen_ghosts, seen_checked = np.zeros(2, int), np.zeros(2, int)  # camera; camera or laser
    empty = (("empty", replace(scene, people=())),) if scene.people and empty_run else ()
    for label, run in (("people", scene), *empty):
        once = None
        for step in (rendered_steps if rendered else mapped)(run, count, seed):
            truth = truth_classes(step.seg, raster)
            walls = truth == TRUE_OBSTACLE
            obstacle = step.seg.state == OBSTACLE
            if once is None:
                once = np.zeros_like(walls)
                covered = person_cells(scene, step.seg, count) if label == "people" else None
                crossed_since = np.zeros((2, *walls.shape), np.uint64)  # since a person left
                solid = truth_classes(step.seg, grazes) == 0  # not a face's sliver
                cut_deep = truth_classes(step.seg, cut) == 1
            if label == "people":
                strict += int((once & walls & ~obstacle).sum())
                fair = once & walls & solid
                eroded += int((fair & ~obstacle).sum())
                freed += int((fair & (step.seg.state == FREE)).sum())
                deep += int((fair & cut_deep & ~obstacle).sum())
                camera, laser = crossed_by_scan(step)
                crossed_since |= np.stack([camera, camera | laser])
                crossed_since[:, covered[step.index]] = 0
                left = step.index - linger
                if left >= 0:
                    gone = covered[:left + 1].any(axis=0) & ~covered[left + 1:step.index + 1
                                                                     ].any(axis=0)
                    gone &= (truth == TRUE_FLOOR) & solid & near(step)
                    checked += int(gone.sum())
                    ghosts += int((gone & obstacle).sum())
                    gone = gone & (share_of_bits(crossed_since, BAND_BINS) >= SEE_THROUGH_SHARE)
                    seen_checked += gone.sum(axis=(1, 2))
                    held = band_held(step.layers)
                    seen_ghosts += (gone & obstacle & (crossed_since & held == held)
                                    ).sum(axis=(1, 2))
            once |= obstacle & walls
        recall[label] = float((obstacle & walls & step.hits).sum()
                              / max(int((walls & step.hits).sum()), 1))
    return {"ghost_cells": ghosts, "left_cells": checked,
            "ghost_cells_seen_through": int(seen_ghosts[0]),
            "left_cells_seen_through": int(seen_checked[0]),
            "ghost_cells_lit_through": int(seen_ghosts[1]),
            "left_cells_lit_through": int(seen_checked[1]),
            "wall_cells_eroded": eroded, "wall_cells_freed": freed,
            "wall_cells_eroded_deep": deep, "wall_cells_eroded_strict": strict,
            "wall_recall_people": recall["people"],
            "wall_recall_empty": recall.get("empty", math.nan if scene.people
                                            else recall["people"])}


def people_rooms(count: int, scans: int | None = None, first: int = 1
                 ) -> dict[str, dict[str, float]]:
    """`people_run` on `count` rooms with people (`random_rooms.people_room`, seeds
    `first` on), by room."""
    return {f"people_room({seed})": people_run(scans, scene=people_room(seed))
            for seed in range(first, first + count)}


def people_rooms_run(count: int, scans: int | None = None) -> dict[str, float]:
    """`people_rooms`: each count summed over them, and the rooms where a static cell
    eroded."""
    return people_summary(list(people_rooms(count, scans).values()))


def people_summary(runs: list[dict[str, float]]) -> dict[str, float]:
    """The counts of `people_run`s summed, the least wall recall with people, and the
    runs where a wall eroded (`people_rooms_run`)."""
    summed = ("ghost_cells", "left_cells", "ghost_cells_seen_through",
              "left_cells_seen_through", "ghost_cells_lit_through", "left_cells_lit_through",
              "wall_cells_eroded", "wall_cells_freed",
              "wall_cells_eroded_deep", "wall_cells_eroded_strict")
    return {"rooms": len(runs), **{key: sum(r[key] for r in runs) for key in summed},
            "rooms_eroded": sum(r["wall_cells_eroded"] > 0 for r in runs),
            "wall_recall_people": min(r["wall_recall_people"] for r in runs)}


def time_per_scan(scans: int = 8, seed: int = 0, points: int | None = None
                  ) -> dict[str, float]:
    """Median CPU seconds to fuse one corridor scan and segment the window around it (the
    process's, every thread's: a library's worker threads, OpenCV's once, spent 1.45 ms a
    segmentation on the other core, which the main thread's time left out); `points`:
    thin each scan to about that many points first, by keeping its frames evenly (the
    budget's 20,000: a scan with fewer, farther apart headings)."""
    grid = HeightGrid(GridConfig(extent=50.0))
    fuse_t, seg_t, counts = [], [], []
    for ideal in ideal_scans(builtin_scene("corridor"), seed=seed, scans=scans):
        if points is not None:
            ideal = _thinned(ideal, points)
        start = time.process_time()
        fuse(grid, ideal)
        middle = time.process_time()
        x, y = ideal.pose_start[0, 3], ideal.pose_start[1, 3]
        half = 0.5 * WINDOW
        segment(grid.layers((x - half, y - half, x + half, y + half)), ROBOT, PARAMS)
        seg_t.append(time.process_time() - middle)
        fuse_t.append(middle - start)
        counts.append(len(ideal.scan))
    fuse_s, seg_s = float(np.median(fuse_t[1:])), float(np.median(seg_t[1:]))
    return {"points_per_scan": float(np.median(counts)), "fuse_ms": 1e3 * fuse_s,
            "segment_ms": 1e3 * seg_s, "per_scan_ms": 1e3 * (fuse_s + seg_s)}


def _thinned(ideal: IdealScan, points: int) -> IdealScan:
    """`ideal` with its frames kept evenly, about `points` points in all."""
    frames = np.unique(ideal.scan.frame_index)
    share = min(points / max(len(ideal.scan), 1), 1.0)
    order = np.arange(len(frames))
    kept = frames[np.floor((order + 1) * share) > np.floor(order * share)]
    mask = np.isin(ideal.scan.frame_index, kept)
    return replace(ideal, scan=ideal.scan.select(mask), true_points=ideal.true_points[mask])


def measure(quick: bool) -> dict[str, dict[str, float]]:
    """Every measure of the module docstring (fewer scans with `quick`)."""
    return {"hazards": hazard_run(8 if quick else None),
            "placed": placed_run(3 if quick else PLACEMENTS, 8 if quick else None),
            "random": random_run(3 if quick else RANDOM_ROOMS, 8 if quick else None),
            "people": people_run(24 if quick else None),
            "people_rooms": people_rooms_run(1 if quick else PEOPLE_ROOMS, 24 if quick else None),
            "rendered": rendered_run(scans=6 if quick else None),
            "rendered_rooms": rendered_rooms(0 if quick else RENDERED_ROOMS)["worst"],
            "timing": time_per_scan(4 if quick else 8),
            "timing_20k": time_per_scan(4 if quick else 8, points=20_000)}


def scene_measures(scene: Scene, scans: int | None = None, robot: RobotShape = ROBOT,
                   params: FloorConfig = PARAMS) -> dict[str, dict[str, float]]:
    """The measures of `measure` on one scene, for hazard scenes other than the built-in
    ones: drop-offs and ramps (`hazard_run`, for `robot` with `params`), and ghosts and
    walls where it has people (`people_run`)."""
    out = {"hazards": hazard_run(scans, scene=scene, robot=robot, params=params)}
    if scene.people:
        out["people"] = people_run(scans, scene=scene)
    return out


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see the module docstring) for `python -m benchmarks`."""
    m = measure(quick)
    h, placed, people, timing = m["hazards"], m["placed"], m["people"], m["timing"]
    crowd = m["people_rooms"]
    rooms = m["random"]
    scenes = (h, placed, rooms)
    per_scan = 1e-3 * timing["per_scan_ms"]
    rendered, crowd_rendered = m["rendered"], m["rendered_rooms"]
    both = [rendered] + ([crowd_rendered] if crowd_rendered["rooms"] else [])
    rendered_rooms_text = (f" and {crowd_rendered['rooms'] // 2} random and mixed rooms each"
                           if crowd_rendered["rooms"] else "")
    edge_rendered = max(r["edge_error_cells"] for r in both)
    within_rendered = min(r["edge_within_one"] for r in both)
    false_rendered = max(r["drop_false"] for r in both)
    f1_rendered = min(r["obstacle_f1"] for r in both)
    ramp_rendered = min((r["ramp_f1"] for r in both if not math.isnan(r["ramp_f1"])),
                        default=math.nan)
    settings = "ideal scans at true poses, 5 cm cells, default robot"
    return [
        {"stage": "hazards", "method": "drop-off cells free or traversable (gate)",
         "settings": f"built-in hazards scene, {settings}", "median_s": per_scan,
         "error": h["drop_free"], "error_unit": "cells (goal 0)", **h, "peers": {}},
        {"stage": "hazards", "method": "drop-off cells on floor a cell off any drop-off",
         "settings": f"built-in hazards scene, {settings}; {placed['placements']} "
         "placements; random rooms",
         "median_s": None, "error": h["drop_false_any_scan"],
         "error_unit": f"cells after the worst scan ({placed['drop_false_any_scan']} placed, "
         f"{rooms['drop_false_any_scan']} in rooms)", "peers": {}},
        {"stage": "hazards", "method": "drop-off edge error",
         "settings": f"built-in hazards scene, {settings}; {placed['placements']} "
         f"placements; {rooms['rooms']} random rooms",
         "median_s": None, "error": max(run["edge_error_cells"] for run in scenes),
         "error_unit": "cells after the last scan, worst (goal 1); after any scan "
         f"{max(run['edge_error_any_scan'] for run in scenes):.2f}, least share within "
         f"a cell {min(run['edge_within_one_any_scan'] for run in scenes):.3f}",
         "peers": {}},
        {"stage": "hazards", "method": "ramp floor F1", "settings": "7 and 20 deg ramps",
         "median_s": None, "error": 1.0 - h["ramp_f1"],
         "error_unit": f"1 - F1 (goal 0.03); traversable (floor and FREE) "
         f"{1.0 - h['ramp_traversable_f1']:.3f}",
         "peers": {}},
        {"stage": "hazards", "method": "drop-off cells free, scene placed anew on the cells",
         "settings": f"built-in hazards scene shifted within a cell and turned, "
         f"{placed['placements']} placements, {settings}; worst over them",
         "median_s": None, "error": placed["drop_free_any_scan"],
         "error_unit": "cells after any scan (goal 0)", **placed, "peers": {}},
        {"stage": "hazards", "method": "drop-off cells free in random hazard rooms",
         "settings": f"{rooms['rooms']} rooms drawn afresh (benchmarks.random_rooms, seeds "
         f"1-{rooms['rooms']}), {settings}; worst over them",
         "median_s": None, "error": rooms["drop_free_any_scan"],
         "error_unit": "cells after any scan (goal 0)", **rooms, "peers": {}},
        {"stage": "hazards", "method": "drop-off cells free through the whole pipeline",
         "settings": f"built-in hazards scene{rendered_rooms_text}, webcam frames rendered "
         "and mapped by scanmap map (extraction, decoding, registration), 5 cm cells, "
         "default robot; worst over them",
         "median_s": rendered["seconds_per_scan"],
         "error": max(rendered["drop_free"], crowd_rendered["drop_free"]),
         "error_unit": "cells more than a cell inside a drop-off after the last scan (goal "
         f"0); edge error {edge_rendered:.2f} cells (goal 1), least share within a cell "
         f"{within_rendered:.3f}; false drop-off cells {false_rendered}; least obstacle F1 "
         f"{f1_rendered:.3f}; least ramp floor F1 {ramp_rendered:.3f}", **rendered,
         "peers": {}},
        {"stage": "hazards", "method": "ghost cells three scans after a person left",
         "settings": f"built-in people scene, {settings}", "median_s": None,
         "error": people["ghost_cells"], "error_unit": f"cells of {people['left_cells']} "
         "checked (goal 0)", **people, "peers": {}},
        {"stage": "hazards", "method": "ghost cells the later scans saw through",
         "settings": f"built-in people scene, {settings}, band crossed by the camera's rays "
         f"in {SEE_THROUGH_SHARE:.0%} of its height bins since the person left, and in "
         "every bin where the map holds a level",
         "median_s": None, "error": people["ghost_cells_seen_through"],
         "error_unit": f"cells of {people['left_cells_seen_through']} checked (goal 0); "
         f"with the laser's rays too: {people['ghost_cells_lit_through']} of "
         f"{people['left_cells_lit_through']}", "peers": {}},
        {"stage": "hazards", "method": "wall cells eroded in rooms with people",
         "settings": f"{crowd['rooms']} rooms drawn afresh (benchmarks.random_rooms."
         f"people_room, seeds 1-{crowd['rooms']}), cabinets turned, four people each, "
         f"{settings}; summed, {crowd['rooms_eroded']} rooms with any",
         "median_s": None, "error": crowd["wall_cells_eroded"],
         "error_unit": f"cell-scans (goal 0; {crowd['wall_cells_freed']} FREE; "
         f"{crowd['wall_cells_eroded_deep']} in cells cut over {DEEP_CUT * 100:.0f} cm deep; "
         f"{crowd['wall_cells_eroded_strict']} with the cells a face grazes); ghosts "
         "three scans after a person left: "
         f"{crowd['ghost_cells']} of {crowd['left_cells']}, seen through "
         f"{crowd['ghost_cells_seen_through']} of {crowd['left_cells_seen_through']}",
         **crowd, "peers": {}},
        *({"stage": "hazards", "method": "fuse + segment one scan",
           "settings": f"corridor, {t['points_per_scan']:.0f} points{thinned}, 8 m window "
           "(budget: 5 ms at 20,000 points)",
           "median_s": 1e-3 * t["per_scan_ms"], "error": None, **t, "peers": {}}
          for t, thinned in ((timing, ""), (m["timing_20k"], " (frames kept evenly)"))),
    ]


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer scans")
    parser.add_argument("--scene", action="append", default=[], metavar="SCENE",
                        help="measure this scene file (or built-in scene) instead: the "
                        "drop-off and ramp measures, and with people the ghost ones; "
                        "repeatable")
    for family in FAMILIES:
        parser.add_argument(f"--{family}", type=int, metavar="N",
                            help=f"instead: the drop-off and ramp measures on N {family} "
                            "rooms (benchmarks.random_rooms), each and the worst")
    parser.add_argument("--rendered", type=int, metavar="N",
                        help="instead: the drop-off measures through the whole pipeline "
                        "(frames rendered, scanmap map) on N random and N mixed rooms")
    parser.add_argument("--people", type=int, metavar="N",
                        help="instead: the ghost and erosion measures on N rooms with "
                        "people (benchmarks.random_rooms), each and summed")
    parser.add_argument("--rendered-approach", type=int, metavar="N",
                        help="instead: the same through the whole pipeline on N approach "
                        "rooms (a hazard across the path, driven at head-on)")
    parser.add_argument("--rendered-people", action="store_true",
                        help="instead: the ghost and erosion measures on the built-in "
                        "people scene through rendered frames (true poses)")
    parser.add_argument("--pixel-sigma", type=float, metavar="PX",
                        help="the rooms' laser peak noise (px; default the scanner model's "
                        "0.1, the extraction leaves 0.33 on the real flat-board images)")
    parser.add_argument("--first", type=int, default=1, metavar="SEED",
                        help="the rooms' first seed (default 1): fresh seeds are rooms "
                        "no rule was tried on")
    parser.add_argument("--step-height", type=float, default=ROBOT.step_height, metavar="M",
                        help="the robot's step (m) for the drop-off and ramp measures of "
                        f"the rooms and --scene (default {ROBOT.step_height})")
    parser.add_argument("--max-slope", type=float, metavar="DEG",
                        default=round(math.degrees(PARAMS.max_slope), 6),
                        help="the robot's steepest ramp (deg) for the same (default "
                        f"{math.degrees(PARAMS.max_slope):g})")
    args = parser.parse_args(argv)
    robot = replace(ROBOT, step_height=args.step_height)
    params = replace(PARAMS, max_slope=math.radians(args.max_slope))
    scans = 8 if args.quick else None
    for family, draw in FAMILIES.items():
        count = getattr(args, family) or 0
        rooms = {f"{family}_room({seed})": hazard_run(scans, scene=draw(seed),
                                                      pixel_sigma=args.pixel_sigma,
                                                      robot=robot, params=params)
                 for seed in range(args.first, args.first + count)}
        if rooms:
            print(json.dumps(rooms | {"worst": rooms_summary(list(rooms.values()))},
                             indent=1))
    if args.rendered:
        print(json.dumps(rendered_rooms(args.rendered, args.first, scans), indent=1))
    if args.rendered_approach:
        print(json.dumps(rendered_rooms(args.rendered_approach, args.first, scans,
                                        (approach_room,)), indent=1))
    rooms = people_rooms(args.people or 0, 24 if args.quick else None, args.first)
    if rooms:
        print(json.dumps(rooms | {"sum": people_summary(list(rooms.values()))}, indent=1))
    if args.rendered_people:
        print(json.dumps({"people (rendered)": people_run(24 if args.quick else None,
                                                          rendered=True)}, indent=1))
    if not (args.scene or args.people or args.rendered or args.rendered_approach
            or args.rendered_people
            or any(getattr(args, family) for family in FAMILIES)):
        print(json.dumps(measure(args.quick), indent=1))
    for text in args.scene:
        print(json.dumps({text: scene_measures(resolve_scene(text), scans, robot, params)},
                         indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
