"""`scanmap bench [--quick] [--only TOPIC ...]`: the speed-against-error report.

Runs the `benchmarks` package of a source checkout (`python -m benchmarks`), which writes
benchmarks/results/latest.json, latest.md and latest.png.
"""

from __future__ import annotations

import argparse

from scanmap_driver import ScanmapError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `bench`."""
    parser = subparsers.add_parser(
        "bench", help="run the speed-against-error benchmarks",
        description="Run every stage on simulated recordings and on the real data, beside "
                    "the peer libraries, and write benchmarks/results/.")
    parser.add_argument("--quick", action="store_true", help="small sizes (minutes, for CI)")
    parser.add_argument("--only", nargs="*", default=None, metavar="TOPIC",
                        help="topics, e.g. triangulation laser registration grid")
    parser.set_defaults(func=_bench)


def _bench(args: argparse.Namespace) -> int:
    try:
        from benchmarks.__main__ import main as run_benchmarks
    except ImportError:
        raise ScanmapError("scanmap bench runs the benchmarks of a source checkout: run it "
                           "from the repository root (the folder holding benchmarks/)") from None
    argv = (["--quick"] if args.quick else []) + (["--only", *args.only] if args.only else [])
    return run_benchmarks(argv)
