"""`scanmap warm-up`: compile the Numba kernels into their on-disk cache now, so that the
first real run is as fast as the tenth (`scanmap.pipelines.warm_cache`)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `warm-up`."""
    parser = subparsers.add_parser(
        "warm-up", help="compile every kernel ahead of time (the set-up runs it)",
        description="Simulate a tiny recording and map it, so that Numba compiles every "
                    "kernel of the main job into its cache beside the sources. Run once "
                    "after installing or updating; later runs only load the cache.")
    parser.set_defaults(func=_warm_up)


def _warm_up(args: argparse.Namespace) -> int:
    from scanmap.pipelines.warm_cache import warm_kernels

    seconds = warm_kernels()
    print(f"scanmap: kernels compiled and cached in {seconds:.1f} s")
    return 0
