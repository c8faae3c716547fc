"""Fuzzed CARMEN logs (`read_carmen`): RecordingError naming the file, or a log whose
times and poses are finite and agree in length, and whose NaN, inf or negative readings
(kept for the beam geometry, dropped from the points) are reported in `skipped`."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from scanmap.datasets.carmen import read_carmen
from scanmap_driver.errors import RecordingError

from .mutations import FUZZ, mutated_bytes, read_within


def _log() -> bytes:
    lines = ["# message formats defined: ODOM FLASER\n"]
    for k in range(6):
        pose = (0.1 * k, 0.02 * k, 0.05 * k)
        ranges = " ".join(f"{2.0 + 0.01 * b:.3f}" for b in range(180))
        numbers = " ".join(f"{v:.6f}" for v in (*pose, *pose, float(k)))
        lines.append(f"ODOM {pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f} 0 0 0 {k - 0.1} h {k}\n")
        lines.append(f"FLASER 180 {ranges} {numbers} host {k}\n")
    return "".join(lines).encode()


ORIGINAL = _log()


@FUZZ
@given(data=st.data())
def test_fuzzed_carmen_log_is_refused_or_read_finite(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("carmen") / "robot.log"
    path.write_bytes(data.draw(mutated_bytes(ORIGINAL)))
    log = read_within(lambda: read_carmen(path), RecordingError, path)
    if log is None:
        return
    m = len(log)
    assert log.ranges.shape[0] == log.times.shape[0] == log.poses.shape[0] == m
    assert np.isfinite(log.times).all() and np.isfinite(log.poses).all()
    assert np.isfinite(log.odometry).all()
    bad = int((~np.isfinite(log.ranges) | (log.ranges < 0)).sum())  # kept, but reported
    assert bad <= sum(n for what, n in log.skipped.items() if "range readings" in what)
