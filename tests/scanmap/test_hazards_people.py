"""People pass, walls stay (issue 17): a person who stood near the robot and left is
cleared from the map within three scans, and no wall cell ever erodes."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from benchmarks.bench_hazards import people_run
from benchmarks.random_rooms import people_room
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


def test_the_lasers_rays_clear_most_of_where_the_person_stood(measures):
    """It stood 1 m from the robot, where no later camera ray crosses the band's low
    heights: 16 of the 272 cells it left stayed OBSTACLE more than three scans later
    until the grid cleared along the laser's rays too (from its emitter, 0.5 m lower),
    9 since, 5 since the levels the laser's plane swept unlit are missed."""
    assert measures["left_cells"] > 250  # the cells checked
    assert measures["ghost_cells"] <= 0.04 * measures["left_cells"]


@pytest.mark.xfail(strict=True, reason="known gap (issue 17): 5 of the 272 cells the "
                   "person left stay OBSTACLE more than three scans later; it stood 1 m from "
                   "the robot, where no later camera ray crosses the band's low heights "
                   "(none of those cells is seen through) and the laser's rays pass them "
                   "away from their hits")
def test_a_person_who_left_is_gone_within_three_scans(measures):
    assert measures["left_cells"] > 50  # the cells checked
    assert measures["ghost_cells"] == 0


@pytest.mark.parametrize(("dx", "dy", "yaw"), [(0.025, 0.025, 0.0), (0.02, 0.01, -33.0)])
def test_walls_never_erode_where_the_scene_lies_at_a_slant_to_the_cells(dx, dy, yaw):
    """The people scene shifted within a cell, and turned: faces cut cells off their
    centres, and rays through a cell's free part used to clear the face's level (3 and 16
    wall cell-scans eroded, some to FREE). A level hit in GridConfig.static_scans scans
    is now cleared only by rays near its mean hit."""
    scene = builtin_scene("people").moved(dx, dy, math.radians(yaw))
    measured = people_run(scene=scene, empty_run=False)
    assert measured["wall_cells_eroded"] == 0


def test_a_face_seen_from_nearly_in_its_plane_does_not_erode():
    """people_room(6): a cabinet turned 16.7 deg; from scan 14 the robot stands almost in
    the plane of its end face, and rays run along the face through the free part of the
    cells it cuts, near their mean hits (11 wall cell-scans eroded by scan 20, 4 to FREE,
    before GridConfig.graze_angle)."""
    measured = people_run(20, scene=people_room(6), empty_run=False)
    assert measured["wall_cells_eroded"] == 0
    assert measured["wall_cells_freed"] == 0


def test_an_end_face_seen_only_on_the_way_towards_it_does_not_erode():
    """people_room(10): a cabinet's end face faces the robot's start; it is hit in the
    8-9 scans before the robot passes it, then rays through the free part of the cell
    its corner cuts cleared it (28 wall cell-scans eroded from scan 17 while
    GridConfig.static_scans was 10; 8 keeps it)."""
    measured = people_run(20, scene=people_room(10), empty_run=False)
    assert measured["wall_cells_eroded"] == 0


def test_a_cabinets_corner_hit_in_fewer_scans_than_its_face_does_not_erode():
    """people_room(15): the corner cell of a turned cabinet's end, its level hit in fewer
    scans than the long face beside it, was cleared from scan 18 by rays through the
    cell's free part, and its floor hits left it FREE (27 cell-scans): a level beside a
    static one at its heights is passed only near its mean hit."""
    measured = people_run(20, scene=people_room(15), empty_run=False)
    assert measured["wall_cells_eroded"] == 0


def test_a_static_corner_passed_close_beside_it_does_not_erode():
    """people_room(19002): a cabinet turned 16.6 deg, its corner cut 1-2 cm into a cell;
    the mean hit of the corner's two faces lies within `pass_radius` of both, and once
    the robot had passed, rays past the corner cleared the static level over scans 18-23
    (FREE at scan 23, with or without people). All the static levels around such a
    ray lie on one side of it: it passes a corner, it did not cross the surface."""
    measured = people_run(25, scene=people_room(19002), empty_run=False)
    assert measured["wall_cells_eroded"] == 0


def test_rays_within_millimetres_of_a_static_corner_do_not_erode_it():
    """people_room(20001) without its people: a cabinet turned 10.6 deg cuts its corner
    4 mm into a cell. Once the robot had passed, rays within millimetres of the corner
    took the cell's static level a miss: the mean hit of the corner's neighbouring cell
    lay 3 mm off the corner, on the rays' far side of the parallel through the level's
    mean hit, so the rays did not seem to pass a corner (FREE from scan 33). The sides
    are now read from the ray's own line, a mean hit within half `pass_radius` of it on
    neither."""
    measured = people_run(34, scene=replace(people_room(20001), people=()))
    assert measured["wall_cells_eroded"] == 0


@pytest.mark.xfail(strict=True, reason="known gap (issue 17): people_room(23): a cabinet's "
                   "end face lies 5 mm inside its cells; hit in one scan as the robot starts, "
                   "it is cleared by rays through the cells' free part (10 wall cell-scans "
                   "no longer OBSTACLE in scans 0-9, none FREE; rooms 13-24: 257 in 7 "
                   "rooms, 13 FREE)")
def test_an_end_face_hit_in_one_scan_at_the_start_does_not_erode():
    assert people_run(10, scene=people_room(23), empty_run=False)["wall_cells_eroded"] == 0
