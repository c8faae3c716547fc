"""The command line of a benchmark over the CARMEN logs (`--quick`, `--only LOG`)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable


def run_from_command_line(run: Callable[..., list[dict]], doc: str) -> None:
    """Parse the arguments, call `run(quick=, only=)` and print each row as JSON."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="freiburg-101 only")
    parser.add_argument("--only", help="only logs whose name contains this")
    args = parser.parse_args()
    for row in run(quick=args.quick, only=args.only):
        print(json.dumps(row, indent=1, default=str), flush=True)
