"""`scanmap map INPUT --out DIR`: a recording or a folder of scans to a map (see
`scanmap.pipelines.offline`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from scanmap.mapping import MapperConfig, MapUpdate
from scanmap.pipelines.offline import map_to_folder, offline_config, report_text
from scanmap.stage_clock import process_seconds
from scanmap_driver import ScannerModel


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
    parser.add_argument("--workers", type=int, default=2,
                        help="threads assembling scans from video (default 2)")
    parser.add_argument("--resume", type=Path, default=None, metavar="MAP",
                        help="continue this map.npz (a previous run's) with INPUT's scans")
    parser.add_argument("--config", type=Path, default=None, metavar="FILE",
                        help="mapper configuration (TOML; `scanmap config --defaults` "
                             "prints every key)")
    parser.set_defaults(func=_map)


def _map(args: argparse.Namespace) -> int:
    model = ScannerModel.load(args.scanner) if args.scanner else None
    config = offline_config(MapperConfig.load(args.config) if args.config else None)
    with tqdm(unit="scan", desc="mapping", dynamic_ncols=True) as bar:

        def progress(done: int, total: int, update: MapUpdate) -> None:
            bar.total = total
            bar.set_postfix_str(f"scan {update.index}: {update.registration.status.value}",
                                refresh=False)
            bar.update(done - bar.n)

        report = map_to_folder(args.input, args.out, model=model, workers=args.workers,
                               config=config, progress=progress, resume=args.resume)
    print(report_text(report))
    print(f"wrote {args.out}")
    command = process_seconds()
    recorded = report["mapping"]["recorded_seconds"]
    speed = f", {recorded / command:.1f}x faster than recording" if recorded else ""
    print(f"the command took {command:.2f} s from start to exit (start-up and imports "
          f"included){speed}")
    return 0
