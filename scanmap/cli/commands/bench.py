"""`scanmap bench [--quick]`: run every benchmark of a source checkout (`python -m benchmarks`).

The benchmarks are not part of the installed package, so this command finds a checkout
(`--repo`, else the current directory, else the one an editable install points to) and
runs `python -m benchmarks` there with this interpreter, in a process of its own.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from urllib.parse import unquote, urlparse

from scanmap_driver import ScanmapError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `bench`."""
    parser = subparsers.add_parser(
        "bench", help="run every benchmark, peers beside ours (needs a source checkout)",
        description="Run `python -m benchmarks` in a source checkout: every benchmark, the "
                    "peer libraries in the same run, writing benchmarks/results/latest.json, "
                    "latest.md, latest.png and the README's table.")
    parser.add_argument("--quick", action="store_true", help="small inputs (under 3 minutes)")
    parser.add_argument("--only", nargs="+", metavar="TOPIC",
                        help="only these modules, e.g. triangulation grid")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help="results folder (default: the checkout's benchmarks/results)")
    parser.add_argument("--repo", type=Path, metavar="PATH",
                        help="the source checkout (default: the current directory, else the "
                             "checkout of an editable install)")
    parser.set_defaults(func=_bench)


def is_checkout(path: Path) -> bool:
    """Whether `path` holds the benchmarks package of a source checkout."""
    return (path / "benchmarks" / "__main__.py").is_file()


def editable_checkout() -> Path | None:
    """The folder scanmap is installed from in editable mode (pip's direct_url.json)."""
    for dist in metadata.distributions(name="scanmap"):  # a checkout's egg-info has none
        info = json.loads(dist.read_text("direct_url.json") or "{}")
        url = urlparse(info.get("url", ""))
        if info.get("dir_info", {}).get("editable") and url.scheme == "file":
            return Path(unquote(url.path))
    return None


def find_checkout(repo: Path | None) -> Path:
    """`repo`, the current directory or the editable install's folder, whichever is a
    checkout first; ScanmapError saying what to do if none is."""
    if repo is not None:
        if is_checkout(repo):
            return repo.resolve()
        raise ScanmapError(f"{repo} is not a scanmap source checkout (no "
                           "benchmarks/__main__.py there)")
    for candidate in (Path.cwd(), editable_checkout()):
        if candidate is not None and is_checkout(candidate):
            return candidate.resolve()
    raise ScanmapError(
        "the benchmarks are not part of the installed package and no source checkout was "
        "found (not in the current directory, and scanmap is not installed in editable "
        "mode). Clone the repository, set it up (`bash scripts/setup.sh`) and run "
        "`scanmap bench` inside it, or pass `--repo PATH`.")


def _bench(args: argparse.Namespace) -> int:
    repo = find_checkout(args.repo)
    command = [sys.executable, "-m", "benchmarks"]
    if args.quick:
        command.append("--quick")
    if args.only:
        command += ["--only", *args.only]
    if args.out is not None:
        command += ["--out", str(args.out.resolve())]
    print(f"scanmap bench: running {' '.join(command[1:])} in {repo}", flush=True)
    return subprocess.run(command, cwd=repo).returncode
