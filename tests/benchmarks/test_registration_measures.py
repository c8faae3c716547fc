"""The registration benchmark's reference-free measure, against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_registration import Sequence, scan_agreement
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import se2_to_pose

HALF_X, HALF_Y = 4.0, 2.5  # an axis-aligned room, 8 m x 5 m


def _room_scan(x: float, y: float, theta: float, index: int) -> Scan:
    """A 2-D laser scan (180 beams, 1 deg) of the room from (x, y, theta)."""
    beams = theta + np.deg2rad(np.arange(-90.0, 90.0))
    c, s = np.cos(beams), np.sin(beams)
    with np.errstate(divide="ignore"):
        ranges = np.minimum((HALF_X - x * np.sign(c)) / np.abs(c),
                            (HALF_Y - y * np.sign(s)) / np.abs(s))
    local = beams - theta
    points = np.column_stack([ranges * np.cos(local), ranges * np.sin(local),
                              np.full(beams.size, 0.3)])
    n = len(points)
    odom = se2_to_pose(x, y, theta)
    return Scan(points=points, colors=np.zeros((n, 3), np.uint8), time=np.zeros(n),
                heading=np.zeros(n), frame_index=np.zeros(n, np.int32),
                range_sigma=np.full(n, 0.01), index=index, stamp=float(index),
                odom_start=odom, odom_end=odom)


def test_scan_agreement_measures_how_far_the_poses_pull_the_scans_apart():
    states = [(-2.0 + 0.2 * k, 0.3 * np.sin(k / 3), 0.1 * k) for k in range(12)]
    truth = np.array([se2_to_pose(*state) for state in states])
    seq = Sequence("room", [_room_scan(*state, k) for k, state in enumerate(states)], truth,
                   max_range=12.0, min_range=0.1, extrude=True)
    drift = 0.01  # m per scan along x and y: scans 2 apart disagree by 2 cm on every wall
    drifted = truth.copy()
    drifted[:, 0, 3] += drift * np.arange(len(truth))
    drifted[:, 1, 3] += drift * np.arange(len(truth))
    row = scan_agreement({"ours": truth, "drifted": drifted}, seq, lag=2)
    assert row["error"] < 1e-6
    assert row["peers"]["drifted"]["error"] == pytest.approx(2 * drift, rel=0.05)
