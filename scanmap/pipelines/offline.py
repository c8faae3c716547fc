"""Offline mapping of a recording or a folder of scans into a folder of map products.

`map_to_folder(INPUT, OUT)` is what `scanmap map` runs. It maps every scan as fast as
the machine allows (scans assembled `workers` at a time, `scan_input`), then writes:

    map.npz          the whole map (`mapper_file`; `Mapper.load` resumes from it)
    map.yaml, .pgm   ROS map_server occupancy map, in the `map` frame
    trajectory.tum   one line per scan, in order: base_link in map when the scan started
    overhead.png     the points from above coloured by height (paper Figs. 6-7)
    occupancy.png    the occupancy map with the robot's path
    report.json      stage timings and, where `ground_truth/` exists, the errors

Timings, wall and thread CPU seconds per stage (`StageClock`): "decode", "extract"
(assembly, in the worker threads), "load" (scan files), "register", "fuse" (in the
mapping thread), "segment" and "write" (once, after mapping). The mapping wall time covers
opening INPUT to the last fused scan, video decoding included, and the process CPU time
over the same span counts every thread. Evaluation against ground truth runs after.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from scanmap.datasets.recordings import ScanSource
from scanmap.evaluation import ground_truth as evaluation
from scanmap.io.map_files import save_ros_map
from scanmap.io.map_image import occupancy_image, write_png
from scanmap.io.overhead import overhead_view
from scanmap.io.trajectory import read_tum, write_tum
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper, MapUpdate
from scanmap.navigation.costmap import occupancy_grid
from scanmap.navigation.floor import FREE, OBSTACLE, UNKNOWN, Segmentation
from scanmap.pipelines.resume import Resume, add_located, localisation_summary
from scanmap.stage_clock import StageClock
from scanmap_driver.files import write_json
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel
from scanmap_driver.sim import ScanTruth, TruthRaster, load_scene, truth_path

REPORT_FORMAT = "scanmap.map_report/1"
OBSTACLE_THRESH = 0.5  # occupancy at which a saved map cell is occupied: every obstacle
OFFLINE_CONFIG = MapperConfig(update_obstacles=False, keep_points=0.01)


def offline_config(config: MapperConfig | None = None, *,
                   loop_closure: bool = False) -> MapperConfig:
    """`config` (default: the defaults) for a batch job: the obstacle field is built once
    at the end, not after every scan, and fused points are kept for the overhead view;
    `loop_closure` switches loop closure on whatever `config` says."""
    config = config or OFFLINE_CONFIG
    if loop_closure:
        config = replace(config, loop_closure=replace(config.loop_closure, enabled=True))
    return replace(config, update_obstacles=False,
                   keep_points=config.keep_points or OFFLINE_CONFIG.keep_points)
Progress = Callable[[int, int, MapUpdate], None]


def map_to_folder(source: str | os.PathLike[str], out: str | os.PathLike[str], *,
                  model: ScannerModel | None = None, workers: int | None = None,
                  config: MapperConfig = OFFLINE_CONFIG, progress: Progress | None = None,
                  resume: Resume | str | os.PathLike[str] | None = None) -> dict:
    """Map INPUT (a recording or a folder of scan_NNNN.npz) into `out`; returns the report.

    resume: a map.npz to continue (its settings and scanner model are kept) instead of
    starting a new map, from where the robot stopped or, with a `Resume` that says so,
    from where its first scan is located in it.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    start, start_cpu = time.perf_counter(), time.process_time()
    scans = ScanSource.open(source, model, workers)
    resume = Resume.of(resume)
    mapper = resume.mapper() if resume else Mapper(scans.model, config, offline=True)
    stages: dict[str, list[StageClock]] = defaultdict(list)
    truth_scans = bool(scans.ground_truth and any(scans.ground_truth.glob("scan_*.npz")))
    kept: list[Scan] = []
    notes = []
    outcome: Counter[str] = Counter()
    preload: threading.Thread | None = None
    for done, item in enumerate(scans, start=1):
        if preload is None and done > scans.count - scans.workers and len(mapper):
            preload = preload_segmentation(mapper)
        update = add_located(mapper, item.scan, notes)
        if update is None:
            continue
        outcome.update({update.registration.status.value: 1, "fused": int(update.fused),
                        "degenerate": int(update.registration.degenerate)})
        for clock in (item.timing, update.timing):
            for name in clock.wall:
                stages[name].append(clock)
        if item.error:
            notes.append(f"scan {item.scan.index}: {item.error}")
        if truth_scans:
            kept.append(item.scan)
        if progress:
            progress(done, scans.count, update)
    mapping_wall = time.perf_counter() - start
    mapping_cpu = time.process_time() - start_cpu
    localised = localisation_summary(mapper, notes)

    if preload is not None:
        preload.join()
    products = StageClock()
    with ThreadPoolExecutor(max(scans.workers, 1), thread_name_prefix="scanmap-truth") as pool:
        checks = [pool.submit(scan_errors, scans, scan) for scan in kept]  # meanwhile:
        with products.stage("close_loops"):
            mapper.close_loops()  # nothing to do without loop closure
        with products.stage("segment"):
            seg = mapper.segment()
        with products.stage("write"):
            files = write_products(mapper, seg, out)
        errors = ground_truth_errors(mapper, seg, scans, [check.result() for check in checks])
    for name in products.wall:
        stages[name].append(products)

    recorded = scans.sweep_seconds()
    report = {
        "format": REPORT_FORMAT,
        "input": {"path": str(scans.path), "kind": scans.kind, "scans": scans.count,
                  "resumed": None if resume is None else str(resume.path),
                  "localised": localised},
        "mapping": {"wall_seconds": mapping_wall,
                    "seconds_per_scan": mapping_wall / max(scans.count, 1),
                    "process_cpu_seconds": mapping_cpu,
                    "recorded_seconds": recorded,
                    "speedup": recorded / mapping_wall if recorded else None,
                    "workers": scans.workers, "cpus": os.cpu_count()},
        "stages": {name: _stage(name, clocks) for name, clocks in stages.items()},
        "registration": dict(sorted(outcome.items())),
        "loops": loop_summary(mapper),
        "map": _map_summary(mapper, seg),
        "notes": notes,
        "files": files,
        "errors": errors,
    }
    job_wall = time.perf_counter() - start
    report["job"] = {"wall_seconds": job_wall,
                     "speedup": recorded / job_wall if recorded else None}
    write_json(out / "report.json", _json_safe(report))
    return report


PRELOAD_REACH = 2.0  # m around the newest pose: the window `preload_segmentation` segments


def preload_segmentation(mapper: Mapper) -> threading.Thread | None:
    """Segment the newest pose's surroundings in a background thread and drop the result:
    it loads the segmentation's Numba kernels (19 of them, 0.1 s of CPU under Numba's
    lock) while the last scans are assembled and a worker runs out of work, instead of
    after the loop, where the map's products wait for them. The grid's `layers` copy
    under its lock, so fusion goes on meanwhile. None (nothing started) without a
    finite pose."""
    pose = mapper.latest_pose
    if pose is None or not np.isfinite(pose[:2, 3]).all():
        return None
    x, y = pose[:2, 3]
    window = (x - PRELOAD_REACH, y - PRELOAD_REACH, x + PRELOAD_REACH, y + PRELOAD_REACH)
    thread = threading.Thread(target=mapper.segment, args=(window,),
                              name="scanmap-preload-segmentation")
    thread.start()
    return thread


def report_text(report: dict) -> str:
    """A few lines for people: speed, registration, and the errors when known."""
    m, job = report["mapping"], report["job"]
    lines = [f"{report['input']['scans']} scans mapped: the whole job took "
             f"{job['wall_seconds']:.2f} s (mapping, segmentation, files, report), the "
             f"mapping loop alone "
             f"{m['wall_seconds']:.2f} s ({1e3 * m['seconds_per_scan']:.0f} ms per scan)"]
    if m["speedup"]:
        lines.append(f"{job['speedup']:.1f}x faster than recording ({m['recorded_seconds']:.0f} s)"
                     f"; the loop alone {m['speedup']:.1f}x")
    stages = ", ".join(f"{name} {s['median_cpu_ms']:.1f}"
                       for name, s in report["stages"].items())
    lines.append(f"CPU ms by stage (median per scan; segment and write once): {stages}; "
                 f"{m['process_cpu_seconds']:.1f} CPU s in all threads while mapping")
    lines.append("registration: " + ", ".join(f"{k} {v}"
                                              for k, v in report["registration"].items()))
    if report["loops"]["enabled"]:
        lines.append(loop_text(report["loops"]))
    errors = report["errors"]
    if errors.get("available"):
        for key, label, scale, unit in (("range_m", "range", 1e3, "mm"),
                                        ("heading_rad", "heading", math.degrees(1.0), "deg")):
            e = errors[key]
            if e.get("count"):
                lines.append(f"{label} error: median {scale * e['median_abs']:.1f} {unit}, "
                             f"p95 {scale * e['p95_abs']:.1f} {unit}"
                             + (f", {e['gross']} points more than "
                                f"{100 * evaluation.GROSS_RANGE:.0f} cm off every true point "
                                f"of their column" if "gross" in e else ""))
        t, g = errors["trajectory_m"], errors["map"]
        lines.append(f"trajectory ATE {100 * t['ate_rmse']:.1f} cm over {t['count']} scans; "
                     f"obstacle F1 {g['obstacle_f1']:.3f} (precision "
                     f"{g['obstacle_precision']:.3f}, recall {g['obstacle_recall']:.3f}), "
                     f"free precision {g['free_precision']:.3f}")
        if "free_cells_on_drop_offs" in g:
            lines.append(f"drop-offs: recall {g['drop_off_recall']:.3f}, "
                         f"{g['free_cells_on_drop_offs']} free cells on them "
                         f"({g['free_cells_inside_drop_offs']} more than a cell inside); "
                         "edge within "
                         f"{g['drop_off_edge_error_cells']:.2f} cells "
                         f"({100 * g['drop_off_edge_within_one']:.0f} % within one), "
                         f"{g['false_drop_off_cells']} false")
        elif "false_drop_off_cells" in g:
            lines.append(f"drop-offs: none in the scene, {g['false_drop_off_cells']} cells "
                         "claimed")
        if "ramp_f1" in g:
            lines.append(f"ramps: floor F1 {g['ramp_f1']:.3f}, traversable F1 "
                         f"{g['ramp_traversable_f1']:.3f} over {g['ramp_cells']} observed "
                         "cells of sloped floor")
    return "\n".join(lines)


def write_products(mapper: Mapper, seg: Segmentation, out: Path) -> dict[str, str]:
    """map.npz, map.yaml + map.pgm, trajectory.tum, overhead.png, occupancy.png."""
    mapper.save(out / "map.npz", segmentation=seg)
    occupancy = occupancy_grid(seg)
    # Every obstacle cell (p > 0.5) is written occupied: a planner that crosses unknown
    # space (Nav2's allow_unknown) must never meet an obstacle written as unknown.
    save_ros_map(out / "map.yaml", occupancy, seg.resolution, seg.origin,
                 occupied_thresh=OBSTACLE_THRESH)
    trajectory = mapper.trajectory()
    write_tum(out / "trajectory.tum", trajectory)
    points, _ = mapper.kept_points()
    floor = seg.planes[0].height_at(points[:, 0], points[:, 1]) if seg.planes else 0.0
    path = trajectory.positions[:, :2]
    closer = mapper.loop_closer
    loops = None if closer is None else np.array(
        [[path[loop.candidate], path[loop.query]] for loop in closer.loops
         if max(loop.candidate, loop.query) < len(path)]).reshape(-1, 2, 2)
    write_png(out / "overhead.png", overhead_view(points, floor, path=path, loops=loops))
    picture = occupancy_image(occupancy, seg.origin, seg.resolution)
    if len(path):
        pixels = picture.pixel(path)
        cv2.polylines(picture.image, [pixels.reshape(-1, 1, 2)], False, (200, 120, 0), 1,
                      cv2.LINE_AA)
    write_png(out / "occupancy.png", picture.image)
    return {name: name for name in ("map.npz", "map.yaml", "map.pgm", "trajectory.tum",
                                    "overhead.png", "occupancy.png", "report.json")}


ScanCheck = tuple[np.ndarray, int, np.ndarray, int]  # what `scan_errors` gives


def scan_errors(scans: ScanSource, scan: Scan) -> ScanCheck | None:
    """A mapped scan's range errors, true laser point count, heading errors and gross
    range errors (`evaluation.gross_ranges`) against its truth file (None when it has
    none: a resumed map's scans)."""
    path = truth_path(scans.path, scan.index)
    if not path.is_file():
        return None
    truth = ScanTruth.load(path, mask=False, laser=evaluation.RANGE_TRUTH_FIELDS)
    columns = evaluation.scan_columns(scan, scans.model)  # once for both
    error, count = evaluation.range_errors(scan, truth, scans.model, columns)
    return (error, count, evaluation.heading_errors(scan, truth),
            evaluation.gross_ranges(scan, truth, scans.model, columns=columns))


def ground_truth_errors(mapper: Mapper, seg: Segmentation, scans: ScanSource,
                        checks: list[ScanCheck | None]) -> dict:
    """Range, heading (`scan_errors` of each scan), trajectory and map errors against the
    input's ground truth."""
    folder = scans.ground_truth
    if folder is None:
        return {"available": False, "reason": f"no ground_truth/ in {scans.path}"}
    errors: dict = {"available": True}
    checks = [check for check in checks if check is not None]
    if checks:  # the scans of this run (not those of a resumed map)
        ranges, counts, headings, gross = zip(*checks, strict=True)
        matched, total = sum(r.size for r in ranges), sum(counts)
        errors["range_m"] = evaluation.statistics(np.concatenate(ranges)) | {
            "matched": matched / total if total else math.nan, "gross": sum(gross)}
        errors["heading_rad"] = evaluation.statistics(np.concatenate(headings))
    else:
        errors["range_m"] = errors["heading_rad"] = {
            "available": False, "reason": "no per-scan truth (scan files, not a recording)"}
    reference = read_tum(folder / "trajectory.txt").poses
    indices = np.array(mapper.scan_indices)
    estimate = mapper.trajectory().poses
    usable = indices < len(reference)
    errors["trajectory_m"] = evaluation.trajectory_errors(estimate[usable],
                                                          reference[indices[usable]])
    raster = TruthRaster.load(folder / "raster.npz")
    world_from_map = evaluation.map_to_world(estimate[usable], reference[indices[usable]])
    scene = folder / "scene.json"  # the simulated scene: the drop-off edge on finer cells
    hits = mapper.grid.layers().nlev > 0  # the window `mapper.segment()` segmented
    errors["map"] = evaluation.map_errors(seg, raster, world_from_map,
                                          load_scene(scene) if scene.is_file() else None,
                                          hits)
    return errors


def _stage(name: str, clocks: list[StageClock]) -> dict[str, float]:
    """Count, total and median (per scan) of a stage's wall and CPU seconds."""
    wall = np.array([c.wall[name] for c in clocks])
    cpu = np.array([c.cpu[name] for c in clocks])
    return {"count": len(clocks), "total_wall_s": float(wall.sum()),
            "total_cpu_s": float(cpu.sum()), "median_wall_ms": 1e3 * float(np.median(wall)),
            "median_cpu_ms": 1e3 * float(np.median(cpu))}


def loop_summary(mapper: Mapper) -> dict:
    """The loops loop closure closed, how they were found and the largest correction."""
    closer = mapper.loop_closer
    if closer is None:
        return {"enabled": False}
    corrections = [loop.correction for loop in closer.loops]
    return {"enabled": True, "closed": len(closer.loops),
            "found_by": dict(Counter(loop.found_by for loop in closer.loops)),
            "largest_correction_m": max(corrections, default=0.0),
            "optimisations": closer.version,
            "optimise_seconds_median": float(np.median(closer.optimise_seconds))
            if closer.optimise_seconds else None}


def loop_text(loops: dict) -> str:
    """One line on the loops `loop_summary` reports."""
    found = ", ".join(f"{n} by {how}" for how, n in loops["found_by"].items())
    return (f"loop closure: {loops['closed']} loops closed ({found or 'none'}), largest "
            f"correction {loops['largest_correction_m']:.2f} m, {loops['optimisations']} "
            "optimisations")


def _map_summary(mapper: Mapper, seg: Segmentation) -> dict:
    area = seg.resolution ** 2
    return {"resolution": seg.resolution, "origin": list(seg.origin),
            "cells": list(seg.shape), "tiles": mapper.grid.tile_count,
            "memory_bytes": mapper.grid.memory_bytes,
            "obstacle_m2": float((seg.state == OBSTACLE).sum() * area),
            "free_m2": float((seg.state == FREE).sum() * area),
            "unknown_m2": float((seg.state == UNKNOWN).sum() * area),
            "floor_planes": len(seg.planes)}


def _json_safe(value):
    """NaN and inf become null (JSON has neither); numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value
