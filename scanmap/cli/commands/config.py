"""`scanmap config --defaults`: every mapper setting with its default, as a TOML file that
`scanmap map --config` reads (see `scanmap.mapping.config`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from scanmap.mapping import MapperConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `config`."""
    parser = subparsers.add_parser(
        "config", help="print the mapper configuration (defaults, or a file's)",
        description="Print the mapper configuration as TOML: the defaults (--defaults), or "
                    "FILE with every key it leaves out filled in. Edit it and pass it to "
                    "`scanmap map --config`.")
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--defaults", action="store_true", help="print the defaults")
    group.add_argument("file", nargs="?", type=Path, metavar="FILE",
                       help="a configuration file to check and print in full")
    parser.set_defaults(func=_config)


def _config(args: argparse.Namespace) -> int:
    config = MapperConfig() if args.defaults else MapperConfig.load(args.file)
    print(config.to_toml(), end="")
    return 0
