"""Obstacle queries under load: controller threads poll `mapper.obstacles` at about 1 kHz
each (nearest, polar, clearance, distance in turn) while the mapper maps office scans in
its background thread, on the same cores.

    .venv/bin/python -m benchmarks.bench_query_load [--quick]

Rows: the latency of each query kind (p50 as the median time, p99 and max beside it), and
the rate each controller thread reached. The controllers' clock is fixed (`CLOCK`), so
an answer's age names the stamp of the snapshot it came from:
tests/scanmap/test_snapshot_consistency.py uses the same harness to check that every
answer is the answer of one whole published snapshot.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper
from scanmap.navigation.obstacles import ObstacleMap, ObstacleSnapshot
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim import builtin_scene, ideal_scans

CLOCK = 1.0e6  # s: the controllers' clock; age = CLOCK - snapshot stamp
KINDS = ("nearest", "polar", "clearance", "distance")
POSES = ((0.5, 0.0, 0.0), (1.0, 0.5, 1.0), (-0.5, 0.3, 2.0), (0.0, -0.8, -1.5))
POLAR_BINS = 90


@dataclass(frozen=True)
class Answer:
    """One query: its kind, pose (x, y, yaw), the API's answer, latency (s), thread."""

    kind: str
    pose: tuple[float, float, float]
    value: Any
    latency: float
    thread: int


@dataclass
class LoadRun:
    """What a run produced: every answer, every snapshot published (by stamp), the run's
    wall time (s) and the mapper."""

    answers: list[Answer]
    published: dict[float, ObstacleSnapshot]
    seconds: float
    mapper: Mapper


def ask(obstacles: ObstacleMap, kind: str, pose: tuple[float, float, float]) -> Any:
    """The answer of one query of `kind` at `pose`."""
    x, y, yaw = pose
    if kind == "nearest":
        return obstacles.nearest(x, y)
    if kind == "polar":
        return obstacles.polar(x, y, yaw, bins=POLAR_BINS)
    if kind == "clearance":
        return obstacles.clearance(pose)
    return obstacles.distance(np.array([[x, y]]))


def office_scans(count: int) -> list[Scan]:
    """`count` ideal scans of the built-in office."""
    return [ideal.scan for ideal in ideal_scans(builtin_scene("office"), seed=4, scans=count)]


def poll_while_mapping(scans: Sequence[Scan], threads: int = 3, rate: float = 1000.0,
                       scan_interval: float = 0.5) -> LoadRun:
    """Map `scans` in the mapper's thread while `threads` controllers poll at `rate` Hz.

    Scans arrive at most one per `scan_interval` seconds (the scanner takes about 2 s a
    scan), so that every snapshot is polled a while however fast this machine maps."""
    mapper = Mapper(reference_scanner(), replace(MapperConfig(), max_age=2 * CLOCK),
                    clock=lambda: CLOCK)
    published: dict[float, ObstacleSnapshot] = {}
    update = mapper.obstacles.update

    def recorded_update(*args: Any, **kwargs: Any) -> ObstacleSnapshot:
        snapshot = update(*args, **kwargs)
        published[snapshot.stamp] = snapshot
        return snapshot

    mapper.obstacles.update = recorded_update
    done = threading.Event()
    answers: list[list[Answer]] = [[] for _ in range(threads)]

    def controller(number: int) -> None:
        period, due, k = 1.0 / rate, time.perf_counter(), number
        while not done.is_set():
            kind, pose = KINDS[k % len(KINDS)], POSES[k % len(POSES)]
            k += 1
            start = time.perf_counter()
            value = ask(mapper.obstacles, kind, pose)
            answers[number].append(Answer(kind, pose, value, time.perf_counter() - start,
                                          number))
            due += period
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            else:
                due = time.perf_counter()  # behind: carry on, no burst to catch up

    pollers = [threading.Thread(target=controller, args=(n,)) for n in range(threads)]
    started = time.perf_counter()
    for poller in pollers:
        poller.start()
    mapping = mapper.start()
    for scan in scans:
        due = time.perf_counter() + scan_interval
        mapping.submit(scan, timeout=300)
        time.sleep(max(due - time.perf_counter(), 0.0))
    mapping.close()
    finished = mapping.join(timeout=600)
    done.set()
    for poller in pollers:
        poller.join()
    if not finished or mapping.error is not None:
        raise RuntimeError(f"mapping did not finish cleanly ({mapping.error})")
    return LoadRun([a for out in answers for a in out], published,
                   time.perf_counter() - started, mapper)


def run(quick: bool = False) -> list[dict]:
    """Latency rows per query kind while mapping (see the module docstring)."""
    threads = 3
    load = poll_while_mapping(office_scans(3 if quick else 6), threads=threads)
    settings = (f"{threads} threads at 1 kHz each while mapping {len(load.published)} "
                f"office scans, 2 cores shared")
    rows = []
    for kind in KINDS:
        latency = np.array([a.latency for a in load.answers if a.kind == kind])
        p50, p99 = np.percentile(latency, [50, 99])
        rows.append({"stage": "obstacle query under load", "method": f"{kind}()",
                     "settings": settings, "median_s": float(p50), "p99_s": float(p99),
                     "max_s": float(latency.max()), "queries": int(latency.size),
                     "error": None, "peers": {}})
    per_thread = len(load.answers) / threads / load.seconds
    rows.append({"stage": "obstacle query under load", "method": "rate per thread (Hz)",
                 "settings": settings, "median_s": None, "rate_hz": per_thread,
                 "error": None, "peers": {}})
    return rows


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 scans instead of 6")
    for row in run(quick=parser.parse_args().quick):
        figures = {k: row[k] for k in ("median_s", "p99_s", "max_s", "queries", "rate_hz")
                   if row.get(k) is not None}
        print(row["method"], {k: f"{v:.3g}" for k, v in figures.items()})
