"""Loop closure on every corrected CARMEN log in ../shared/data/real/carmen: the seven
shared ones and any other placed beside them (`benchmarks.carmen_logs`), against the
logs' corrected poses.

Issue 18: no log worse than the registration alone, and no false loop: a loop that joins
two places the reference keeps apart bends the map by metres.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_loop_closure import LOGS, run_loop_closure
from benchmarks.bench_registration import carmen, run_ours
from benchmarks.carmen_logs import REAL, carmen_logs
from scanmap.evaluation.trajectory_errors import ate_rmse
from scanmap_driver.transforms import invert_pose

# A loop measured this far from the reference's relative pose is false. Measured on the
# seven shared logs: at most 0.44 m and 5.6 deg (the reference's own error included).
FALSE_LOOP_M, FALSE_LOOP_DEG = 1.0, 10.0
ATE_TOLERANCE_M = 0.01  # "no worse": an ATE within a centimetre of the registration's

PRESENT = carmen_logs(LOGS)


@pytest.mark.skipif(not PRESENT, reason=f"no CARMEN log in {REAL} (it lives in ../shared)")
@pytest.mark.parametrize("name", PRESENT or ["none"])
def test_loop_closure_closes_only_true_loops_and_never_worsens_a_real_log(name):
    seq = carmen(name, None)
    poses, _, closer = run_loop_closure(seq)
    plain, _ = run_ours(seq)
    for edge in (e for e in closer.graph.edges if e.loop):
        truth = invert_pose(seq.reference[edge.source]) @ seq.reference[edge.target]
        error = invert_pose(truth) @ edge.measurement
        offset = np.hypot(error[0, 3], error[1, 3])
        turn = abs(np.degrees(np.arctan2(error[1, 0], error[0, 0])))
        assert offset < FALSE_LOOP_M and turn < FALSE_LOOP_DEG, (
            f"{name}: loop {edge.source}->{edge.target} is {offset:.2f} m, {turn:.1f} deg "
            "off the reference")
    with_loops = ate_rmse(poses, seq.reference, "se2")
    without = ate_rmse(plain, seq.reference, "se2")
    assert with_loops <= without + ATE_TOLERANCE_M, (name, with_loops, without)
