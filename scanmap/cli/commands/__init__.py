"""Subcommands of `scanmap`: one module each, with `register(subparsers)`."""
