"""The whole pipeline: a raw recording to a map, video decoding included (issue 8's goal:
the corridor maps at least 20 times faster than it took to record, 2 s per scan).

Runs `scanmap map` (`offline.map_to_folder`) on the corridor recording of the examples
(./data/corridor_recording, 20 scans; simulated into a temporary folder when absent, 2
scans in --quick) with 1 and 2 assembly threads, after a warm-up run that compiles the
kernels. Rows give the wall time per scan, the process CPU time per scan (all threads;
what an idle machine would need, divided by its cores) and the speed-up over the sweep
time; errors are the trajectory ATE and the obstacle F1 against the ground truth, and
the stage rows say where the time goes (median CPU per scan). The online mapper (obstacle
field rebuilt after every scan, as a controller needs) is timed on the same scans.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from scanmap.datasets.recordings import ScanSource
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver import reference_scanner
from scanmap_driver.recording import INDEX_NAME
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.simulate import simulate_recording

RECORDING = Path(__file__).resolve().parents[1] / "data" / "corridor_recording"


def corridor_recording(scratch: Path, scans: int = 20) -> Path:
    """The examples' corridor recording (./data/corridor_recording) when it is there and
    `scans` is its 20, else `scans` scans of the corridor simulated into `scratch`."""
    if scans == 20 and (RECORDING / INDEX_NAME).is_file():
        return RECORDING
    out = scratch / "corridor"
    simulate_recording(builtin_scene("corridor"), out, reference_scanner(), scans=scans)
    return out


def _pipeline_rows(recording: Path, scratch: Path) -> list[dict]:
    map_to_folder(recording, scratch / "warm-up", workers=2)  # compile or load the kernels
    rows = []
    for workers in (1, 2):
        report = map_to_folder(recording, scratch / f"map{workers}", workers=workers)
        m, errors = report["mapping"], report["errors"]
        scans = report["input"]["scans"]
        rows.append({
            "stage": "pipeline", "method": "scanmap map (decode, extract, register, fuse)",
            "settings": f"corridor, {scans} scans, {workers} thread(s) assembling",
            "median_s": m["seconds_per_scan"],
            "cpu_s_per_scan": m["process_cpu_seconds"] / scans,
            "speedup_vs_recording": m["speedup"], "goal_speedup": 20.0,
            "error": errors["trajectory_m"]["ate_rmse"], "error_unit": "m (ATE)",
            "obstacle_f1": errors["map"]["obstacle_f1"],
            "range_p95_m": errors["range_m"]["p95_abs"], "peers": {}})
    for name, stage in report["stages"].items():
        if stage["count"] == scans:
            rows.append({"stage": f"pipeline: {name}", "method": "median per scan, CPU",
                         "settings": "2 threads assembling",
                         "median_s": stage["median_cpu_ms"] / 1e3,
                         "wall_median_s": stage["median_wall_ms"] / 1e3, "peers": {}})
    return rows


def _online_row(recording: Path) -> dict:
    scans = [item.scan for item in ScanSource.open(recording)]
    mapper = Mapper(reference_scanner(), MapperConfig(), offline=True)
    mapper.warm_up()
    updates = mapper.map_scans(scans)
    per_scan = [sum(u.timing.wall.values()) for u in updates[1:]]
    obstacles = [u.timing.wall.get("obstacles", np.nan) for u in updates[1:]]
    return {"stage": "mapper (online)", "method": "register + fuse + obstacle field",
            "settings": "12 m obstacle window, per scan", "median_s": float(np.median(per_scan)),
            "obstacles_median_s": float(np.nanmedian(obstacles)), "peers": {}}


def run(quick: bool = False) -> list[dict]:
    """Rows: the pipeline with 1 and 2 threads, its stages, the online mapper."""
    with tempfile.TemporaryDirectory() as folder:
        scratch = Path(folder)
        recording = corridor_recording(scratch, 2 if quick else 20)
        return _pipeline_rows(recording, scratch) + [_online_row(recording)]


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    print(markdown_table(run()))
