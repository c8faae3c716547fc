"""Consistent snapshots under load: controller threads poll the obstacle API at about
1 kHz each while the mapper maps (the harness of benchmarks/bench_query_load.py).

Every answer must be the answer of ONE whole published snapshot: its `stamp` names the
snapshot, its age agrees (the controllers' clock is fixed), and the same query asked of
an ObstacleMap holding only that snapshot (captured when the mapper published it) must
give the same answer, field for field. A torn read (distance field, segmentation and stamp
from different updates) would give an answer no single snapshot gives.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from benchmarks.bench_query_load import CLOCK, ask, office_scans, poll_while_mapping
from scanmap.navigation.obstacles import ObstacleMap, ObstacleSnapshot, QueryStatus


def same(a: object, b: object) -> bool:
    """Field-for-field equality of two answers (NaN equal to NaN)."""
    if dataclasses.is_dataclass(a):
        return type(a) is type(b) and all(
            same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


def alone(snapshot: ObstacleSnapshot, robot) -> ObstacleMap:
    """An obstacle map that only ever held `snapshot`, on the controllers' clock."""
    single = ObstacleMap(robot, max_age=2 * CLOCK, clock=lambda: CLOCK)
    single.publish(snapshot)
    return single


@pytest.fixture(scope="module")
def load():
    return poll_while_mapping(office_scans(3), threads=3)


def test_answers_come_while_the_snapshot_changes(load):
    stamps = {CLOCK - a.value.age for a in load.answers if a.kind != "distance"
              and math.isfinite(a.value.age)}
    assert len(load.published) == 3 and len(stamps) >= 2  # the swap happened under polling
    assert len(load.answers) > 1000


def test_every_answer_is_the_answer_of_one_whole_snapshot(load):
    robot = load.mapper.obstacles.robot
    singles = {stamp: alone(snap, robot) for stamp, snap in load.published.items()}
    torn, checked = [], 0
    for answer in load.answers:
        if answer.kind == "distance":  # no age: it must be the answer of some snapshot
            candidates = list(singles.values())
        elif not math.isfinite(answer.value.age):  # before the first snapshot
            assert answer.value.status == QueryStatus.UNKNOWN
            continue
        else:  # the answer names its snapshot, and its age agrees with that snapshot
            stamp = answer.value.stamp
            assert stamp in singles and abs(CLOCK - answer.value.age - stamp) < 1e-6
            candidates = [singles[stamp]]
        checked += 1
        if not any(same(answer.value, ask(c, answer.kind, answer.pose)) for c in candidates):
            torn.append(answer)
    assert checked > 500, checked
    assert torn == [], f"{len(torn)} of {checked} answers torn"


def test_no_controller_sees_an_older_snapshot_after_a_newer_one(load):
    for thread in {a.thread for a in load.answers}:
        stamps = [a.value.stamp for a in load.answers if a.thread == thread
                  and a.kind != "distance"
                  and math.isfinite(a.value.age)]
        assert stamps == sorted(stamps)
