"""`scanmap carmen-map LOG --out DIR`: the occupancy map of a CARMEN log at its corrected poses.

Writes DIR/<name>.yaml + .pgm (ROS map_server) and DIR/<name>.png (the same pixels).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2

from scanmap.datasets.carmen import LASERS, read_carmen
from scanmap.grid.height_grid import GridConfig
from scanmap.io.map_files import read_pgm, save_ros_map
from scanmap.navigation.costmap import occupancy_grid
from scanmap.pipelines.carmen_map import (
    carmen_segmentation,
    fuse_carmen,
    occupied_cells_per_reading,
)
from scanmap.pipelines.offline import OBSTACLE_THRESH
from scanmap_driver.errors import MapError
from scanmap_driver.files import atomic_path


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `carmen-map`."""
    parser = subparsers.add_parser(
        "carmen-map", help="occupancy map of a CARMEN laser log (corrected poses)",
        description="Fuse every scan of one laser of a CARMEN log at its corrected pose into "
                    "the grid and write the occupancy map as ROS map_server YAML + PGM, and "
                    "PNG. Prints the beam layout used (and where it came from), what was "
                    "skipped, and the map's sharpness.")
    parser.add_argument("log", type=Path, metavar="LOG", help="CARMEN log (.log or .log.gz)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR")
    parser.add_argument("--resolution", type=float, default=0.05, help="cell size (m)")
    parser.add_argument("--height", type=float, default=0.3,
                        help="height (m) given to the laser and its points")
    parser.add_argument("--laser", default="front",
                        choices=LASERS,
                        help="which laser: front (FLASER, ROBOTLASER1), rear (RLASER, "
                             "ROBOTLASER2) or RAWLASERk (posed by the odometry)")
    parser.set_defaults(func=_carmen_map)


def _carmen_map(args: argparse.Namespace) -> int:
    log = read_carmen(args.log, laser=args.laser)
    print(f"beam layout: {log.layout}")
    for what, count in log.skipped.items():
        print(f"skipped: {count} {what}")
    print(f"sharpness: {occupied_cells_per_reading(log):.3f} occupied 0.1 m cells per reading")
    grid = fuse_carmen(log, GridConfig(resolution=args.resolution), height=args.height)
    seg = carmen_segmentation(grid)
    name = args.log.name.split(".")[0]
    pgm = save_ros_map(args.out / f"{name}.yaml", occupancy_grid(seg), seg.resolution,
                       seg.origin, occupied_thresh=OBSTACLE_THRESH)
    png = args.out / f"{name}.png"
    with atomic_path(png) as tmp:
        if not cv2.imwrite(str(tmp.with_suffix(".png")), read_pgm(pgm).astype("uint8")):
            raise MapError(f"{png}: OpenCV could not write the PNG")
        tmp.with_suffix(".png").replace(tmp)
    print(f"{len(log)} scans of {args.log}: {seg.shape[1]} x {seg.shape[0]} cells at "
          f"{seg.resolution} m; wrote {pgm.with_suffix('.yaml')}, {pgm} and {png}")
    return 0
