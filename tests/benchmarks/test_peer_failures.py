"""A peer that crashes (SIGSEGV) or hangs in a benchmark module is reported as that peer's
failure with the reason, and ours and the other peers are still measured. The peers are
replaced by module-level functions that really segfault or sleep in their own process."""

from __future__ import annotations

import os
import signal
import time

import numpy as np

import benchmarks.isolation
from benchmarks import bench_grid, bench_loop_closure, bench_simulator
from benchmarks.bench_registration import simulated
from benchmarks.report import markdown_table
from scanmap.grid.height_grid import GridConfig, HeightGrid
from scanmap.grid.rays import scan_rays
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim import builtin_scene, ideal_scans


def _segfault(*args):
    os.kill(os.getpid(), signal.SIGSEGV)


def _hang(*args):
    time.sleep(120)


def _office_grid() -> HeightGrid:
    model = reference_scanner()
    grid = HeightGrid(GridConfig())
    for k, ideal in enumerate(ideal_scans(builtin_scene("office"), model, scans=1)):
        points, origins = scan_rays(ideal.scan, model, ideal.frame_poses)
        grid.insert(points, origins, float(k))
    return grid


def test_distance_field_peers_that_crash_or_hang_fail_alone(monkeypatch):
    monkeypatch.setattr(benchmarks.isolation, "PEER_TIMEOUT", 5.0)
    monkeypatch.setattr(bench_grid, "EDT_PEERS", {"crasher": _segfault, "hanger": _hang,
                                                  "scipy edt": bench_grid.scipy_edt})
    start = time.perf_counter()
    [row] = bench_grid.field_rows(_office_grid(), quick=True)
    assert time.perf_counter() - start < 90  # the hang was cut at its limit
    assert "SIGSEGV" in row["peers"]["crasher"]["failed"]
    assert "no answer within 5 s" in row["peers"]["hanger"]["failed"]
    # Ours and the healthy peer are still scored against the k-d tree's exact distances.
    assert row["median_s"] > 0 and row["error"] < 1e-5
    assert row["peers"]["scipy edt"]["error"] < 1e-5
    assert "crasher: failed (crashed (signal SIGSEGV))" in markdown_table([row])


def test_a_crashing_open3d_leaves_the_ray_casting_row(monkeypatch):
    monkeypatch.setattr(bench_simulator, "open3d_cast", _segfault)
    row = bench_simulator._hit_map_row(reference_scanner())
    [(name, peer)] = row["peers"].items()
    assert name.startswith("Open3D") and "SIGSEGV" in peer["failed"]
    assert row["median_s"] > 0 and 0 <= row["error"] < 1e-6


def test_a_hanging_kiss_slam_is_reported_and_ours_still_scored(monkeypatch):
    monkeypatch.setattr(benchmarks.isolation, "PEER_TIMEOUT", 5.0)
    monkeypatch.setattr(bench_loop_closure, "run_kiss_slam", _hang)
    seq = simulated("corridor", 6)
    row = bench_loop_closure.compare(seq)
    assert "no answer within 5 s" in row["peers"]["KISS-SLAM"]["failed"]
    assert np.isfinite(row["error"]) and row["error"] < 0.05  # ideal scans: cm at most
    assert row["peers"]["ours without loop closure"]["ate_m"] < 0.05
