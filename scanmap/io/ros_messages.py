"""ROS messages of scanmap's data, and bag files that hold them (pure Python, `rosbags`).

`RosMessages` builds the messages of one typestore (ROS 2 Humble or ROS 1 Noetic) from
numpy arrays: PointCloud2 (x, y, z float32 and rgb packed in a float32 as RViz reads it:
0x00RRGGBB), TFMessage, Path, OccupancyGrid (row 0 at the origin, the lower-left corner
of cell [0, 0]; -1 unknown, 0..100), and LaserScan and Odometry for bags to map from.
`BagFile` writes them: a ROS 2 bag with MCAP storage (one `.mcap` file that Foxglove and
`ros2 bag` open) or a ROS 1 `.bag`; it is a context manager, so an exception or an
interrupt closes the file cleanly. Frames are REP-105's: `map`, `odom`, `base_link`, and
`scanner` (the scan's frame, fixed in `base_link`).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from types import TracebackType

import numpy as np

from scanmap_driver.errors import MapError
from scanmap_driver.files import publish
from scanmap_driver.transforms import rotation_to_quaternion, se2_to_pose

MAP, ODOM, BASE_LINK, SCANNER = "map", "odom", "base_link", "scanner"
FLOAT32 = 7  # sensor_msgs/PointField datatype
_TF_MESSAGE = "tf2_msgs/msg/TFMessage"
_TF_DEFINITION = "geometry_msgs/TransformStamped[] transforms"
LATCHED_TOPICS = ("/tf_static", "/map", "/costmap")  # transient local (ROS 2), latched (ROS 1)


def typestore_for(ros1: bool):
    """The typestore of ROS 1 Noetic or ROS 2 Humble, with tf2_msgs/TFMessage registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if _TF_MESSAGE not in store.types:
        store.register(get_types_from_msg(_TF_DEFINITION, _TF_MESSAGE))
    return store


def nanoseconds(seconds: float) -> int:
    """Seconds as integer nanoseconds (a bag's timestamps)."""
    return round(float(seconds) * 1e9)


def pack_rgb(colors: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 RGB as (N,) float32 whose bits are 0x00RRGGBB (PCL's / RViz's rgb)."""
    c = np.asarray(colors, dtype=np.uint32).reshape(-1, 3)
    return ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).view(np.float32)


def unpack_rgb(packed: np.ndarray) -> np.ndarray:
    """The inverse of `pack_rgb`: (N,) float32 to (N, 3) uint8 RGB."""
    bits = np.ascontiguousarray(packed, dtype=np.float32).view(np.uint32)
    return np.column_stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255]).astype(np.uint8)


class RosMessages:
    """Message builders for one typestore (`typestore_for`)."""

    def __init__(self, typestore) -> None:
        self.store = typestore
        self.types = typestore.types
        self.ros1 = "seq" in self.types["std_msgs/msg/Header"].__dataclass_fields__

    def time(self, seconds: float):
        """builtin_interfaces/Time of `seconds`."""
        ns = nanoseconds(seconds)
        return self.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

    def header(self, stamp: float, frame: str):
        """std_msgs/Header (ROS 1's seq is 0: a bag has no sequence)."""
        extra = {"seq": 0} if self.ros1 else {}
        return self.types["std_msgs/msg/Header"](stamp=self.time(stamp), frame_id=frame, **extra)

    def pose(self, pose: np.ndarray):
        """geometry_msgs/Pose of a 4x4 pose."""
        t = self.types
        q = rotation_to_quaternion(np.asarray(pose, dtype=np.float64)[:3, :3])
        x, y, z = np.asarray(pose, dtype=np.float64)[:3, 3]
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=t["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))

    def point_cloud(self, stamp: float, frame: str, points: np.ndarray,
                    colors: np.ndarray):
        """sensor_msgs/PointCloud2, one row: x, y, z, rgb as float32 (16 bytes a point)."""
        t = self.types
        points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        layout = np.dtype({"names": ["x", "y", "z", "rgb"], "formats": ["<f4"] * 4})
        rows = np.empty(len(points), layout)
        for axis, name in enumerate("xyz"):
            rows[name] = points[:, axis]
        rows["rgb"] = pack_rgb(colors)
        fields = [t["sensor_msgs/msg/PointField"](name=name, offset=layout.fields[name][1],
                                                  datatype=FLOAT32, count=1)
                  for name in layout.names]
        return t["sensor_msgs/msg/PointCloud2"](
            header=self.header(stamp, frame), height=1, width=len(points), fields=fields,
            is_bigendian=False, point_step=layout.itemsize,
            row_step=layout.itemsize * len(points), data=rows.view(np.uint8),
            is_dense=bool(np.isfinite(points).all()))

    def transform(self, stamp: float, parent: str, child: str, pose: np.ndarray):
        """geometry_msgs/TransformStamped: `child` in `parent` (4x4)."""
        t = self.types
        p = self.pose(pose)
        return t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent), child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=p.position.x, y=p.position.y,
                                                           z=p.position.z),
                rotation=p.orientation))

    def tf(self, transforms: list) -> object:
        """tf2_msgs/TFMessage of TransformStamped messages."""
        return self.types[_TF_MESSAGE](transforms=transforms)

    def path(self, stamps: np.ndarray, poses: np.ndarray, frame: str = MAP):
        """nav_msgs/Path: one PoseStamped per pose, stamped with the newest time."""
        stamped = [self.types["geometry_msgs/msg/PoseStamped"](
            header=self.header(s, frame), pose=self.pose(p))
            for s, p in zip(stamps, poses, strict=True)]
        last = float(stamps[-1]) if len(stamps) else 0.0
        return self.types["nav_msgs/msg/Path"](header=self.header(last, frame), poses=stamped)

    def occupancy_grid(self, stamp: float, values: np.ndarray, resolution: float,
                       origin: tuple[float, float], frame: str = MAP):
        """nav_msgs/OccupancyGrid of (ny, nx) int8 values (row = y, row 0 at `origin`)."""
        values = np.asarray(values)
        if values.ndim != 2 or values.dtype != np.int8 or ((values < -1) | (values > 100)).any():
            raise MapError(f"occupancy_grid: expected (ny, nx) int8 in -1..100, got "
                           f"{values.dtype} {values.shape}")
        t = self.types
        ny, nx = values.shape
        info = t["nav_msgs/msg/MapMetaData"](
            map_load_time=self.time(stamp), resolution=float(resolution), width=nx, height=ny,
            origin=self.pose(se2_to_pose(origin[0], origin[1], 0.0)))
        return t["nav_msgs/msg/OccupancyGrid"](header=self.header(stamp, frame), info=info,
                                               data=np.ascontiguousarray(values).reshape(-1))

    def laser_scan(self, stamp: float, frame: str, ranges: np.ndarray, angle_min: float,
                   angle_increment: float, range_min: float, range_max: float):
        """sensor_msgs/LaserScan of one sweep taken at once (no time between beams)."""
        ranges = np.asarray(ranges, dtype=np.float32)
        return self.types["sensor_msgs/msg/LaserScan"](
            header=self.header(stamp, frame), angle_min=float(angle_min),
            angle_max=float(angle_min + angle_increment * (len(ranges) - 1)),
            angle_increment=float(angle_increment), time_increment=0.0, scan_time=0.0,
            range_min=float(range_min), range_max=float(range_max), ranges=ranges,
            intensities=np.zeros(0, np.float32))

    def odometry(self, stamp: float, pose: np.ndarray):
        """nav_msgs/Odometry: base_link in odom, covariances zero (unknown), no twist."""
        t = self.types
        zero = np.zeros(36, np.float64)
        return t["nav_msgs/msg/Odometry"](
            header=self.header(stamp, ODOM), child_frame_id=BASE_LINK,
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(pose),
                                                           covariance=zero),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](
                    linear=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                covariance=zero))


class BagFile:
    """A bag being written: ROS 2 with MCAP storage (`path` a `.mcap` file) or ROS 1
    (`ros1`, a `.bag` file). A context manager; `write` adds topics as they come.

    Either bag is written by rosbags into a folder beside `path` (`NAME.writing`) and its
    file moved to `path` on `close`, so `path` only ever holds a finished bag; a writer
    killed before it closed leaves the folder, which the next bag of that name replaces.
    """

    def __init__(self, path: str | os.PathLike[str], *, ros1: bool = False) -> None:
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        self.path = Path(path)
        if self.path.exists():
            raise MapError(f"{self.path}: exists already; a bag is never overwritten")
        self.ros1 = ros1
        self.store = typestore_for(ros1)
        self.messages = RosMessages(self.store)
        self._folder = self.path.with_name(self.path.name + ".writing")
        if self._folder.exists():
            shutil.rmtree(self._folder)  # an earlier run's, killed before it closed
        if ros1:
            self._folder.mkdir()
            self._file = self._folder / self.path.name
            self._writer = Writer1(self._file)
        else:
            self._file = self._folder / f"{self._folder.name}.mcap"
            self._writer = Writer2(self._folder, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, object] = {}
        self.closed = False

    def write(self, topic: str, message: object, stamp: float) -> None:
        """Write `message` on `topic` with bag time `stamp` (s)."""
        msgtype = message.__msgtype__
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._connections[topic] = self._add_connection(topic, msgtype)
        data = (self.store.serialize_ros1 if self.ros1 else self.store.serialize_cdr)(
            message, msgtype)
        self._writer.write(connection, nanoseconds(stamp), data)

    def _add_connection(self, topic: str, msgtype: str) -> object:
        latched = topic in LATCHED_TOPICS
        if self.ros1:
            return self._writer.add_connection(topic, msgtype, typestore=self.store,
                                               latching=int(latched))
        from rosbags.interfaces import (
            Qos,
            QosDurability,
            QosHistory,
            QosLiveliness,
            QosReliability,
            QosTime,
        )

        never = QosTime(sec=0, nsec=0)
        qos = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
                  QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
                  never, never, QosLiveliness.AUTOMATIC, never, False)
        return self._writer.add_connection(topic, msgtype, typestore=self.store,
                                           offered_qos_profiles=[qos])

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self.closed:
            return
        self.closed = True
        self._writer.close()
        publish(self._file, self.path)
        shutil.rmtree(self._folder)

    def __enter__(self) -> BagFile:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

