"""`scanmap map INPUT --out DIR`: a recording, a folder of scans or a ROS bag to a map (see
`scanmap.pipelines.offline`, `scanmap.pipelines.ros_export.map_bag`)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scanmap.datasets.rosbag import is_bag
from scanmap.mapping import MapperConfig, MapUpdate
from scanmap.pipelines.offline import map_to_folder, offline_config, report_text
from scanmap.pipelines.resume import Resume, localisation_text
from scanmap.pipelines.ros_export import bag_report_text, map_bag
from scanmap.stage_clock import process_seconds
from scanmap_driver import ScannerModel
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import se2_to_pose


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `map`."""
    parser = subparsers.add_parser(
        "map", help="map a recording or a folder of processed scans",
        description="Register and fuse every scan of INPUT (a raw recording, or a folder of "
                    "scan_NNNN.npz) and write map.npz, map.yaml + map.pgm, trajectory.tum, "
                    "overhead.png, occupancy.png and report.json (timings, and errors "
                    "where INPUT has ground_truth/).")
    parser.add_argument("input", type=Path, metavar="INPUT",
                        help="recording folder or folder of processed scans")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR")
    parser.add_argument("--scanner", type=Path, default=None, metavar="FILE",
                        help="scanner model (default: the recording's own; the reference "
                             "scanner for scan files)")
    parser.add_argument("--workers", type=int, default=None,
                        help="threads assembling scans from video (default: one per CPU "
                             "this process may use)")
    parser.add_argument("--resume", type=Path, default=None, metavar="MAP",
                        help="continue this map.npz (a previous run's) with INPUT's scans")
    parser.add_argument("--localise", action="store_true",
                        help="with --resume: the robot may have been moved since the map was "
                             "saved; locate its scans in the map (by place, or near "
                             "--hint) before mapping on (needs a map saved with loop closure)")
    parser.add_argument("--hint", type=_pose_hint, default=None, metavar="X,Y,YAW",
                        help="with --resume: --localise near this pose in the map (m, m, deg; "
                             "within about 3 m and 45 deg); default: where the robot stopped")
    parser.add_argument("--loop-closure", action="store_true",
                        help="close loops (a pose graph behind the registration; the same "
                             "as loop_closure.enabled = true in --config)")
    parser.add_argument("--config", type=Path, default=None, metavar="FILE",
                        help="mapper configuration (TOML; `scanmap config --defaults` "
                             "prints every key)")
    parser.add_argument("--scan-topic", default="/scan", metavar="TOPIC",
                        help="when INPUT is a ROS 1 or 2 bag (.bag, .mcap, .db3 or a rosbag2 "
                             "folder): its LaserScan or PointCloud2 topic (default /scan)")
    parser.add_argument("--odom-topic", default=None, metavar="TOPIC",
                        help="the bag's nav_msgs/Odometry topic (the registration prior)")
    parser.set_defaults(func=_map)


def _pose_hint(text: str) -> np.ndarray:
    """X,Y,YAW (m, m, degrees) as a 4x4 pose."""
    try:
        x, y, yaw = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,YAW (m, m, deg), got {text!r}") from None
    if not np.isfinite([x, y, yaw]).all():
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return se2_to_pose(x, y, np.radians(yaw))


def _map(args: argparse.Namespace) -> int:
    if (args.localise or args.hint is not None) and args.resume is None:
        raise MapError("--localise and --hint locate the scans in a map given by --resume")
    resume = None if args.resume is None else Resume(
        args.resume, args.localise or args.hint is not None, args.hint)
    model = ScannerModel.load(args.scanner) if args.scanner else None
    loaded = MapperConfig.load(args.config) if args.config else None
    config = offline_config(loaded, loop_closure=args.loop_closure)
    with tqdm(unit="scan", desc="mapping", dynamic_ncols=True) as bar:

        def progress(done: int, total: int, update: MapUpdate) -> None:
            bar.total = total
            bar.set_postfix_str(f"scan {update.index}: {update.registration.status.value}",
                                refresh=False)
            bar.update(done - bar.n)

        if is_bag(args.input):
            report = map_bag(args.input, args.out, args.scan_topic, odom_topic=args.odom_topic,
                             config=loaded, progress=progress, resume=resume,
                             loop_closure=args.loop_closure)
        else:
            report = map_to_folder(args.input, args.out, model=model, workers=args.workers,
                                   config=config, progress=progress, resume=resume)
    print(bag_report_text(report) if is_bag(args.input) else report_text(report))
    if report["input"]["localised"]:
        print(localisation_text(report["input"]["localised"]))
    print(f"wrote {args.out}")
    command = process_seconds()
    recorded = report["mapping"]["recorded_seconds"]
    speed = f", {recorded / command:.1f}x faster than recording" if recorded else ""
    print(f"the command took {command:.2f} s from start to exit (start-up and imports "
          f"included){speed}")
    return 0
