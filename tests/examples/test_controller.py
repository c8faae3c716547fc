"""examples/controller.py: polls while mapping, slows near obstacles, stops on stale data."""

from __future__ import annotations

import json
import math

from hypothesis import example, given, settings
from hypothesis import strategies as st

from scanmap.navigation.floor import OBSTACLE, UNKNOWN
from scanmap.navigation.obstacles import Nearest, QueryStatus, Travel

from .conftest import run_example

FRESH = {"clear", "slowing", "obstacle", "unknown ahead"}


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
@example(distance=0.28, closer=0.0, travel=0.0, status=QueryStatus.OK, ahead_unknown=True,
         age=0.1)  # unknown space touching, an obstacle within stop beside: no creeping
@given(distance=st.floats(0.0, 10.0), closer=st.floats(0.0, 10.0),
       travel=st.floats(0.0, 10.0), status=st.sampled_from(list(QueryStatus)),
       ahead_unknown=st.booleans(), age=st.sampled_from([0.1, math.inf]))
def test_the_control_law(examples_on_path, distance, closer, travel, status, ahead_unknown,
                         age):
    import controller

    limits, radius = controller.Limits(), 0.25
    kind = UNKNOWN if ahead_unknown else OBSTACLE
    ahead_status = QueryStatus.UNKNOWN if ahead_unknown else QueryStatus.OK

    def speed(d: float, t: float = travel) -> float:
        nearest = Nearest(d, 0.0, (0.0, 0.0), 0.0, age, status)
        return controller.speed_command(nearest, Travel(t, kind, age, ahead_status), radius,
                                        limits)[0]

    value = speed(distance)
    assert 0.0 <= value <= limits.top
    if status in (QueryStatus.STALE, QueryStatus.FAULTED, QueryStatus.INVALID) \
            or age == math.inf:
        assert value == 0.0
        return
    if distance <= limits.stop:  # an obstacle that near, in any direction: stop
        assert value == 0.0
    if ahead_unknown and travel == 0.0:  # entering unknown space: creeping at most
        assert value <= limits.creep
    if not ahead_unknown and radius + travel <= limits.stop:
        assert value == 0.0
    # Unknown space ahead is an obstacle to the law, but for creeping into it
    law = limits.top * min(max((min(distance, radius + travel) - limits.stop)
                               / (limits.slow - limits.stop), 0.0), 1.0)
    assert value == law or (ahead_unknown and distance > limits.stop
                            and law < value == limits.creep)
    assert speed(min(distance, closer)) <= value  # slower when the obstacle is closer
    assert speed(distance, min(travel, closer)) <= max(value, limits.creep)
    assert speed(limits.slow + 1.0, limits.slow + 1.0) == limits.top
