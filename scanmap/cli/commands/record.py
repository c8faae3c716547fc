"""`scanmap record`: keep raw recordings of scans (no processing on the robot).

    scanmap record --camera 0 --port /dev/ttyUSB0 --out DIR [--scans N] [--continuous]

The scanner turns and the encoder disk is decoded as in `scanmap scan` (to know when a
turn is complete and to bring the head back), but frames are not turned into points:
each scan's video keeps the webcam's JPEGs byte for byte, with frame times and the motor
log (`scanmap_driver.recording`). Process it later with `scanmap process DIR --out SCANS`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scanmap.cli.commands.scan import add_device_arguments, run_device


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `record`."""
    parser = subparsers.add_parser(
        "record", help="record raw scans (video, frame times, motor log) from the scanner",
        description="Drive the scanner and keep each scan as recorded, without processing; "
                    "process it later with `scanmap process`.")
    add_device_arguments(parser)
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="recording folder to write")
    parser.set_defaults(func=_record)


def _record(args: argparse.Namespace) -> int:
    args.record = args.out
    return run_device(args, process=False, on_scan=lambda result: None)
