"""People pass, walls stay (issue 17): a person who stood near the robot and left is
cleared from the map within three scans, and no wall cell ever erodes."""

from __future__ import annotations

import math

import pytest

from benchmarks.bench_hazards import people_run
from scanmap_driver.sim import Scene, builtin_scene

SCANS = 10


@pytest.fixture(scope="module")
def measures() -> dict[str, float]:
    """The people corridor, the robot creeping along it, one person standing 1 m from it
    for scans 0-3 and gone from scan 4."""
    data = builtin_scene("people").to_dict()
    data["people"] = [{"radius": 0.2, "height": 1.7, "color": [90, 70, 160], "name": "visitor",
                       "track": [[0, 1.0, 0.55], [3, 1.0, 0.55], [4, 20.0, 0.55]]}]
    return people_run(SCANS, scene=Scene.from_dict(data))


def test_walls_never_erode_and_keep_their_recall(measures):
    assert measures["wall_cells_eroded"] == 0
    assert measures["wall_recall_people"] >= measures["wall_recall_empty"] - 0.01


@pytest.mark.xfail(strict=True, reason="known gap (issue 17): a few cells of the person's "
                   "rim stay OBSTACLE more than three scans after it left")
def test_a_person_who_left_is_gone_within_three_scans(measures):
    assert measures["left_cells"] > 50  # the cells checked
    assert measures["ghost_cells"] == 0


@pytest.mark.xfail(strict=True, reason="known gap (issue 17): rays that clip the free corner "
                   "of a cell whose centre a face cuts clear the face's level (16 wall "
                   "cell-scans eroded, 3 of them to FREE)")
def test_walls_never_erode_where_the_scene_lies_at_a_slant_to_the_cells():
    """The people scene turned by -33 deg and shifted within a cell: faces cut cells off
    their centres. Letting only rays within 1.75 cm of a cell's centre or of its level's
    mean hit clear the level fixed this (0 eroded) but left a person's rim cells standing
    when later rays only clipped them (a box the robot had seen for six scans kept 2
    cells for more than 11 scans after it left; ghost cell-scans of the people run 1879 ->
    2334), so it was not kept."""
    scene = builtin_scene("people").moved(0.02, 0.01, math.radians(-33.0))
    measured = people_run(scene=scene)
    assert measured["wall_cells_eroded"] == 0
