"""`scanmap process RECORDING --out DIR`: raw recording to processed scans (.npz, .ply)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scanmap_driver import ScannerModel
from scanmap_driver.processing import process_recording


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `process`."""
    parser = subparsers.add_parser(
        "process", help="turn a raw recording into processed scans",
        description="Extract the laser stripe and heading of every frame, triangulate, and "
                    "write scan_NNNN.npz and scan_NNNN.ply per scan plus summary.json.")
    parser.add_argument("recording", type=Path, metavar="RECORDING", help="recording folder")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR")
    parser.add_argument("--scanner", type=Path, default=None, metavar="FILE",
                        help="scanner model to use instead of the recording's own "
                             "(e.g. a new calibration)")
    parser.add_argument("--no-ply", action="store_true", help="skip the .ply files")
    parser.set_defaults(func=_process)


def _process(args: argparse.Namespace) -> int:
    model = ScannerModel.load(args.scanner) if args.scanner else None
    summaries = process_recording(args.recording, args.out, model=model, ply=not args.no_ply,
                                  progress=print)
    incomplete = [s["index"] for s in summaries if not s["complete"]]
    print(f"wrote {len(summaries)} scans to {args.out}"
          + (f"; incomplete scans: {incomplete}" if incomplete else ""))
    return 0
