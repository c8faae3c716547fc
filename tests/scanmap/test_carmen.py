"""CARMEN log reader: synthetic logs with known odometry, the real Intel log, bad input."""

from __future__ import annotations

import gzip
import itertools

import numpy as np
import pytest

from scanmap.datasets.carmen import carmen_scan_points, read_carmen
from scanmap_driver.errors import RecordingError
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose
from tests.conftest import real_data


def _flaser(ranges, pose, odom, t):
    values = " ".join(f"{v:.6f}" for v in (*ranges, *pose, *odom, t))
    return f"FLASER {len(ranges)} {values} host {t}\n"


def _odom(pose, t):
    return f"ODOM {pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f} 0 0 0 {t} host {t}\n"


def _write_anchored_log(path, raw, corrected):
    """A log in the 'corrected' layout: odometry re-anchored at each corrected pose."""
    lines = ["# message formats defined: ODOM FLASER\n", _odom(raw[0], 0.5)]
    ranges = np.full(180, 2.0)
    for k in range(len(raw)):
        lines.append(_flaser(ranges, corrected[k], corrected[k], float(k)))
        if k + 1 < len(raw):
            lines.append(_odom(corrected[k], 0))  # the anchor
            step = invert_pose(se2_to_pose(*raw[k])) @ se2_to_pose(*raw[k + 1])
            middle = se2_to_pose(*corrected[k]) @ step
            lines.append(_odom(pose_to_se2(middle), k + 0.9))
    with gzip.open(path, "wt") as fh:
        fh.writelines(lines)


def test_anchored_odometry_is_rechained_into_the_raw_trajectory(tmp_path):
    rng = np.random.default_rng(1)
    raw = np.cumsum(rng.normal(0, 0.3, (12, 3)), axis=0)
    corrected = raw + rng.normal(0, 0.2, raw.shape)
    _write_anchored_log(tmp_path / "a.log.gz", raw, corrected)
    log = read_carmen(tmp_path / "a.log.gz")
    assert len(log) == 12
    np.testing.assert_allclose(log.poses, corrected, atol=1e-6)
    # Raw odometry up to a rigid transform that puts its start on the first corrected pose.
    align = se2_to_pose(*corrected[0]) @ invert_pose(se2_to_pose(*raw[0]))
    expected = np.array([pose_to_se2(align @ se2_to_pose(*p)) for p in raw])
    np.testing.assert_allclose(log.odometry[:, :2], expected[:, :2], atol=1e-4)
    np.testing.assert_allclose(np.cos(log.odometry[:, 2] - expected[:, 2]), 1.0, atol=1e-8)


def test_log_without_odom_lines_uses_flaser_odometry(tmp_path):
    path = tmp_path / "b.log"
    ranges = np.linspace(1.0, 2.0, 180)
    path.write_text(_flaser(ranges, (1, 2, 0.1), (3, 4, 0.2), 1.0)
                    + _flaser(ranges, (1, 2, 0.1), (5, 6, 0.3), 2.0))
    log = read_carmen(path)
    np.testing.assert_allclose(log.odometry, [[3, 4, 0.2], [5, 6, 0.3]])
    assert log.max_range == 2.0


def test_scan_points_follow_the_beam_geometry():
    ranges = np.full(180, 81.83)
    ranges[90] = 2.0   # straight ahead
    ranges[0] = 1.0    # -90 deg: to the right
    ranges[179] = 3.0  # +89 deg
    ranges[10] = np.nan
    points = carmen_scan_points(ranges, height=0.25)
    expected = [[1.0 * np.cos(-np.pi / 2), -1.0, 0.25], [2.0, 0.0, 0.25],
                [3.0 * np.cos(np.deg2rad(89)), 3.0 * np.sin(np.deg2rad(89)), 0.25]]
    np.testing.assert_allclose(points, expected, atol=1e-12)


@pytest.mark.parametrize("text, fragment", [
    ("FLASER 3 1 2\nODOM 0 0 0 0 0 0 1 h 1\n",
     ":1: FLASER needs 11 numbers, got 3 .the line is cut short"),
    ("ODOM 1 2 x 0 0 0 1 h 1\n", ":1: ODOM has a non-numeric field"),
    ("FLASER\nODOM 0 0 0 0 0 0 1 h 1\n", ":1: FLASER needs a beam count"),
    ("ODOM 0 0 0 0 0 0 1 h 1\n", "no usable FLASER/ROBOTLASER1 lines"),
])
def test_bad_logs_name_file_and_line(tmp_path, text, fragment):
    path = tmp_path / "bad.log"
    path.write_text(text)
    with pytest.raises(RecordingError, match=fragment):
        read_carmen(path)


def test_missing_file(tmp_path):
    with pytest.raises(RecordingError, match="file not found"):
        read_carmen(tmp_path / "nope.log.gz")


def test_real_intel_log():
    log = read_carmen(real_data("carmen/intel-corrected.log.gz"))
    assert log.ranges.shape == (910, 180)
    assert log.max_range == pytest.approx(81.83)
    np.testing.assert_allclose(log.odometry[0], log.poses[0])
    # Wheel odometry increments agree with the corrected ones to within a few cm per step
    # (the raw chain drifts by tens of metres over the whole log, its steps do not).
    def steps(traj):
        return np.array([pose_to_se2(invert_pose(se2_to_pose(*a)) @ se2_to_pose(*b))
                         for a, b in itertools.pairwise(traj)])
    diff = steps(log.odometry) - steps(log.poses)
    assert np.median(np.hypot(diff[:, 0], diff[:, 1])) < 0.1  # steps: median 0.67 m
    assert np.median(np.abs(diff[:, 2])) < 0.1  # and 0.38 rad
    assert np.linalg.norm(log.odometry[-1, :2] - log.poses[-1, :2]) > 1.0
    points = log.scan_points(0)
    assert 100 < len(points) <= 180 and np.all(np.linalg.norm(points[:, :2], axis=1) < 40)
