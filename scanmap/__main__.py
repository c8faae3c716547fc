"""`python -m scanmap` runs the command line."""

from scanmap.cli import run

run()
