"""examples/controller.py: polls while mapping, slows near obstacles, stops on stale data."""

from __future__ import annotations

import json
import math

from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.navigation.obstacles import Nearest, QueryStatus

from .conftest import run_example

FRESH = {"clear", "slowing", "obstacle", "unknown nearby"}


def test_the_controller_drives_on_fresh_data_and_stops_when_it_goes_stale(office_recording,
                                                                          tmp_path):
    summary_file = tmp_path / "summary.json"
    result = run_example("controller", "--recording", office_recording, "--speed", 4,
                         "--max-age", 3, "--summary", summary_file, "--workers", 1)
    assert "latency p50" in result.stdout
    summary = json.loads(summary_file.read_text())
    assert summary["scans_mapped"] == 1 and summary["mapping_error"] is None
    assert summary["polls"] > 100
    assert set(summary["polls_by_reason"]) & FRESH  # it moved while the data were fresh
    reasons = [t["reason"] for t in summary["transitions"]]
    assert reasons[0] == "no data" and reasons[-1] == "stale"
    assert summary["final"]["speed"] == 0.0 and summary["final"]["status"] == "STALE"
    fresh_at = next(t["t"] for t in summary["transitions"] if t["reason"] in FRESH)
    stale_at = summary["transitions"][-1]["t"]
    assert stale_at - fresh_at > 2.0  # fresh until the 3 s max age had nearly passed
    for t in summary["transitions"]:
        if t["status"] in ("STALE", "FAULTED") or t["reason"] == "no data":
            assert t["speed"] == 0.0
    latency = summary["latency_us"]
    assert 0 < latency["p50"] <= latency["p90"] <= latency["p99"] <= latency["max"]


@settings(deadline=None)  # the first example imports the controller (seconds under load)
@given(distance=st.floats(0.0, 10.0), closer=st.floats(0.0, 10.0),
       status=st.sampled_from(list(QueryStatus)), age=st.sampled_from([0.1, math.inf]))
def test_the_control_law(examples_on_path, distance, closer, status, age):
    import controller

    limits = controller.Limits()

    def speed(d: float, s: QueryStatus = status) -> float:
        return controller.speed_command(Nearest(d, 0.0, (0.0, 0.0), 0.0, age, s), limits)[0]

    value = speed(distance)
    assert 0.0 <= value <= limits.top
    if status in (QueryStatus.STALE, QueryStatus.FAULTED, QueryStatus.INVALID) \
            or age == math.inf:
        assert value == 0.0
    if status == QueryStatus.UNKNOWN:
        assert value <= limits.creep
    if distance <= limits.stop:
        assert value == 0.0
    if status == QueryStatus.OK and age < math.inf:
        assert speed(min(distance, closer)) <= value  # slower when the obstacle is closer
        assert speed(limits.slow + 1.0) == limits.top
