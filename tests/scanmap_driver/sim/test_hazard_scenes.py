"""Hazard scenes: floor regions, ramps, glass, mirrors, black surfaces and people, in the
scene format, the ray caster and the truth raster (issue 17)."""

from __future__ import annotations

import copy
import math
import re

import numpy as np
import pytest

from scanmap_driver.errors import SceneError
from scanmap_driver.sim import (
    RASTER_DROP_OFF,
    RASTER_FLOOR,
    RASTER_OBSTACLE,
    Scene,
    builtin_scene,
    ideal_scans,
    truth_raster,
)
from scanmap_driver.sim.geometry import floor_pieces


@pytest.fixture(scope="module")
def hazards() -> Scene:
    return builtin_scene("hazards")


def region(scene: Scene, name: str):
    return next(r for r in scene.floor_regions if r.name == name)


def named(scene: Scene, name: str):
    return next(o for o in scene.objects if o.name == name)


@pytest.mark.parametrize(("path", "value", "message"), [
    (("floor_regions", 0, "height"), "deep", "floor_regions[0].height: expected a number"),
    (("floor_regions", 0, "polygon"), [[0, 0], [1, 1], [1, 0], [0, 1]],
     "floor_regions[0].polygon: expected a convex polygon"),
    (("floor_regions", 2, "gradient"), [0.0, 1.0], "floor_regions[2].gradient"),
    (("floor_regions", 1, "reflectance"), 1.5, "floor_regions[1].reflectance"),
    (("objects", 4, "surface"), "wood", "objects[4].surface: expected one of"),
    (("floor_regions", 0, "depth"), 1.0, "floor_regions[0]: unknown field(s) depth"),
])
def test_bad_hazard_fields_fail_naming_the_field(hazards, path, value, message):
    data = copy.deepcopy(hazards.to_dict())
    target = data
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    with pytest.raises(SceneError, match=re.escape(message)):
        Scene.from_dict(data, "hazards.json")


def test_a_person_track_must_run_forward():
    data = copy.deepcopy(builtin_scene("people").to_dict())
    data["people"][0]["track"] = [[5, 0.0, 0.0], [2, 1.0, 0.0]]
    with pytest.raises(SceneError, match=r"people\[0\].track: scan indices must increase"):
        Scene.from_dict(data, "people.json")


def test_hazard_scenes_round_trip_through_json():
    for name in ("hazards", "people", "workshop"):
        scene = builtin_scene(name)
        assert Scene.from_dict(scene.to_dict()).to_dict() == scene.to_dict()


def test_floor_pieces_cover_the_floor_outside_the_regions(hazards):
    x0, y0, x1, y1 = -2.0, -3.0, 10.0, 3.0
    pieces = floor_pieces(x0, y0, x1, y1, hazards.floor_regions)
    rng = np.random.default_rng(0)
    p = rng.uniform((x0, y0), (x1, y1), (20000, 2))
    in_region = np.zeros(len(p), bool)
    for r in hazards.floor_regions:
        in_region |= r.contains(p[:, 0], p[:, 1])
    in_piece = np.zeros(len(p), int)
    for piece in pieces:
        edges = np.roll(piece, -1, axis=0) - piece
        cross = edges[:, 0] * (p[:, 1, None] - piece[:, 1]) \
            - edges[:, 1] * (p[:, 0, None] - piece[:, 0])
        in_piece += (cross > 0).all(axis=1)
    assert ((in_piece == 1) == ~in_region).mean() > 0.999  # points on edges aside
    assert (in_piece <= 1).all()


def test_truth_raster_holds_drop_offs_ramps_steps_and_glass(hazards):
    raster = truth_raster(hazards)

    def at(x, y):
        row, col = raster.cell_of(np.array([[x, y]]))[0]
        return raster.classes[row, col], raster.floor_height[row, col], raster.slope[row, col]

    for name in ("stairwell", "loading dock"):
        cx, cy = region(hazards, name).corners.mean(axis=0)
        assert at(cx, cy)[0] == RASTER_DROP_OFF
    ramp = region(hazards, "ramp")
    cls, height, slope = at(*ramp.corners.mean(axis=0))
    assert cls == RASTER_FLOOR and height == pytest.approx(ramp.height, abs=0.01)
    assert slope == pytest.approx(math.atan(math.hypot(*ramp.gradient)), abs=1e-6)
    steep = region(hazards, "steep ramp")
    assert at(*steep.corners.mean(axis=0))[0] != RASTER_FLOOR
    platform = region(hazards, "platform")
    assert at(*platform.corners.mean(axis=0))[0] != RASTER_FLOOR
    assert at(*region(hazards, "black carpet").corners.mean(axis=0))[0] == RASTER_FLOOR
    glass = named(hazards, "glass panel")
    assert at(*glass.center[:2])[0] == RASTER_OBSTACLE


def map_points(ideal) -> np.ndarray:
    """The true stripe points of an ideal scan in `map`."""
    poses = ideal.frame_poses[ideal.scan.frame_index]
    return np.einsum("nij,nj->ni", poses[:, :3, :3], ideal.true_points) + poses[:, :3, 3]


def test_ideal_scans_see_drops_but_not_glass_mirrors_or_black_carpet(hazards):
    points = np.vstack([map_points(i) for i in ideal_scans(hazards, scans=6)])
    x, y, z = points.T
    corners = region(hazards, "stairwell").corners  # its walls below the floor are lit
    low, high = corners.min(axis=0) - 0.01, corners.max(axis=0) + 0.01
    inside = (x > low[0]) & (x < high[0]) & (y > low[1]) & (y < high[1])
    assert (inside & (z < -0.1)).sum() > 50
    carpet = region(hazards, "black carpet").corners  # a rectangle; its edges are floor's
    low, high = carpet.min(axis=0) + 0.002, carpet.max(axis=0) - 0.002
    on_carpet = (x > low[0]) & (x < high[0]) & (y > low[1]) & (y < high[1])
    assert not (on_carpet & (np.abs(z) < 0.01)).any()
    for name in ("glass panel", "mirror"):
        box = named(hazards, name)
        local = np.abs(points - np.array(box.center)) <= np.array(box.size) / 2 + 0.005
        assert not (local.all(axis=1) & (z > 0.01)).any()  # the floor under it aside
    behind_glass = named(hazards, "glass panel").center[1] + 0.05
    assert (y > behind_glass).sum() > 100  # the glass hides nothing behind it


def test_people_stand_where_their_track_puts_them_at_each_scan():
    data = builtin_scene("people").to_dict()
    data["people"][0]["track"] = [[0, 1.2, 0.55], [1, 1.6, 0.55], [5, 3.0, 0.55]]
    scene = Scene.from_dict(data)
    walker = scene.people[0]
    first, second, last = walker.track[0], walker.track[1], walker.track[-1]
    middle = 0.5 * (first[0] + second[0])
    assert walker.at_scan(middle).center[:2] == pytest.approx(0.5 * (first[1:] + second[1:]))
    assert walker.at_scan(last[0] + 10).center[:2] == pytest.approx(last[1:])
    assert len(scene.at_scan(3).objects) == len(scene.objects) + len(scene.people)
    for ideal in ideal_scans(scene, scans=2):
        points = map_points(ideal)
        where = np.array(walker.at_scan(ideal.plan.index).center[:2])
        on_walker = np.hypot(*(points[:, :2] - where).T) <= walker.radius + 0.01
        assert on_walker.sum() > 20


def ramp_into_lower_area(yaw: float) -> Scene:
    """A ramp 1 m long going down 15 cm into a 2 m x 2 m area 15 cm below the floor (they
    share part of an edge), the pair turned by `yaw` about the origin."""
    c, s = math.cos(yaw), math.sin(yaw)

    def turned(x: float, y: float) -> list[float]:
        return [c * x - s * y, s * x + c * y]

    return Scene.from_dict({
        "format": "scanmap.scene/1", "name": "ramp down", "floor": {"color": [150, 140, 125]},
        "ambient": 0.8, "texture": 0.25,
        "objects": [], "scan_poses": [[-2.0, 0.0, 0.0]],
        "floor_regions": [
            {"polygon": [turned(x, y) for x, y in ((0, -0.6), (1, -0.6), (1, 0.6), (0, 0.6))],
             "height": -0.075, "gradient": turned(-0.15, 0.0), "name": "ramp"},
            {"polygon": [turned(x, y) for x, y in ((1, -1), (3, -1), (3, 1), (1, 1))],
             "height": -0.15, "name": "lower area"}]})


@pytest.mark.parametrize("yaw", [0.0, 0.4])
def test_regions_sharing_an_edge_meet_without_a_face_and_keep_their_other_faces(yaw):
    # Each region's edges used to be joined to z = 0 by a face: a ramp down into a lower
    # area got a 15 cm fin at their shared edge, which the truth (floor_at) does not have
    from scanmap_driver.sim.geometry import Raycaster, scene_planes

    scene = ramp_into_lower_area(yaw)
    caster = Raycaster(scene_planes(scene))
    c, s = math.cos(yaw), math.sin(yaw)
    along = np.array([c, s, 0.0])
    # Level rays 1 cm above the lower area, from 1 m inside it back across the shared
    # edge (x = 1, |y| < 0.6): the ramp's surface rises to meet them, no face stops them
    # at the edge; beside the ramp (|y| > 0.6) the lower area's wall does, at the edge
    y = np.array([-0.5, -0.2, 0.0, 0.3, 0.55, -0.8, 0.8])
    origins = np.column_stack([2.0 * c - y * s, 2.0 * s + y * c, np.full(y.size, -0.14)])
    plane, distance = caster.cast(origins, np.tile(-along, (y.size, 1)))
    hit = origins - distance[:, None] * along
    level = scene.floor_at(hit[:, 0], hit[:, 1])[0]
    shared = np.abs(y) < 0.6
    assert (plane >= 0).all()
    np.testing.assert_allclose(hit[shared, 2], level[shared], atol=1e-6)  # the ramp's top
    np.testing.assert_allclose(distance[shared], 1.0 + 0.01 / 0.15, atol=1e-6)
    np.testing.assert_allclose(distance[~shared], 1.0, atol=1e-6)  # the lower area's wall
    # Down onto the strip either side of the shared edge: every hit on the true floor
    u = np.linspace(0.9, 1.1, 41)
    tops = np.column_stack([u * c - 0.1 * s, u * s + 0.1 * c, np.full(u.size, 1.0)])
    _, down = caster.cast(tops, np.tile([0.0, 0.0, -1.0], (u.size, 1)))
    np.testing.assert_allclose(1.0 - down, scene.floor_at(tops[:, 0], tops[:, 1])[0],
                               atol=1e-6)
