"""The whole pipeline: a raw recording to a map, video decoding included (issue 8's goal:
the corridor maps at least 20 times faster than it took to record, 2 s per scan).

Runs `scanmap map` (`offline.map_to_folder`) on the corridor recording of the examples
(./data/corridor_recording, 20 scans; simulated into a temporary folder when absent, 2
scans in --quick) with 1 and 2 assembly threads, after a warm-up run that compiles the
kernels. Rows give the wall time per scan, the process CPU time per scan (all threads;
what an idle machine would need, divided by its cores) and the speed-up over the sweep
time; errors are the trajectory ATE and the obstacle F1 against the ground truth, and
the stage rows say where the time goes (median CPU per scan). The online mapper (obstacle
field rebuilt after every scan, as a controller needs) is timed on the same scans. The
whole command (issue 16: what a user waits for, from start to exit, at least 20 times
faster than recording) is timed in a new process each run, as a shell runs it: the
median of COMMAND_RUNS runs (one in --quick).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
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
COMMAND_RUNS = 7


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


def map_command(recording: Path, out: Path) -> list[str]:
    """The `scanmap map` command line a user runs, with this interpreter."""
    return [sys.executable, "-m", "scanmap", "map", str(recording), "--out", str(out)]


def command_row(recording: Path, scratch: Path, runs: int) -> dict:
    """`scanmap map RECORDING` in a new process `runs` times: the median wall time from
    start to exit (interpreter start-up, imports, mapping, segmentation, files, report)
    and its speed-up over the recording's sweep time."""
    out = scratch / "command"
    walls = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(map_command(recording, out), check=True, capture_output=True)
        walls.append(time.perf_counter() - start)
    report = json.loads((out / "report.json").read_text())
    recorded, wall = report["mapping"]["recorded_seconds"], float(np.median(walls))
    return {"stage": "pipeline",
            "method": "scanmap map, the whole command (a new process, start to exit)",
            "settings": f"corridor, {report['input']['scans']} scans ({recorded:.1f} s "
                        f"recorded), median of {runs} runs ({min(walls):.2f}-"
                        f"{max(walls):.2f} s): {recorded / wall:.1f}x faster than recording",
            "median_s": wall, "runs_s": walls, "speedup_vs_recording": recorded / wall,
            "goal_speedup": 20.0, "peers": {}}


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
    """Rows: the pipeline with 1 and 2 threads, its stages, the whole command, the online
    mapper."""
    with tempfile.TemporaryDirectory() as folder:
        scratch = Path(folder)
        recording = corridor_recording(scratch, 2 if quick else 20)
        return (_pipeline_rows(recording, scratch)
                + [command_row(recording, scratch, 1 if quick else COMMAND_RUNS),
                   _online_row(recording)])


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    print(markdown_table(run()))
