"""ROS 1 and ROS 2 bags (MCAP or SQLite storage) as scans, read with `rosbags` (no ROS).

A bag's scan topic holds `sensor_msgs/LaserScan` or `sensor_msgs/PointCloud2`; each
message becomes one `Scan` in `base_link` stamped with its header stamp. A LaserScan's
beams (angle_min + i * angle_increment) are kept where range_min <= r < range_max (a
reading at range_max is the laser's "no return", as in CARMEN logs; +-inf are no returns
too, REP-117) and lifted to `laser_height` (a 2-D laser sees no floor, like
`carmen_scan_points`); NaN ranges, which REP-117 reserves for erroneous readings, are an
error. A PointCloud2's x, y, z (and rgb) are read as they are, non-finite points dropped.
The message's frame is taken as `base_link`: no tf lookup.

With an odometry topic (`nav_msgs/Odometry`), each scan's `odom_start` and `odom_end`
are the newest odometry pose at or before its stamp (the registration prior); scans
before the first odometry message have none.

A bag the mapper cannot use raises RecordingError naming the bag, topic and stamp: a
missing topic, a message type other than those above, stamps going backwards, NaN ranges.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from scanmap.io.ros_messages import unpack_rgb
from scanmap_driver.errors import RecordingError
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import make_pose, quaternion_to_rotation

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
LASER_SCAN = "sensor_msgs/msg/LaserScan"
POINT_CLOUD = "sensor_msgs/msg/PointCloud2"
ODOMETRY = "nav_msgs/msg/Odometry"
LASER_HEIGHT = 0.3  # m above the floor given to a 2-D laser's points (as for CARMEN logs)
RANGE_SIGMA = 0.01  # m, the range noise given to a bag's points (a laser's typical 1 cm)
_NUMPY_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_NO_POSE = np.full((4, 4), np.nan)


def is_bag(path: str | os.PathLike[str]) -> bool:
    """A bag file (.bag, .mcap, .db3) or a rosbag2 folder (with metadata.yaml)."""
    path = Path(path)
    return (path.is_file() and path.suffix in BAG_SUFFIXES) or (path / "metadata.yaml").is_file()


class BagScans:
    """The scans of one topic of a bag, in order (see the module docstring); iterate it."""

    def __init__(self, path: str | os.PathLike[str], scan_topic: str,
                 odom_topic: str | None = None, laser_height: float = LASER_HEIGHT) -> None:
        from rosbags.highlevel import AnyReader, AnyReaderError

        self.path = Path(path)
        self.scan_topic = scan_topic
        self.laser_height = float(laser_height)
        self._errors = (AnyReaderError, *_reader_errors())
        if not self.path.exists():
            raise RecordingError(f"{self.path}: no such bag")
        try:
            self._reader = AnyReader([self.path])
        except self._errors as exc:
            raise RecordingError(f"{self.path}: not a readable bag ({exc})") from None
        with self._open():
            topics = {c.topic: c.msgtype for c in self._reader.connections}
            self.msgtype = self._topic_type(topics, scan_topic, (LASER_SCAN, POINT_CLOUD))
            self.count = sum(c.msgcount for c in self._reader.connections
                             if c.topic == scan_topic)
            self._odometry = (None if odom_topic is None else
                              self._read_odometry(odom_topic, topics))

    @property
    def laser_2d(self) -> bool:
        """True when the scans are LaserScans (a 2-D laser)."""
        return self.msgtype == LASER_SCAN

    @contextmanager
    def _open(self) -> Iterator[None]:
        """The reader opened (and closed after); its errors name the bag."""
        try:
            self._reader.open()
        except self._errors as exc:
            raise RecordingError(f"{self.path}: not a readable bag ({exc})") from None
        try:
            yield
        finally:
            self._reader.close()

    def _topic_type(self, topics: dict[str, str], topic: str, expected: tuple[str, ...]) -> str:
        if topic not in topics:
            raise RecordingError(f"{self.path}: no topic {topic} (topics: "
                                 f"{', '.join(sorted(topics)) or 'none'})")
        if topics[topic] not in expected:
            raise RecordingError(f"{self.path}: topic {topic} is {topics[topic]}, expected "
                                 f"{' or '.join(expected)}")
        return topics[topic]

    def _messages(self, topic: str) -> Iterator[tuple[float, object]]:
        """(header stamp in s, message) of `topic`, checked to go forwards in time."""
        connections = [c for c in self._reader.connections if c.topic == topic]
        previous = -np.inf
        for connection, _, raw in self._reader.messages(connections=connections):
            message = self._reader.deserialize(raw, connection.msgtype)
            stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            if stamp < previous:
                raise RecordingError(f"{self.path}: {topic} message stamped {stamp:.9f} s "
                                     f"comes after one stamped {previous:.9f} s")
            previous = stamp
            yield stamp, message

    def _read_odometry(self, topic: str, topics: dict[str, str]) -> tuple[np.ndarray,
                                                                         np.ndarray]:
        self._topic_type(topics, topic, (ODOMETRY,))
        stamps, poses = [], []
        for stamp, message in self._messages(topic):
            p, q = message.pose.pose.position, message.pose.pose.orientation
            stamps.append(stamp)
            poses.append(make_pose(quaternion_to_rotation(np.array([q.x, q.y, q.z, q.w])),
                                   np.array([p.x, p.y, p.z])))
        if not stamps:
            raise RecordingError(f"{self.path}: odometry topic {topic} has no messages")
        return np.array(stamps), np.array(poses)

    def _odometry_at(self, stamp: float) -> np.ndarray:
        if self._odometry is None:
            return _NO_POSE
        stamps, poses = self._odometry
        k = int(np.searchsorted(stamps, stamp, side="right")) - 1
        return poses[k] if k >= 0 else _NO_POSE

    def __iter__(self) -> Iterator[Scan]:
        with self._open():
            for index, (stamp, message) in enumerate(self._messages(self.scan_topic)):
                if self.laser_2d:
                    points, colors, times = self._laser_points(stamp, message)
                else:
                    points, colors = self._cloud_points(stamp, message)
                    times = np.full(len(points), stamp)
                odom = self._odometry_at(stamp)
                n = len(points)
                yield Scan(points=points, colors=colors, time=times, heading=np.zeros(n),
                           frame_index=np.zeros(n, np.int32),
                           range_sigma=np.full(n, RANGE_SIGMA), index=index, stamp=stamp,
                           odom_start=odom, odom_end=odom)

    def _laser_points(self, stamp: float, scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        bad = np.isnan(ranges)
        if bad.any():
            raise RecordingError(f"{self.path}: {self.scan_topic} scan stamped {stamp:.9f} s has "
                                 f"{int(bad.sum())} NaN ranges (first at beam "
                                 f"{int(np.argmax(bad))}); REP-117 marks them erroneous")
        beams = np.arange(ranges.size)
        angles = scan.angle_min + scan.angle_increment * beams
        keep = (ranges >= scan.range_min) & (ranges < scan.range_max)
        r, a = ranges[keep], angles[keep]
        points = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(r.size,
                                                                         self.laser_height)])
        times = stamp + scan.time_increment * beams[keep]
        return points, np.zeros((r.size, 3), np.uint8), times

    def _cloud_points(self, stamp: float, cloud) -> tuple[np.ndarray, np.ndarray]:
        fields = {f.name: f for f in cloud.fields}
        missing = [axis for axis in "xyz" if axis not in fields]
        if missing:
            raise RecordingError(f"{self.path}: {self.scan_topic} cloud stamped {stamp:.9f} s "
                                 f"has no field {', '.join(missing)}")
        names = [name for name in ("x", "y", "z", "rgb") if name in fields]
        order = ">" if cloud.is_bigendian else "<"
        layout = np.dtype({"names": names,
                           "formats": [order + _NUMPY_TYPES[fields[n].datatype] for n in names],
                           "offsets": [fields[n].offset for n in names],
                           "itemsize": cloud.point_step})
        data = np.frombuffer(np.asarray(cloud.data, np.uint8).tobytes(), np.uint8)
        rows = data.reshape(cloud.height, cloud.row_step)[:, :cloud.width * cloud.point_step]
        values = np.ascontiguousarray(rows).view(layout).reshape(-1)
        points = np.column_stack([values[axis].astype(np.float64) for axis in "xyz"])
        colors = (unpack_rgb(values["rgb"].astype(np.float32)) if "rgb" in names
                  else np.zeros((len(points), 3), np.uint8))
        keep = np.isfinite(points).all(axis=1)
        return points[keep], colors[keep]


def _reader_errors() -> tuple[type[Exception], ...]:
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    return Reader1Error, Reader2Error
