"""The fleet (issue 20): many recordings reprocessed on a Dask LocalCluster against the
serial jobs, with the figures docs/fleet.md plans from.

Simulates office recordings (4 of 3 scans; in --quick 2 of 1, the second a copy of the
first), runs `process_recording` and `map_to_folder` on each in this process, then
`run_fleet` on a LocalCluster of 1 (not in --quick) and 2 one-thread worker processes
(after warm-up jobs that load the kernels in the workers). Rows give the wall time, the
speed-up over serial, the efficiency (speed-up per worker) and whether every output
array equals the serial one; the planning rows give the MJPG bytes per frame, the
process CPU time per frame, the workers' peak RSS and the scheduler's rate on trivial
tasks (a tenth of them in --quick). On a shared machine the figures move with the load
(the load average is in each row).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from scanmap.pipelines.fleet import connect, run_fleet
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver import reference_scanner
from scanmap_driver.processing import process_recording
from scanmap_driver.recording import INDEX_NAME
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.simulate import simulate_recording

SERIAL: dict[str, Callable[[Path, Path], object]] = {"process": process_recording,
                                                     "map": map_to_folder}
TRIVIAL_TASKS = 2000


def _recordings(scratch: Path, count: int, scans: int, copies: bool = False) -> list[Path]:
    """`count` office recordings of `scans` scans, each its own seed; with `copies`, one
    simulated and the others copies of it (as much work to process, a quarter of the time
    to make)."""
    paths = [scratch / "recordings" / f"office{seed}" for seed in range(count)]
    for seed, path in enumerate(paths):
        if copies and seed:
            shutil.copytree(paths[0], path)
        else:
            simulate_recording(builtin_scene("office"), path, reference_scanner(), seed=seed,
                               scans=scans)
    return paths


def _frames(recording: Path) -> int:
    return sum(s["frames"] for s in json.loads((recording / INDEX_NAME).read_text())["scans"])


def _same_outputs(serial: Path, fleet: Path) -> bool:
    """Every array of every .npz of the serial folder equal in the fleet's folder."""
    for path in sorted(serial.glob("*.npz")):
        with np.load(path) as a, np.load(fleet / path.name) as b:
            if a.files != b.files or not all(
                    np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind in "fc")
                    for k in a.files):
                return False
    return True


def _peak_rss() -> int:
    """This process's peak resident set size in bytes (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _serial(job: str, recordings: list[Path], out: Path) -> tuple[float, float]:
    """Wall and process CPU seconds of the serial job over every recording."""
    SERIAL[job](recordings[0], out / "warm-up")  # compile or load the kernels
    start, cpu = time.perf_counter(), time.process_time()
    for path in recordings:
        SERIAL[job](path, out / path.name)
    return time.perf_counter() - start, time.process_time() - cpu


def _scheduler_rate(client, tasks: int = TRIVIAL_TASKS) -> float:
    """Trivial tasks per second through the scheduler, submit to gather."""
    start = time.perf_counter()
    client.gather(client.map(abs, range(tasks), pure=False))
    return tasks / (time.perf_counter() - start)


def run(quick: bool = False) -> list[dict]:
    """Rows: serial and 1 and 2 workers for `process` and `map`; the planning figures."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        scratch = Path(folder)
        recordings = _recordings(scratch, *((2, 1, True) if quick else (4, 3)))
        frames = sum(_frames(path) for path in recordings)
        video = sum(p.stat().st_size for path in recordings for p in path.glob("*.avi"))
        serial = {job: _serial(job, recordings, scratch / f"serial-{job}") for job in SERIAL}
        settings = f"office, {len(recordings)} recordings, {frames} frames"
        for job, (wall, cpu) in serial.items():
            rows.append({"stage": f"fleet {job}", "method": "serial, this process",
                         "settings": settings, "median_s": wall, "cpu_s": cpu,
                         "cpu_s_per_frame": cpu / frames, "load": os.getloadavg()[0],
                         "peers": {}})
        for workers in (2,) if quick else (1, 2):
            with connect(f"local:{workers}") as client:
                for job in SERIAL:  # load the kernels in the workers
                    run_fleet(client, job, recordings[:2], scratch / f"warm-up-{job}{workers}")
                for job in SERIAL:
                    out = scratch / f"fleet-{job}-{workers}"
                    start = time.perf_counter()
                    run_fleet(client, job, recordings, out)
                    wall = time.perf_counter() - start
                    speedup = serial[job][0] / wall
                    same = all(_same_outputs(scratch / f"serial-{job}" / p.name, out / p.name)
                               for p in recordings)
                    rows.append({
                        "stage": f"fleet {job}", "method": f"LocalCluster, {workers} worker(s)",
                        "settings": f"{settings}; speed-up {speedup:.2f}x, efficiency "
                                    f"{speedup / workers:.2f}, outputs equal: {same}",
                        "median_s": wall, "speedup": speedup,
                        "efficiency": speedup / workers, "outputs_equal": same,
                        "load": os.getloadavg()[0], "peers": {}})
                rss = max(client.run(_peak_rss).values())
                rate = _scheduler_rate(client, TRIVIAL_TASKS // (10 if quick else 1))
        rows.append({"stage": "fleet planning", "method": "figures for docs/fleet.md",
                     "settings": f"{video / frames / 1e3:.1f} kB per MJPG frame, "
                                 f"{frames / serial['process'][1]:.1f} frames/s per core "
                                 f"(process), worker peak RSS {rss / 2**20:.0f} MiB, "
                                 f"scheduler {rate:.0f} trivial tasks/s",
                     "median_s": serial["process"][1] / frames,
                     "bytes_per_frame": video / frames,
                     "frames_per_s_per_core": frames / serial["process"][1],
                     "map_cpu_s_per_frame": serial["map"][1] / frames,
                     "worker_peak_rss_bytes": rss, "scheduler_tasks_per_s": rate,
                     "peers": {}})
    return rows


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    print(markdown_table(run()))
