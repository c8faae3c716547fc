"""Bags in: a CARMEN-like log of a robot in a room, ray-cast here, written as a LaserScan bag
(ROS 2 MCAP, ROS 2 SQLite, ROS 1) and mapped from the bag, against the same scans mapped
directly; bad bags are named by topic and stamp."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from scanmap.cli import main
from scanmap.datasets.carmen import BeamLayout, carmen_scan_points, half_turn_layout
from scanmap.datasets.rosbag import BagScans, is_bag
from scanmap.io.map_files import load_ros_map
from scanmap.io.ros_messages import BagFile, RosMessages, typestore_for
from scanmap.io.trajectory import read_tum
from scanmap.mapping import Mapper, MapperConfig
from scanmap.navigation.costmap import occupancy_grid
from scanmap.pipelines.carmen_map import LASER_2D, carmen_segmentation
from scanmap.pipelines.offline import offline_config
from scanmap.registration import RegistrationConfig
from scanmap_driver.errors import RecordingError
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose, se2_to_pose

MAX_RANGE = 12.0
LAYOUT = half_turn_layout(181)  # -90..90 deg, 1 deg
# The same beams as a LaserScan carries them (angle_min, angle_increment are float32).
MESSAGE_LAYOUT = BeamLayout(LAYOUT.count, float(np.float32(LAYOUT.first)),
                            float(np.float32(LAYOUT.step)), "float32")
# The room's walls and a pillar, as segments (x0, y0, x1, y1).
WALLS = np.array([[0, 0, 8, 0], [8, 0, 8, 5], [8, 5, 0, 5], [0, 5, 0, 0],
                  [3, 2, 3.6, 2], [3.6, 2, 3.6, 2.6], [3.6, 2.6, 3, 2.6], [3, 2.6, 3, 2],
                  [7.1, 3.9, 7.6, 4.6]], float)


def ray_cast(x: float, y: float, theta: float) -> np.ndarray:
    """Ranges of a CARMEN laser (LAYOUT) at (x, y, theta): nearest wall hit, MAX_RANGE
    where none."""
    angles = theta + LAYOUT.angles
    d = np.column_stack([np.cos(angles), np.sin(angles)])[:, None, :]
    a, b = WALLS[None, :, :2], WALLS[None, :, 2:]
    e = b - a
    w = a - np.array([x, y])
    cross = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / cross
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / cross
    hit = (np.abs(cross) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    return np.minimum(np.where(hit, t, np.inf).min(axis=1), MAX_RANGE)


def room_log(count: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, poses (x, y, theta), ranges) of a robot driving around the pillar."""
    s = np.linspace(0.0, 1.6 * math.pi, count)
    poses = np.column_stack([4.3 + 2.5 * np.cos(s), 2.5 + 1.4 * np.sin(s), s + math.pi / 2])
    times = 1000.0 + 0.5 * np.arange(count)
    return times, poses, np.array([ray_cast(*p) for p in poses], np.float32)


def write_laser_bag(path: Path, *, ros1: bool = False, stamps: np.ndarray | None = None,
                    ranges: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The room log as /scan (LaserScan in `laser`) and /odom (Odometry) messages,
    recorded at the log's times and stamped `stamps` (default: the same)."""
    times, poses, log_ranges = room_log()
    stamps = times if stamps is None else stamps
    ranges = log_ranges if ranges is None else ranges
    with BagFile(path, ros1=ros1) as bag:
        m = bag.messages
        for recorded, stamp, pose, r in zip(times, stamps, poses, ranges, strict=True):
            bag.write("/odom", m.odometry(stamp, se2_to_pose(*pose)), recorded)
            bag.write("/scan", m.laser_scan(stamp, "laser", r, LAYOUT.first, LAYOUT.step, 0.1,
                                            MAX_RANGE), recorded)
    return times, poses, log_ranges


def direct_scans() -> list[Scan]:
    """The room log's scans made as for CARMEN logs (at float32 beam angles), no bag."""
    times, poses, ranges = room_log()
    scans = []
    for i, (t, pose, r) in enumerate(zip(times, poses, ranges, strict=True)):
        points = carmen_scan_points(r, MESSAGE_LAYOUT, height=0.3, max_range=MAX_RANGE)
        n = len(points)
        odom = se2_to_pose(*pose)
        scans.append(Scan(points=points, colors=np.zeros((n, 3), np.uint8),
                          time=np.full(n, t), heading=np.zeros(n),
                          frame_index=np.zeros(n, np.int32), range_sigma=np.full(n, 0.01),
                          index=i, stamp=float(t), odom_start=odom, odom_end=odom))
    return scans


@pytest.fixture(scope="module")
def mcap_bag(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("bags") / "room.mcap"
    write_laser_bag(path)
    return path


@pytest.fixture(scope="module")
def mapped(mcap_bag: Path, tmp_path_factory) -> Path:
    """The map folder of `scanmap map room.mcap --scan-topic /scan --odom-topic /odom`."""
    out = tmp_path_factory.mktemp("map")
    assert main(["map", str(mcap_bag), "--out", str(out), "--scan-topic", "/scan",
                 "--odom-topic", "/odom"]) == 0
    return out


def test_bag_scans_are_the_carmen_scans(mcap_bag: Path, tmp_path: Path):
    ros1 = tmp_path / "room.bag"
    write_laser_bag(ros1, ros1=True)
    for path in (mcap_bag, ros1):
        assert is_bag(path)
        source = BagScans(path, "/scan", "/odom")
        assert source.laser_2d and source.count == len(direct_scans())
        for got, want in zip(source, direct_scans(), strict=True):
            assert got.stamp == pytest.approx(want.stamp, abs=1e-9)
            np.testing.assert_allclose(got.points, want.points, atol=1e-5)
            np.testing.assert_allclose(got.odom_start, want.odom_start, atol=1e-12)


def test_sqlite_bag_folder_reads_too(tmp_path: Path):
    from rosbags.rosbag2 import Writer

    store = typestore_for(False)
    m = RosMessages(store)
    times, _, ranges = room_log()
    folder = tmp_path / "room_sqlite"
    with Writer(folder, version=9) as writer:
        scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
        for t, r in zip(times[:5], ranges[:5], strict=True):
            msg = m.laser_scan(t, "laser", r, LAYOUT.first, LAYOUT.step, 0.1, MAX_RANGE)
            writer.write(scan, round(t * 1e9), store.serialize_cdr(msg, msg.__msgtype__))
    assert is_bag(folder) and not is_bag(tmp_path)
    scans = list(BagScans(folder, "/scan"))
    assert [s.stamp for s in scans] == pytest.approx(times[:5])
    assert not scans[0].has_odometry


def test_mapped_from_the_bag_as_from_the_scans(mapped: Path):
    config = offline_config(MapperConfig(registration=RegistrationConfig.for_2d_scans(),
                                         floor=LASER_2D))
    mapper = Mapper(config=config, offline=True)
    for scan in direct_scans():
        mapper.add(scan)
    direct = mapper.trajectory()
    from_bag = read_tum(mapped / "trajectory.tum")
    np.testing.assert_allclose(from_bag.times, direct.times, atol=1e-6)
    shift = np.linalg.norm(from_bag.positions - direct.positions, axis=1)
    assert shift.max() < 1e-6
    _, truth, _ = room_log()  # the map starts at the first pose
    relative = [invert_pose(se2_to_pose(*truth[0])) @ se2_to_pose(*p) for p in truth]
    assert np.linalg.norm(direct.positions - np.array(relative)[:, :3, 3], axis=1).max() < 0.1
    want = occupancy_grid(carmen_segmentation(mapper.grid))
    got = load_ros_map(mapped / "map.yaml")
    assert got.data.shape == want.shape
    kind = np.sign(want.astype(int))  # PGM keeps unknown / free / occupied
    assert (np.sign(got.data.astype(int)) == kind).mean() > 0.999
    assert (kind == 1).sum() > 100 and (kind == 0).sum() > 1000


@pytest.mark.parametrize("problem, message", [
    ("topic", "no topic /laser"),
    ("type", "topic /odom is nav_msgs/msg/Odometry"),
    ("order", "/scan message stamped 1000.500000000 s comes after one stamped 1001"),
    ("nan", "/scan scan stamped 1000.500000000 s has 1 NaN ranges"),
])
def test_bad_bags_are_named(tmp_path: Path, problem: str, message: str):
    times, _, ranges = room_log()
    stamps, ranges = times.copy(), ranges.copy()
    if problem == "order":
        stamps[[1, 2]] = stamps[[2, 1]]
    if problem == "nan":
        ranges[1, 7] = np.nan
    path = tmp_path / "bad.mcap"
    write_laser_bag(path, stamps=stamps, ranges=ranges)
    topic = {"topic": "/laser", "type": "/odom"}.get(problem, "/scan")
    with pytest.raises(RecordingError, match=message) as error:
        list(BagScans(path, topic))
    assert str(path) in str(error.value)
