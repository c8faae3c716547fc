"""Random hazard rooms (`benchmarks.random_rooms`): scenes drawn afresh from a seed, and
the hazards benchmark's `--random`, `--mixed`, `--step`, `--ramp`, `--terrain`,
`--approach` and `--people` measures on them."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchmarks.bench_hazards import main, mapped
from benchmarks.random_rooms import (
    APPROACH,
    HAZARDS,
    MIXED,
    PEOPLE_SCANS,
    approach_room,
    mixed_room,
    people_room,
    ramp_room,
    random_room,
    step_room,
    terrain_room,
)
from scanmap.navigation.floor import FloorConfig, RobotShape
from scanmap_driver.sim import RASTER_DROP_OFF, RASTER_FLOOR, Scene, truth_raster


def assert_path_clear(room: Scene, seed: int) -> None:
    """The robot (0.25 m round its poses) never stands on a floor region."""
    x, y = room.scan_poses[:, 0], room.scan_poses[:, 1]
    for region in room.floor_regions:
        for dx, dy in ((0.25, 0), (-0.25, 0), (0, 0.25), (0, -0.25)):
            assert not region.contains(x + dx, y + dy).any(), (seed, region.name)
    assert np.isfinite(room.scan_poses).all()


def test_a_seed_draws_one_room_and_other_seeds_other_rooms():
    first, again, other = random_room(1), random_room(1), random_room(2)
    assert first.to_dict() == again.to_dict()
    assert first.to_dict()["floor_regions"] != other.to_dict()["floor_regions"]
    names = sorted(region.name for region in first.floor_regions)
    assert names == sorted(HAZARDS)


def test_every_room_holds_drop_offs_and_ramps_and_a_path_clear_of_them():
    for seed in range(1, 6):
        room = random_room(seed)
        raster = truth_raster(room)
        assert (raster.classes == RASTER_DROP_OFF).sum() > 100
        assert sum(any(region.gradient) for region in room.floor_regions) == 2
        assert_path_clear(room, seed)


def test_a_ramp_rooms_ramps_are_turned_and_lie_either_side_of_max_slope():
    robot, max_slope = RobotShape(), FloorConfig().max_slope
    assert ramp_room(2).to_dict() == ramp_room(2).to_dict()
    for seed in range(1, 6):
        room = ramp_room(seed)
        assert sorted(region.name for region in room.floor_regions) == sorted(HAZARDS)
        raster = truth_raster(room, 0.05, robot.step_height, robot.height, max_slope=max_slope)
        for region in room.floor_regions:
            if not any(region.gradient):
                continue
            degrees = math.degrees(math.atan(math.hypot(*region.gradient)))
            low, high = (12.0, 14.7) if region.name == "ramp" else (15.5, 17.5)
            assert low - 0.01 <= degrees <= high + 0.01, (seed, region.name, degrees)
            # turned with its polygon: its low edge on the floor, its high one a metre on
            corners = np.sort(region.height_at(region.corners[:, 0], region.corners[:, 1]))
            assert 0.0 <= corners[0] <= corners[1] < 0.002, (seed, region.name, corners)
            rise = math.tan(math.radians(degrees))
            assert np.allclose(corners[2:], rise, atol=0.002), (seed, region.name, corners)
            middle = region.corners.mean(axis=0)[None]
            assert (raster.class_at(middle)[0] == RASTER_FLOOR) == (region.name == "ramp")
        assert_path_clear(room, seed)


def test_a_mixed_room_holds_its_hazards_inside_its_walls_beside_a_clear_path():
    assert mixed_room(3).to_dict() == mixed_room(3).to_dict()
    assert mixed_room(3).to_dict()["floor_regions"] != mixed_room(4).to_dict()["floor_regions"]
    for seed in range(1, 6):
        room = mixed_room(seed)
        things = [region.name for region in room.floor_regions] \
            + [box.name for box in room.objects if box.name]
        assert sorted(things) == sorted(MIXED)
        assert sum(region.reflectance == 0.0 for region in room.floor_regions) == 2
        assert (truth_raster(room).classes == RASTER_DROP_OFF).sum() > 100
        low, high = room.bounds()  # the walls'
        for region in room.floor_regions:
            assert (region.corners > low + 0.05).all() and (region.corners < high - 0.05).all()
        assert_path_clear(room, seed)


def test_the_rooms_are_scanned_with_the_laser_peak_noise_asked_for():
    # --pixel-sigma: the floor's heights scatter as the peak's noise grows
    room = step_room(1)

    def floor_scatter(pixel_sigma: float | None) -> float:
        step = list(mapped(room, 2, pixel_sigma=pixel_sigma))[-1]
        raster = truth_raster(room, step.layers.resolution)
        levels, nlev = step.layers.levels, step.layers.nlev
        xs, ys = step.layers.cell_centers()
        gx, gy = np.meshgrid(xs, ys)
        flat = raster.class_at(np.column_stack([gx.ravel(), gy.ravel()])).reshape(gx.shape)
        cells = (flat == RASTER_FLOOR) & (nlev == 1)
        return float(np.std(0.5 * (levels[..., 0, 0] + levels[..., 0, 1])[cells]))

    assert floor_scatter(1.0) > 3.0 * floor_scatter(None)


def test_the_benchmark_measures_random_rooms_and_their_worst(capsys):
    assert main(["--random", "2", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"random_room(1)", "random_room(2)", "worst"}
    worst = out["worst"]
    assert worst["rooms"] == 2
    assert worst["drop_free_any_scan"] == max(out[f"random_room({k})"]["drop_free_any_scan"]
                                              for k in (1, 2))
    assert worst["rooms_with_free_drop_off"] == 0
    assert 0.0 < worst["ramp_f1_min"] <= worst["ramp_f1_mean"] <= 1.0


def test_the_benchmark_measures_mixed_rooms(capsys):
    assert main(["--mixed", "1", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"mixed_room(1)", "worst"}
    assert out["worst"]["rooms"] == 1
    assert out["worst"]["drop_free"] == out["mixed_room(1)"]["drop_free"]


def test_a_people_room_has_people_passing_clear_of_the_robot_and_out_of_sight_between():
    assert people_room(2).to_dict() == people_room(2).to_dict()
    assert people_room(2).to_dict()["people"] != people_room(3).to_dict()["people"]
    for seed in range(1, 6):
        room = people_room(seed)
        cabinets = [box for box in room.objects if box.name == "cabinet"]
        assert len(cabinets) == 3 and len(room.people) == 4
        east = max(box.center[0] for box in room.objects if box.name != "cabinet")
        shown = 0
        for k, (x, y, _) in enumerate(room.scan_poses):
            for person in room.people:
                px, py = person.at_scan(k).center[:2]
                assert px > east or np.hypot(px - x, py - y) > 0.25 + person.radius
                shown += px < east
        assert shown > 20  # people are in the room for a good part of the run
        assert len(room.scan_poses) == PEOPLE_SCANS


def test_the_benchmark_measures_rooms_with_people_and_their_sum(capsys):
    assert main(["--people", "1", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"people_room(1)", "sum"}
    room, total = out["people_room(1)"], out["sum"]
    assert total["rooms"] == 1 and total["ghost_cells"] == room["ghost_cells"]
    assert total["left_cells"] > 0 and 0.9 < total["wall_recall_people"] <= 1.0
    assert total["wall_cells_freed"] <= total["wall_cells_eroded"] \
        <= total["wall_cells_eroded_strict"]
    assert total["wall_cells_eroded_deep"] <= total["wall_cells_eroded"]


def test_a_step_room_holds_one_turned_step_down_just_deeper_than_a_step_beside_the_path():
    assert step_room(5).to_dict() == step_room(5).to_dict()
    depths = []
    for seed in range(1, 6):
        room = step_room(seed)
        (region,) = room.floor_regions
        depths.append(-region.height)
        low, high = room.bounds()  # the walls'
        assert (region.corners > low + 0.05).all() and (region.corners < high - 0.05).all()
        assert (truth_raster(room).classes == RASTER_DROP_OFF).sum() > 100
        assert_path_clear(room, seed)
    assert min(depths) > RobotShape().step_height and max(depths) < 0.09
    assert len(set(depths)) == 5


def test_the_benchmark_measures_step_rooms_from_a_first_seed(capsys):
    assert main(["--step", "1", "--first", "7", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"step_room(7)", "worst"}
    assert out["worst"]["rooms"] == 1
    assert out["worst"]["drop_free"] == out["step_room(7)"]["drop_free"]


def test_a_terrain_rooms_floors_reached_by_ramps_are_floor_and_its_dock_and_stair_drop_offs():
    for seed in range(1, 7):
        room = terrain_room(seed)
        assert room.to_dict() == terrain_room(seed).to_dict()
        raster = truth_raster(room)
        regions = {region.name: region for region in room.floor_regions}
        for name, kind in (("sunken floor", RASTER_FLOOR), ("landing", RASTER_FLOOR),
                           ("ramp down", RASTER_FLOOR), ("ramp up", RASTER_FLOOR),
                           ("dock", RASTER_DROP_OFF), ("stair 4", RASTER_DROP_OFF)):
            centre = np.mean(regions[name].corners, axis=0)
            assert raster.class_at(centre[None])[0] == kind, (seed, name)
        assert regions["sunken floor"].height < -0.1 + 1e-3  # deeper than a step
        assert regions["landing"].height > 0.08 - 1e-3
        assert regions["ramp down"].height_at(*regions["ramp down"].corners.T).max() <= 0.0
        assert_path_clear(room, seed)


@pytest.mark.parametrize("family", ["terrain", "approach"])
def test_the_benchmark_measures_terrain_and_approach_rooms(capsys, family):
    assert main([f"--{family}", "1", "--first", "3", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {f"{family}_room(3)", "worst"}
    assert out[f"{family}_room(3)"]["drop_free"] == 0
    assert out[f"{family}_room(3)"]["drop_found"] > 0


def test_an_approach_rooms_hazard_lies_across_the_path_and_the_robot_stops_short_of_it():
    """Seeds draw the kinds in turn; the floor past a ramp is floor to the truth (reached
    down or up the ramp), past a step, a dock's edge or a stair a drop-off; the robot
    drives at it and its last pose stands 0.15-0.5 m short of the edge, never on it."""
    for seed in range(1, 11):
        room = approach_room(seed)
        assert room.to_dict() == approach_room(seed).to_dict()
        kind = APPROACH[seed % len(APPROACH)]
        regions = room.floor_regions
        assert kind.startswith(regions[0].name.split()[0])
        raster = truth_raster(room)
        far = np.mean(regions[-1].corners, axis=0)
        expected = RASTER_FLOOR if kind.startswith("ramp") else RASTER_DROP_OFF
        assert raster.class_at(far[None])[0] == expected, (seed, kind)
        assert_path_clear(room, seed)
        edge = regions[0].corners[[0, 3]]  # its near side, from y = -half to half
        normal = np.array([edge[1, 1] - edge[0, 1], edge[0, 0] - edge[1, 0]])
        normal /= np.linalg.norm(normal)  # pointing away from the robot
        gaps = (edge[0] - room.scan_poses[:, :2]) @ normal - 0.25  # footprint to the edge
        assert (gaps > 0.15 - 1e-3).all() and gaps[-1] < 0.5 + 1e-3, (seed, gaps[-1])
        assert np.all(np.diff(room.scan_poses[:, 0]) > 0.2)  # driving at it



def test_the_benchmark_measures_the_rooms_for_another_robot(capsys):
    # a robot that climbs 25 cm steps finds fewer drop-offs in the same room: the truth
    # and the map both read the flags
    counts = []
    for flags in ([], ["--step-height", "0.25", "--max-slope", "20"]):
        assert main(["--random", "1", "--first", "2", "--quick", *flags]) == 0
        counts.append(json.loads(capsys.readouterr().out)["random_room(2)"]["drop_cells"])
    assert 0 < counts[1] < counts[0]
