"""The CARMEN logs the benchmarks run on: every corrected log in ../shared/data/real/carmen.

A log is `NAME-corrected.log.gz` or `NAME-corrected.log` (its laser poses corrected by a
SLAM solution: the reference). The seven logs shared with the project come first, in the
order a benchmark lists them; any other log found there (one recorded by others, added
beside them) follows, sorted by name, so that it is measured too rather than ignored.
"""

from __future__ import annotations

from pathlib import Path

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "carmen"
SHARED_LOGS = ("intel", "aces", "acapulco", "belgioioso", "edmonton", "fhw", "freiburg-101")
SUFFIXES = ("-corrected.log.gz", "-corrected.log")


def carmen_path(name: str, folder: Path = REAL) -> Path:
    """The file of log `name` in `folder` (the compressed one when both exist); the
    compressed name when neither does, so that reading it reports the missing file."""
    for suffix in SUFFIXES:
        path = folder / f"{name}{suffix}"
        if path.is_file():
            return path
    return folder / f"{name}{SUFFIXES[0]}"


def carmen_logs(first: tuple[str, ...] = SHARED_LOGS, folder: Path = REAL) -> tuple[str, ...]:
    """Names of the corrected logs present in `folder`: those of `first` in its order,
    then the others, sorted (none when the folder is absent)."""
    present = set()
    if folder.is_dir():
        for path in folder.iterdir():
            for suffix in SUFFIXES:
                if path.name.endswith(suffix) and path.is_file():
                    present.add(path.name[:-len(suffix)])
    return (tuple(name for name in first if name in present)
            + tuple(sorted(present - set(first))))
