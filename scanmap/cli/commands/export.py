"""`scanmap export ros MAP_DIR --out run.mcap`: a map folder as a ROS 2 (MCAP) or ROS 1 bag
(see `scanmap.pipelines.ros_export`). SIGTERM, like Ctrl-C, stops the export with the bag
closed cleanly, holding what was written."""

from __future__ import annotations

import argparse
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from scanmap.pipelines.ros_export import export_map_folder


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `export`."""
    parser = subparsers.add_parser("export", help="export a map folder for other tools")
    kinds = parser.add_subparsers(dest="kind", metavar="KIND", required=True)
    ros = kinds.add_parser(
        "ros", help="a ROS 2 bag (MCAP) or ROS 1 bag for Foxglove, RViz, ros2 bag play",
        description="Write the run of a `scanmap map` folder as a bag: /tf and /tf_static "
                    "(map -> odom -> base_link -> scanner), /path, /map and /costmap "
                    "(OccupancyGrid), and a PointCloud2 per scan on /scanmap/points when "
                    "--scans gives the scan files (a map folder keeps only the map's points, "
                    "written on /scanmap/map_points).")
    ros.add_argument("map_dir", type=Path, metavar="MAP_DIR", help="output folder of scanmap map")
    ros.add_argument("--out", required=True, type=Path, metavar="FILE",
                     help="the bag to write (.mcap, or .bag with --format ros1)")
    ros.add_argument("--format", choices=("ros2", "ros1"), default="ros2",
                     help="ros2: MCAP storage (default); ros1: a .bag file")
    ros.add_argument("--scans", type=Path, default=None, metavar="DIR",
                     help="folder of the processed scans (scan_NNNN.npz) that were mapped")
    ros.set_defaults(func=_export_ros)


def _export_ros(args: argparse.Namespace) -> int:
    with _sigterm_interrupts():
        summary = export_map_folder(args.map_dir, args.out, scans=args.scans,
                                    ros1=args.format == "ros1")
    print(f"{summary['scans']} poses and {summary['clouds']} scan clouds in "
          f"{summary['seconds']:.2f} s; wrote {args.out} ({summary['bytes'] / 1e6:.2f} MB)")
    return 0


@contextmanager
def _sigterm_interrupts() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt (as SIGINT does), so open bags are closed."""
    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
