"""The Mapper against the simulator's ground truth: poses, map, queries, files, resuming."""

from __future__ import annotations

import dataclasses
import json
import zipfile

import numpy as np
import pytest
from scipy.spatial import cKDTree

from scanmap import MapError, Mapper
from scanmap.evaluation.ground_truth import map_errors, map_to_world
from scanmap.grid.height_grid import GridConfig
from scanmap.grid.rays import scan_rays
from scanmap.io.map_files import load_map, save_map
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.scan_motion import frame_poses
from scanmap.navigation.floor import FREE
from scanmap.navigation.obstacles import QueryStatus
from scanmap_driver import reference_scanner
from scanmap_driver.scan import Scan
from scanmap_driver.sim import builtin_scene, ideal_scans, truth_raster
from scanmap_driver.sim.scene import Motion
from scanmap_driver.transforms import se2_to_pose, transform_points

from .scene_footprints import footprint_distance

OFFICE_SCANS = 6


@pytest.fixture(scope="module")
def office():
    """Ideal scans of the first poses round the office table, with the truth."""
    return list(ideal_scans(builtin_scene("office"), seed=3, scans=OFFICE_SCANS))


@pytest.fixture(scope="module")
def mapped(office):
    mapper = Mapper(reference_scanner(), MapperConfig(keep_points=0.02), offline=True)
    updates = mapper.map_scans(ideal.scan for ideal in office)
    return mapper, updates


def true_starts(office) -> np.ndarray:
    return np.array([ideal.pose_start for ideal in office])


def test_poses_follow_the_true_path(office, mapped):
    mapper, updates = mapped
    assert [u.registration.status.value for u in updates] == ["initialised"] + \
        ["ok"] * (OFFICE_SCANS - 1)
    assert all(u.fused for u in updates)
    truth = true_starts(office)
    estimate = mapper.trajectory().poses
    placed = map_to_world(estimate, truth) @ estimate
    error = np.linalg.norm(placed[:, :3, 3] - truth[:, :3, 3], axis=1)
    assert error.max() < 0.02
    assert mapper.trajectory().times.tolist() == [ideal.scan.stamp for ideal in office]


def test_map_matches_the_scene_raster(office, mapped):
    mapper, _ = mapped
    raster = truth_raster(builtin_scene("office"))
    estimate = mapper.trajectory().poses
    errors = map_errors(mapper.segment(), raster, map_to_world(estimate, true_starts(office)))
    assert errors["obstacle_f1"] >= 0.95
    # Free is (almost) never claimed on an obstacle. A few cells under the table top are:
    # rays passed under it at most band heights and none hit it there (`floor._states`'
    # min_coverage trade-off), so the top's height stays unseen in those cells.
    assert errors["free_precision"] >= 0.99


def band_points_seen(office) -> np.ndarray:
    """(x, y) in the world of the true points of the scans in the robot's band."""
    out = []
    for ideal in office:
        pose = ideal.frame_poses[ideal.scan.frame_index]
        world = np.einsum("nij,nj->ni", pose[:, :3, :3], ideal.true_points) + pose[:, :3, 3]
        out.append(world[(world[:, 2] > 0.05) & (world[:, 2] < 1.0), :2])
    return np.vstack(out)


def free_cells(office, mapped) -> tuple[np.ndarray, np.ndarray]:
    """The snapshot's FREE cells: their centres (x, y) in the map and in the world."""
    mapper, _ = mapped
    world_from_map = map_to_world(mapper.trajectory().poses, true_starts(office))
    seg = mapper.obstacles.snapshot.segmentation
    rows, cols = np.nonzero(seg.state == FREE)
    xy = np.column_stack([seg.origin[0] + (cols + 0.5) * seg.resolution,
                          seg.origin[1] + (rows + 0.5) * seg.resolution])
    return xy, transform_points(world_from_map, np.column_stack([xy, np.zeros(len(xy))]))[:, :2]


def test_obstacle_distances_agree_with_the_scene(office, mapped):
    """nearest() at free cells against the exact distance to the scene's objects, where
    the scans saw that nearest object (six scans leave faces unseen, and an unseen face
    is unknown space, not an obstacle: the clearance covers it)."""
    mapper, _ = mapped
    xy, world = free_cells(office, mapped)
    pick = np.random.default_rng(0).choice(len(xy), 300, replace=False)
    xy, world = xy[pick], world[pick]
    truth = footprint_distance(builtin_scene("office"), world)
    answers = [mapper.obstacles.nearest(*p) for p in xy]
    measured = np.array([a.distance for a in answers])
    seen, _ = cKDTree(band_points_seen(office)).query(world)
    near = (truth < 2.0) & (seen <= truth + 0.01)  # the snapshot's window; seen nearest
    assert near.sum() > 200
    assert np.percentile(np.abs(measured - truth)[near], 95) < 0.03
    assert all(a.status in (QueryStatus.OK, QueryStatus.UNKNOWN) for a in answers)


def test_known_free_space_never_reaches_past_an_obstacle(office, mapped):
    """At every FREE cell, not a draw of them (a draw of 300 missed 4 under the table top's
    west end, 23 cm inside its edge, where rays passed only under the top, seen at its
    other end only: FREE while an overhanging board was carried 0.6 m from where it was
    seen, FloorConfig.overhang_reach, now 1 m)."""
    mapper, _ = mapped
    xy, world = free_cells(office, mapped)
    truth = footprint_distance(builtin_scene("office"), world)
    clearance = np.array([mapper.obstacles.nearest(*p).clearance for p in xy])
    assert (clearance <= truth + 0.03).all()


def test_rays_are_fused_from_each_frame_pose_when_the_robot_drives():
    """A robot driving 0.3 m/s during the 2 s scan: each frame is fused where it was seen."""
    scene = dataclasses.replace(builtin_scene("corridor"), motion=Motion(speed=0.3))
    ideal = next(ideal_scans(scene, seed=1, scans=1))
    start = ideal.pose_start
    poses = frame_poses(ideal.scan, np.eye(4))
    assert poses.shape == (int(ideal.scan.frame_index.max()) + 1, 4, 4)
    points, _ = scan_rays(ideal.scan, reference_scanner(), poses)
    truth = np.empty_like(points)
    for frame, pose in enumerate(ideal.frame_poses):
        rows = ideal.scan.frame_index == frame
        truth[rows] = transform_points(np.linalg.inv(start) @ pose, ideal.true_points[rows])
    error = np.linalg.norm(points - truth, axis=1)
    assert np.median(error) < 0.01  # odometry noise and range noise only
    static, _ = scan_rays(ideal.scan, reference_scanner(), np.eye(4))
    assert np.median(np.linalg.norm(static - truth, axis=1)) > 0.1  # what one pose would do


def test_frame_poses_interpolate_the_odometry_motion():
    n = 5
    scan = Scan(points=np.ones((n, 3)), colors=np.zeros((n, 3), np.uint8),
                time=np.array([10.0, 10.5, 11.0, 11.5, 12.0]), heading=np.zeros(n),
                frame_index=np.arange(n), range_sigma=np.zeros(n), stamp=10.0,
                odom_start=se2_to_pose(1.0, 2.0, 0.5), odom_end=se2_to_pose(1.4, 2.0, 0.7))
    start = se2_to_pose(5.0, 0.0, 0.0)
    poses = frame_poses(scan, start)
    np.testing.assert_allclose(poses[0], start, atol=1e-12)
    end = start @ np.linalg.inv(scan.odom_start) @ scan.odom_end
    np.testing.assert_allclose(poses[-1], end, atol=1e-12)
    yaws = np.arctan2(poses[:, 1, 0], poses[:, 0, 0])
    np.testing.assert_allclose(yaws, np.linspace(0.0, 0.2, n), atol=1e-12)
    still = dataclasses.replace(scan, odom_end=scan.odom_start)
    np.testing.assert_array_equal(frame_poses(still, start), start)


def test_offline_queries_use_the_data_clock_and_live_ones_go_stale(office):
    live = Mapper(reference_scanner(), clock=lambda: 1e6)
    live.add(office[0].scan)
    assert live.obstacles.nearest(0.0, 0.0).status == QueryStatus.STALE
    offline = Mapper(reference_scanner(), offline=True)
    offline.add(office[0].scan)
    assert offline.obstacles.nearest(0.0, 0.0).status != QueryStatus.STALE


def test_the_latest_pose_is_that_of_the_map_the_queries_answer_from(office):
    """While a scan's map is being made the controller reads the pose of the scan before
    it, whose map the obstacle queries still answer from; once published, its own."""
    mapper = Mapper(reference_scanner(), offline=True)
    assert mapper.latest_pose is None
    mapper.add(office[0].scan)
    publish, seen = mapper.obstacles.update, []

    def update(*args, **kwargs):
        seen.append((mapper.latest_pose, len(mapper)))  # the new pose recorded by now
        return publish(*args, **kwargs)

    mapper.obstacles.update = update
    mapper.add(office[1].scan)
    poses = mapper.trajectory().poses
    assert seen[0][1] == 2 and np.array_equal(seen[0][0], poses[0])
    assert np.array_equal(mapper.latest_pose, poses[1])
    assert not np.allclose(poses[0][:2, 3], poses[1][:2, 3])  # the robot moved


def test_a_failed_registration_is_recorded_but_not_fused(office):
    mapper = Mapper(reference_scanner(), offline=True)
    mapper.add(office[0].scan)
    stamp = mapper.grid.stamp
    # A scan of the corridor claiming to be where the office scan was: no overlap.
    stranger = next(ideal_scans(builtin_scene("corridor"), scans=1)).scan
    stranger = dataclasses.replace(stranger, stamp=office[1].scan.stamp,
                                   time=stranger.time - stranger.stamp + office[1].scan.stamp,
                                   odom_start=office[0].scan.odom_start,
                                   odom_end=office[0].scan.odom_start)
    update = mapper.add(stranger)
    assert not update.registration.ok and not update.fused and update.insert is None
    assert mapper.grid.stamp == stamp
    assert mapper.statuses[-1] == update.registration.status.value
    empty = mapper.add(Scan.empty(index=9, stamp=stamp + 10))
    assert not empty.fused and len(mapper) == 3


def test_a_rolling_window_grid_follows_the_robot(office):
    config = MapperConfig(grid=GridConfig(window=6.4, extent=50.0))
    mapper = Mapper(reference_scanner(), config, offline=True)
    updates = mapper.map_scans(ideal.scan for ideal in office[:3])
    assert all(u.fused for u in updates)
    assert mapper.grid.tile_count <= 9  # a 6.4 m window of 3.2 m tiles


def test_save_and_load_keep_everything(mapped, tmp_path):
    mapper, _ = mapped
    path = tmp_path / "map.npz"
    mapper.save(path, segmentation=mapper.segment())
    again = Mapper.load(path, offline=True)
    assert again.config == mapper.config and again.model == mapper.model
    np.testing.assert_array_equal(again.trajectory().poses, mapper.trajectory().poses)
    np.testing.assert_array_equal(again.trajectory().times, mapper.trajectory().times)
    assert again.statuses == mapper.statuses and again.scan_indices == mapper.scan_indices
    saved, loaded = mapper.grid.state(), again.grid.state()
    for name, value in saved.items():
        np.testing.assert_array_equal(loaded[name], value, err_msg=name)
    for a, b in zip(mapper.kept_points(), again.kept_points(), strict=True):
        np.testing.assert_array_equal(a, b)
    for name in ("state", "floor_height"):  # where it stood too: the same floor and edges
        np.testing.assert_array_equal(getattr(again.segment(), name),
                                      getattr(mapper.segment(), name), err_msg=name)
    as_full_map = load_map(path)  # the file is also a map_io full map, with its layers
    assert as_full_map.layers["state"].shape == mapper.segment().shape


def test_a_loaded_map_resumes_where_it_stopped(office, tmp_path):
    whole = Mapper(reference_scanner(), offline=True)
    whole.map_scans(ideal.scan for ideal in office)
    first = Mapper(reference_scanner(), offline=True)
    first.map_scans(ideal.scan for ideal in office[:3])
    first.save(tmp_path / "map.npz")
    resumed = Mapper.load(tmp_path / "map.npz", offline=True)
    updates = resumed.map_scans(ideal.scan for ideal in office[3:])
    assert [u.registration.status.value for u in updates] == ["ok"] * (OFFICE_SCANS - 3)
    difference = resumed.trajectory().positions - whole.trajectory().positions
    assert np.abs(difference).max() < 0.01
    assert len(resumed) == OFFICE_SCANS


def test_bad_map_files_raise_map_errors_naming_them(mapped, tmp_path):
    mapper, _ = mapped
    good = tmp_path / "good.npz"
    mapper.save(good)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(MapError, match=r"truncated\.npz"):
        Mapper.load(truncated)
    grid_only = tmp_path / "grid_only.npz"
    save_map(grid_only, mapper.grid)
    with pytest.raises(MapError, match="mapper_format"):
        Mapper.load(grid_only)
    with zipfile.ZipFile(good) as archive:
        arrays = {name[:-4]: np.load(archive.open(name)) for name in archive.namelist()}
    for change, message in ((("mapper_format", np.array("other/1")), "mapper_format"),
                            (("trajectory_poses", np.zeros((2, 4, 4))), "trajectory_poses"),
                            (("mapper_config", np.array("{not json")), "mapper_config")):
        broken = tmp_path / f"broken_{change[0]}.npz"
        np.savez(broken, **(arrays | dict([change])))
        with pytest.raises(MapError, match=message):
            Mapper.load(broken)


def test_a_map_from_another_version_drops_unknown_tuning_but_not_grid_layout(mapped,
                                                                             tmp_path):
    mapper, _ = mapped
    good = tmp_path / "good.npz"
    mapper.save(good)
    with zipfile.ZipFile(good) as archive:
        arrays = {name[:-4]: np.load(archive.open(name)) for name in archive.namelist()}
    config = json.loads(str(arrays["mapper_config"]))
    config["floor"]["retired_setting"] = 1.0
    newer = tmp_path / "newer.npz"
    np.savez(newer, **(arrays | {"mapper_config": np.array(json.dumps(config))}))
    with pytest.warns(UserWarning, match="retired_setting"):
        assert len(Mapper.load(newer)) == len(mapper)
    config["grid"]["tile_shape"] = "hexagonal"
    layout = tmp_path / "layout.npz"
    np.savez(layout, **(arrays | {"mapper_config": np.array(json.dumps(config))}))
    with pytest.raises(MapError, match="tile_shape"):
        Mapper.load(layout)


@pytest.mark.parametrize("name", ["laser_rays", "swept"])
def test_the_lasers_rays_are_a_setting_read_from_toml_and_checked(tmp_path, name):
    """`laser_rays` and `swept` (on by default): the Mapper clears along the laser's rays
    too, and misses what its plane swept unlit; a TOML file may turn either off, and
    anything but true or false is refused by name."""
    assert getattr(MapperConfig(), name) is True
    path = tmp_path / "mapper.toml"
    path.write_text(f"{name} = false\n")
    config = MapperConfig.load(path)
    assert getattr(config, name) is False
    path.write_text(config.to_toml())
    assert MapperConfig.load(path) == config
    with pytest.raises(MapError, match=name):
        MapperConfig(**{name: 1})


@pytest.mark.parametrize("swept", [True, False])
def test_the_mapper_fuses_with_the_lasers_rays_as_configured(swept):
    """The people corridor's first scans fused by the Mapper at the true poses, with and
    without the laser's rays (and its swept frames, or not): each grid is the one
    `HeightGrid.insert` builds given the laser's emitters or not, and the two differ (the
    laser's rays clear more)."""
    from scanmap.grid.height_grid import HeightGrid
    from scanmap.grid.rays import laser_origins
    from scanmap.grid.swept import swept_frames
    from scanmap.grid.unlit import unlit_floor

    model = reference_scanner()
    ideal = list(ideal_scans(builtin_scene("people"), model, scans=6))
    grids = {}
    for laser_rays in (True, False):
        config = MapperConfig(laser_rays=laser_rays, swept=swept, update_obstacles=False)
        mapper = Mapper(model, config, offline=True, initial_pose=ideal[0].pose_start)
        reference = HeightGrid(config.grid)
        for step in ideal:
            poses = frame_poses(step.scan, step.pose_start)
            mapper._fuse(step.scan, step.pose_start)
            points, origins = scan_rays(step.scan, model, poses)
            lasers = laser_origins(step.scan, model, poses) if laser_rays else None
            reference.insert(points, origins, float(step.scan.time.max()),
                             stood=poses[..., :2, 3].reshape(-1, 2),
                             unlit=unlit_floor(step.scan, model, poses), lasers=lasers,
                             swept=swept_frames(step.scan, model, poses) if swept else None)
        ours, theirs = mapper.grid.layers(), reference.layers()
        for name in ("levels", "counts", "nlev", "seen"):
            np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name))
        grids[laser_rays] = ours
    assert grids[True].counts[..., 1].sum() > grids[False].counts[..., 1].sum()  # passes
