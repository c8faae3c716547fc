"""ROS bags out and in: a mapping run as ROS messages (`BagWriter`, live or from a map
folder, `export_map_folder`), and a bag of scans mapped into a map folder (`map_bag`).

Topics of a written bag (REP-103/105 frames, stamps the scans' own):

    /scanmap/points  sensor_msgs/PointCloud2  each scan's points and colours in `scanner`
    /tf              tf2_msgs/TFMessage  map -> odom and odom -> base_link at each scan
                     (odom is the scan's odometry; the identity when it has none)
    /tf_static       base_link -> scanner: the identity (scan points are in base_link,
                     whose origin is on the floor under the scanner's axis)
    /path            nav_msgs/Path  the trajectory, written by `finish`
    /map             nav_msgs/OccupancyGrid  the final map (`occupancy_grid`)
    /costmap         the Nav2 costmap (`inflate`), valued as Nav2 publishes it
    /scanmap/map_points  the map's kept points in `map` (exports of a map folder)
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import numpy as np

from scanmap.datasets.rosbag import BagScans
from scanmap.grid.height_grid import HeightGrid
from scanmap.io.ros_messages import BASE_LINK, MAP, ODOM, SCANNER, BagFile
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper, MapUpdate
from scanmap.mapping.state_file import load_state
from scanmap.navigation.costmap import costmap_to_occupancy, inflate, occupancy_grid
from scanmap.navigation.floor import Segmentation, segment
from scanmap.pipelines.carmen_map import LASER_2D
from scanmap.pipelines.offline import (
    REPORT_FORMAT,
    loop_summary,
    loop_text,
    offline_config,
    write_products,
)
from scanmap.pipelines.resume import Resume, add_located, localisation_summary
from scanmap.registration import RegistrationConfig
from scanmap_driver.errors import RecordingError
from scanmap_driver.files import write_json
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose

POINTS_TOPIC = "/scanmap/points"
MAP_POINTS_TOPIC = "/scanmap/map_points"


def map_segmentation(grid: HeightGrid, config: MapperConfig) -> Segmentation:
    """The map's floor and obstacle layers; a map whose floor is never seen (a 2-D laser,
    `FloorConfig.detect` false) has it assumed at z = 0, as for CARMEN logs."""
    return segment(grid.layers(), config.robot, config.floor,
                   fallback_floor=None if config.floor.detect else 0.0)


class BagWriter:
    """A mapping run written as ROS messages (see the module docstring), scan by scan.

    A context manager: leaving it (also by an exception or KeyboardInterrupt) closes the
    bag, which then holds every message written so far. ros1: a ROS 1 `.bag` instead of
    a ROS 2 MCAP file.
    """

    def __init__(self, path: str | os.PathLike[str], *, ros1: bool = False) -> None:
        self.bag = BagFile(path, ros1=ros1)
        self.messages = self.bag.messages
        self.stamps: list[float] = []
        self.poses: list[np.ndarray] = []

    def add_pose(self, stamp: float, pose: np.ndarray, odom: np.ndarray | None = None) -> None:
        """/tf at `stamp`: base_link at `pose` in map, at `odom` in odom (None: identity)."""
        m = self.messages
        if not self.stamps:
            self.bag.write("/tf_static", m.tf([m.transform(stamp, BASE_LINK, SCANNER,
                                                           np.eye(4))]), stamp)
        odom = np.eye(4) if odom is None else odom
        self.bag.write("/tf", m.tf([m.transform(stamp, MAP, ODOM, pose @ invert_pose(odom)),
                                    m.transform(stamp, ODOM, BASE_LINK, odom)]), stamp)
        self.stamps.append(float(stamp))
        self.poses.append(np.asarray(pose, dtype=np.float64))

    def add(self, scan: Scan, pose: np.ndarray) -> None:
        """One scan and base_link's pose in map at its start (`MapUpdate.pose`)."""
        self.add_pose(scan.stamp, pose, scan.odom_start if scan.has_odometry else None)
        self.bag.write(POINTS_TOPIC, self.messages.point_cloud(scan.stamp, SCANNER,
                                                               scan.points, scan.colors),
                       scan.stamp)

    def add_update(self, scan: Scan, update: MapUpdate) -> None:
        """What `Mapper.add(scan)` returned, with the scan: call after each scan."""
        self.add(scan, update.pose)

    def finish(self, seg: Segmentation, stamp: float | None = None) -> None:
        """/path, /map and /costmap at `stamp` (default: the newest scan's)."""
        m = self.messages
        stamp = (self.stamps[-1] if self.stamps else 0.0) if stamp is None else stamp
        if self.stamps:
            self.bag.write("/path", m.path(np.array(self.stamps), np.array(self.poses)), stamp)
        for topic, values in (("/map", occupancy_grid(seg)),
                              ("/costmap", costmap_to_occupancy(inflate(seg)))):
            self.bag.write(topic, m.occupancy_grid(stamp, values, seg.resolution, seg.origin),
                           stamp)

    def close(self) -> None:
        """Close the bag (idempotent)."""
        self.bag.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()


def export_map_folder(map_dir: str | os.PathLike[str], out: str | os.PathLike[str], *,
                      scans: str | os.PathLike[str] | None = None, ros1: bool = False) -> dict:
    """Write the run of a `scanmap map` folder as a bag; returns a summary.

    A map folder keeps no per-scan points: `scans` (a folder of scan_NNNN.npz, matched by
    scan index) adds each scan's cloud; without it the bag has the map's kept points.
    """
    map_dir = Path(map_dir)
    state = load_state(map_dir / "map.npz")
    files = {} if scans is None else {Scan.load(f).index: f
                                      for f in sorted(Path(scans).glob("scan_*.npz"))}
    if scans is not None and not files:
        raise RecordingError(f"{scans}: no scan_NNNN.npz files")
    start = time.perf_counter()
    clouds = 0
    with BagWriter(out, ros1=ros1) as writer:
        for stamp, pose, index, odom in zip(state.stamps, state.poses, state.index,
                                            state.odometry, strict=True):
            if int(index) in files:
                writer.add(Scan.load(files[int(index)]), pose)
                clouds += 1
            else:
                writer.add_pose(stamp, pose, odom if np.isfinite(odom).all() else None)
        last = float(state.stamps[-1]) if len(state.stamps) else 0.0
        if len(state.points):
            writer.bag.write(MAP_POINTS_TOPIC, writer.messages.point_cloud(
                last, MAP, state.points, state.point_colors), last)
        writer.finish(map_segmentation(state.grid, state.config), last)
    return {"scans": len(state.stamps), "clouds": clouds, "bytes": Path(out).stat().st_size,
            "seconds": time.perf_counter() - start}


def bag_config(scans: BagScans, config: MapperConfig | None = None,
               loop_closure: bool = False) -> MapperConfig:
    """The offline mapper settings for a bag's scans: `config` if given, else the
    defaults, with the 2-D laser settings (`RegistrationConfig.for_2d_scans`, no floor
    detection) for LaserScans; `loop_closure` switches loop closure on."""
    if config is None and scans.laser_2d:
        config = MapperConfig(registration=RegistrationConfig.for_2d_scans(), floor=LASER_2D)
    return offline_config(config, loop_closure=loop_closure)


def map_bag(bag: str | os.PathLike[str], out: str | os.PathLike[str], scan_topic: str, *,
            odom_topic: str | None = None, config: MapperConfig | None = None,
            progress: Callable[[int, int, MapUpdate], None] | None = None,
            resume: Resume | str | os.PathLike[str] | None = None,
            loop_closure: bool = False) -> dict:
    """Map the scans of a bag's `scan_topic` into the folder `out` (the products of
    `scanmap map`, `write_products`); returns the report (also out/report.json). resume:
    as for `map_to_folder`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    start, start_cpu = time.perf_counter(), time.process_time()
    scans = BagScans(bag, scan_topic, odom_topic)
    config = bag_config(scans, config, loop_closure)
    resume = Resume.of(resume)
    mapper = resume.mapper() if resume else Mapper(config=config, offline=True)
    outcome: Counter[str] = Counter()
    stamps: list[float] = []
    notes: list[str] = []
    for done, scan in enumerate(scans, start=1):
        update = add_located(mapper, scan, notes)
        if update is None:
            continue
        stamps.append(scan.stamp)
        outcome.update({update.registration.status.value: 1, "fused": int(update.fused),
                        "degenerate": int(update.registration.degenerate)})
        if progress:
            progress(done, scans.count, update)
    localised = localisation_summary(mapper, notes)
    mapper.close_loops()  # nothing to do without loop closure
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    files = write_products(mapper, map_segmentation(mapper.grid, mapper.config), out)
    recorded = stamps[-1] - stamps[0] if len(stamps) > 1 else None
    report = {
        "format": REPORT_FORMAT,
        "input": {"path": str(scans.path), "kind": "bag", "topic": scan_topic,
                  "type": scans.msgtype, "odometry": odom_topic, "scans": len(stamps),
                  "resumed": None if resume is None else str(resume.path),
                  "localised": localised},
        "mapping": {"wall_seconds": wall, "seconds_per_scan": wall / max(len(stamps), 1),
                    "process_cpu_seconds": cpu, "recorded_seconds": recorded,
                    "speedup": recorded / wall if recorded else None, "workers": 1,
                    "cpus": os.cpu_count()},
        "stages": {},
        "registration": dict(sorted(outcome.items())),
        "loops": loop_summary(mapper),
        "notes": notes,
        "files": files,
        "errors": {"available": False, "reason": f"no ground truth in a bag ({scans.path})"},
    }
    write_json(out / "report.json", report)
    return report


def bag_report_text(report: dict) -> str:
    """Two lines for people: speed and registration of a bag mapped by `map_bag`."""
    m = report["mapping"]
    return (f"{report['input']['scans']} scans of {report['input']['topic']} mapped in "
            f"{m['wall_seconds']:.2f} s ({1e3 * m['seconds_per_scan']:.0f} ms per scan)\n"
            "registration: " + ", ".join(f"{k} {v}" for k, v in report["registration"].items())
            + (f"\n{loop_text(report['loops'])}" if report["loops"]["enabled"] else ""))
