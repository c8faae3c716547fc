"""Bags out: a map folder exported as ROS 2 (MCAP) and ROS 1 bags, read back with rosbags and
the mcap reader and checked against the message definitions, REP-103/105 and the folder's
own trajectory and map; the live BagWriter fed by a Mapper, and interrupted."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader

from scanmap.cli import main
from scanmap.datasets.rosbag import BagScans
from scanmap.io.map_files import load_ros_map
from scanmap.io.ros_messages import typestore_for
from scanmap.io.trajectory import read_tum
from scanmap.mapping import Mapper
from scanmap.pipelines.ros_export import BagWriter, bag_config, map_bag, map_segmentation
from scanmap_driver.transforms import make_pose, quaternion_to_rotation
from tests.scanmap.test_rosbag_input import direct_scans, write_laser_bag

TOPICS = {"/scanmap/points": "sensor_msgs/msg/PointCloud2", "/tf": "tf2_msgs/msg/TFMessage",
          "/tf_static": "tf2_msgs/msg/TFMessage", "/path": "nav_msgs/msg/Path",
          "/map": "nav_msgs/msg/OccupancyGrid", "/costmap": "nav_msgs/msg/OccupancyGrid"}


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, Path, list]:
    """(map folder, folder of its scans with colours, the scans)."""
    root = tmp_path_factory.mktemp("export")
    write_laser_bag(root / "room.mcap")
    map_bag(root / "room.mcap", root / "map", "/scan", odom_topic="/odom")
    rng = np.random.default_rng(4)
    scans = []
    (root / "scans").mkdir()
    for scan in direct_scans():
        colours = rng.integers(0, 256, (len(scan), 3), dtype=np.uint8)
        scan = type(scan)(**{**scan.__dict__, "colors": colours})
        scan.save(root / "scans" / f"scan_{scan.index:04d}.npz")
        scans.append(scan)
    return root / "map", root / "scans", scans


def read_bag(path: Path) -> dict[str, list[tuple[int, object]]]:
    """topic -> [(bag time ns, message)] read with rosbags; checks the message types."""
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for connection in reader.connections:
            assert TOPICS.get(connection.topic, connection.msgtype) == connection.msgtype
        for connection, t, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (t, reader.deserialize(raw, connection.msgtype)))
    return out


def seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def pose_of(transform) -> np.ndarray:
    q, p = transform.rotation, transform.translation
    return make_pose(quaternion_to_rotation(np.array([q.x, q.y, q.z, q.w])),
                     np.array([p.x, p.y, p.z]))


@pytest.mark.parametrize("ros", ["ros2", "ros1"])
def test_export_follows_the_message_definitions(run, tmp_path: Path, ros: str):
    map_dir, scans_dir, scans = run
    out = tmp_path / ("run.mcap" if ros == "ros2" else "run.bag")
    assert main(["export", "ros", str(map_dir), "--out", str(out), "--format", ros,
                 "--scans", str(scans_dir)]) == 0
    bag = read_bag(out)
    assert set(TOPICS) <= set(bag)
    point_field = typestore_for(ros == "ros1").types["sensor_msgs/msg/PointField"]
    trajectory = read_tum(map_dir / "trajectory.tum")

    clouds = bag["/scanmap/points"]
    assert len(clouds) == len(scans)
    for (t, cloud), scan in zip(clouds, scans, strict=True):
        assert cloud.header.frame_id == "scanner" and t == round(scan.stamp * 1e9)
        assert seconds(cloud.header.stamp) == pytest.approx(scan.stamp, abs=1e-9)
        assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == [
            ("x", 0, point_field.FLOAT32, 1), ("y", 4, point_field.FLOAT32, 1),
            ("z", 8, point_field.FLOAT32, 1), ("rgb", 12, point_field.FLOAT32, 1)]
        assert cloud.height == 1 and cloud.width == len(scan) and not cloud.is_bigendian
        assert cloud.point_step == 16 and cloud.row_step == 16 * len(scan)
        raw = np.asarray(cloud.data, np.uint8)
        assert raw.size == cloud.row_step * cloud.height
        words = raw.view("<u4").reshape(-1, 4)
        np.testing.assert_array_equal(words[:, :3].view("<f4"), scan.points)
        rgb = words[:, 3]  # 0x00RRGGBB, as PCL and RViz read it
        np.testing.assert_array_equal(np.column_stack([rgb >> 16, (rgb >> 8) & 255, rgb & 255]),
                                      scan.colors)

    (_, static), = bag["/tf_static"]
    (link,) = static.transforms
    assert (link.header.frame_id, link.child_frame_id) == ("base_link", "scanner")
    np.testing.assert_allclose(pose_of(link.transform), np.eye(4), atol=1e-12)
    tf = bag["/tf"]
    assert len(tf) == len(trajectory)
    for (_, message), stamp, pose, scan in zip(tf, trajectory.times, trajectory.poses, scans,
                                               strict=True):
        to_odom, to_base = message.transforms
        assert (to_odom.header.frame_id, to_odom.child_frame_id) == ("map", "odom")
        assert (to_base.header.frame_id, to_base.child_frame_id) == ("odom", "base_link")
        assert seconds(to_odom.header.stamp) == pytest.approx(stamp, abs=1e-6)
        np.testing.assert_allclose(pose_of(to_base.transform), scan.odom_start, atol=1e-9)
        np.testing.assert_allclose(pose_of(to_odom.transform) @ pose_of(to_base.transform),
                                   pose, atol=1e-6)

    (_, path), = bag["/path"]
    assert path.header.frame_id == "map" and len(path.poses) == len(trajectory)
    np.testing.assert_allclose([[p.pose.position.x, p.pose.position.y] for p in path.poses],
                               trajectory.positions[:, :2], atol=1e-6)

    saved = load_ros_map(map_dir / "map.yaml")  # row 0 at the lowest y, like OccupancyGrid
    (_, grid), = bag["/map"]
    (_, costmap), = bag["/costmap"]
    for message in (grid, costmap):
        info = message.info
        assert message.header.frame_id == "map"
        assert (info.height, info.width) == saved.data.shape
        assert info.resolution == pytest.approx(saved.resolution)
        assert (info.origin.position.x, info.origin.position.y) == pytest.approx(
            saved.origin[:2])
        assert info.origin.orientation.w == 1.0
    cells = np.asarray(grid.data, np.int8).reshape(grid.info.height, grid.info.width)
    assert ((cells == -1) | ((cells >= 0) & (cells <= 100))).all()
    np.testing.assert_array_equal(np.sign(cells), np.sign(saved.data))
    costs = np.asarray(costmap.data, np.int8).reshape(cells.shape)
    assert ((costs == -1) | ((costs >= 0) & (costs <= 100))).all()
    assert (costs[cells > 50] == 100).all()  # an obstacle is lethal: Nav2 publishes 100
    assert (costs[cells == 0] >= 0).all() and (costs == -1).sum() <= (cells == -1).sum()
    assert ((costs > 0) & (costs < 100) & (cells == 0)).any()  # inflation around obstacles


def test_mcap_file_has_ros2_schemas_and_cdr_channels(run, tmp_path: Path):
    from mcap.reader import make_reader

    map_dir, _, _ = run
    out = tmp_path / "run.mcap"
    assert main(["export", "ros", str(map_dir), "--out", str(out)]) == 0
    with open(out, "rb") as fh:
        summary = make_reader(fh).get_summary()
    schemas = {s.id: s for s in summary.schemas.values()}
    channels = {c.topic: c for c in summary.channels.values()}
    assert set(channels) == (set(TOPICS) - {"/scanmap/points"}) | {"/scanmap/map_points"}
    for topic, channel in channels.items():
        schema = schemas[channel.schema_id]
        assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert schema.name == TOPICS.get(topic, "sensor_msgs/msg/PointCloud2")
    assert "transient_local" in channels["/tf_static"].metadata["offered_qos_profiles"]
    assert summary.statistics.message_count == sum(summary.statistics.channel_message_counts
                                                   .values())


def test_live_writer_fed_by_the_mapper_and_interrupted(tmp_path: Path):
    write_laser_bag(tmp_path / "room.mcap")
    source = BagScans(tmp_path / "room.mcap", "/scan", "/odom")
    mapper = Mapper(config=bag_config(source), offline=True)
    with BagWriter(tmp_path / "live.mcap") as writer:
        for scan in source:
            writer.add_update(scan, mapper.add(scan))
        writer.finish(map_segmentation(mapper.grid, mapper.config))
    bag = read_bag(tmp_path / "live.mcap")
    assert len(bag["/scanmap/points"]) == source.count and "/map" in bag
    for (_, message), pose in zip(bag["/tf"], mapper.trajectory().poses, strict=True):
        to_odom, to_base = message.transforms
        np.testing.assert_allclose(pose_of(to_odom.transform) @ pose_of(to_base.transform),
                                   pose, atol=1e-6)

    with pytest.raises(KeyboardInterrupt), BagWriter(tmp_path / "cut.bag", ros1=True) as cut:
        for done, scan in enumerate(source, start=1):
            cut.add(scan, np.eye(4))
            if done == 5:
                raise KeyboardInterrupt
    assert len(read_bag(tmp_path / "cut.bag")["/scanmap/points"]) == 5
    assert not (tmp_path / "live.mcap.writing").exists()


KILLED_MIDWAY = """
import sys, time
import numpy as np
from scanmap.cli.commands.export import _sigterm_interrupts
from scanmap.datasets.rosbag import BagScans
from scanmap.pipelines.ros_export import BagWriter

with _sigterm_interrupts(), BagWriter(sys.argv[2], ros1=sys.argv[2].endswith(".bag")) as writer:
    for done, scan in enumerate(BagScans(sys.argv[1], "/scan"), start=1):
        writer.add(scan, np.eye(4))
        if done == 3:
            print("ready", flush=True)
        time.sleep(0.05 if done < 3 else 10)
"""


@pytest.mark.parametrize("name", ["cut.mcap", "cut.bag"])
@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_a_writer_stopped_midway_leaves_a_whole_bag_or_none(tmp_path: Path, name, how):
    """SIGTERM closes the bag with what was written; SIGKILL leaves no bag at all (never a
    torn one), and the next writer of that name starts afresh."""
    write_laser_bag(tmp_path / "room.mcap")
    child = subprocess.Popen([sys.executable, "-c", KILLED_MIDWAY, str(tmp_path / "room.mcap"),
                              str(tmp_path / name)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        child.send_signal(how)
        assert child.wait(timeout=30) != 0
    finally:
        child.kill()
        child.stdout.close()
    if how == signal.SIGTERM:
        assert len(read_bag(tmp_path / name)["/scanmap/points"]) == 3
        return
    assert not (tmp_path / name).exists() and (tmp_path / f"{name}.writing").exists()
    source = BagScans(tmp_path / "room.mcap", "/scan")
    with BagWriter(tmp_path / name, ros1=name.endswith(".bag")) as again:
        for scan in source:
            again.add(scan, np.eye(4))
    assert len(read_bag(tmp_path / name)["/scanmap/points"]) == source.count
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["room.mcap", name])
