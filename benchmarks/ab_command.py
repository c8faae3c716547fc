"""The whole `scanmap map` command of two source trees, run in turns: which is faster.

On a shared machine the same code takes 2.0 s in one minute and 3.5 s in the next, so
two sets of runs made one after the other compare the machine's moods, not the code.
Here each run of tree A is followed at once by a run of tree B (a new process each,
start to exit, as a user waits for it), and the pairs are compared: the median of each
side, the median difference, and in how many pairs B was faster.

    .venv/bin/python -m benchmarks.ab_command [--runs N] [--recording DIR] A B

A and B are source checkouts (folders holding `scanmap/`) or git revisions of this
repository, checked out for the run in temporary worktrees and removed after. Each
tree's bytecode is compiled first (where `PYTHONDONTWRITEBYTECODE` is set a tree
without it compiles its modules on every start: 0.28 s) and each tree maps the
recording once before the timed runs (a new worktree compiles its Numba kernels into
its own cache on its first run). The interpreter is this one, with each tree first on
`PYTHONPATH`.
"""

from __future__ import annotations

import argparse
import compileall
import json
import os
import resource
import statistics
import subprocess
import tempfile
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from benchmarks.bench_mapping import RECORDING, map_command

REPOSITORY = Path(__file__).resolve().parent.parent
PACKAGES = ("scanmap", "scanmap_driver")


@dataclass(frozen=True)
class Run:
    """One `scanmap map` process: wall and CPU (user + system) seconds from start to exit,
    and the job's and the loop's wall seconds from its report."""

    wall: float
    cpu: float
    job: float
    loop: float


def run_command(tree: Path, recording: Path, out: Path) -> Run:
    """`scanmap map RECORDING --out OUT` with `tree`'s sources, timed from start to exit."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tree), *filter(None, [os.environ.get("PYTHONPATH")])])}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(map_command(recording, out), cwd=tree, env=env, check=True,
                   capture_output=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = json.loads((out / "report.json").read_text())
    return Run(wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
               report["job"]["wall_seconds"], report["mapping"]["wall_seconds"])


def compare(a: list[Run], b: list[Run]) -> dict:
    """Medians of each side's runs and of the pairs' differences (A - B: positive when B is
    faster), and the pairs in which B was faster (its wall time below A's)."""
    if len(a) != len(b) or not a:
        raise ValueError(f"expected as many runs of A as of B (at least one), got {len(a)} "
                         f"and {len(b)}")
    summary = {}
    for field in ("wall", "cpu", "job", "loop"):
        summary[field] = {"a": statistics.median(getattr(r, field) for r in a),
                          "b": statistics.median(getattr(r, field) for r in b)}
    differences = [x.wall - y.wall for x, y in zip(a, b, strict=True)]
    summary["wall_difference"] = statistics.median(differences)
    summary["b_faster_pairs"] = sum(d > 0 for d in differences)
    summary["pairs"] = len(differences)
    return summary


def source_tree(spec: str, stack: ExitStack) -> Path:
    """The checkout `spec` names: a folder holding the packages, or else a git revision of
    this repository checked out in a temporary worktree that `stack` removes."""
    folder = Path(spec)
    if all((folder / package).is_dir() for package in PACKAGES):
        return folder.resolve()
    revision = subprocess.run(["git", "-C", str(REPOSITORY), "rev-parse", "--verify",
                               f"{spec}^{{commit}}"], capture_output=True, text=True)
    if revision.returncode:
        raise SystemExit(f"ab_command: {spec!r} is neither a checkout (a folder with "
                         f"{' and '.join(PACKAGES)}) nor a git revision of {REPOSITORY}")
    worktree = Path(stack.enter_context(tempfile.TemporaryDirectory())) / "tree"
    subprocess.run(["git", "-C", str(REPOSITORY), "worktree", "add", "--detach", "--quiet",
                    str(worktree), revision.stdout.strip()], check=True)
    stack.callback(subprocess.run, ["git", "-C", str(REPOSITORY), "worktree", "remove",
                                    "--force", str(worktree)], check=False)
    return worktree


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("a", help="tree A: a checkout's folder or a git revision")
    parser.add_argument("b", help="tree B: a checkout's folder or a git revision")
    parser.add_argument("--runs", type=int, default=10, help="pairs of runs (default 10)")
    parser.add_argument("--recording", type=Path, default=RECORDING,
                        help="the recording to map (default: the main job's corridor)")
    args = parser.parse_args(argv)
    recording = args.recording.resolve()
    if not (recording / "recording.json").is_file():
        parser.error(f"{recording}: no recording.json (run the main job, "
                     "examples/corridor_map.py, to simulate the corridor's)")
    if args.runs < 1:
        parser.error(f"--runs: expected at least 1, got {args.runs}")
    with ExitStack() as stack, tempfile.TemporaryDirectory() as scratch:
        trees = [source_tree(spec, stack) for spec in (args.a, args.b)]
        outs = [Path(scratch) / name for name in ("a", "b")]
        for tree, out in zip(trees, outs, strict=True):
            for package in PACKAGES:
                compileall.compile_dir(tree / package, quiet=1, workers=0)
            run_command(tree, recording, out)  # loads or fills the tree's kernel cache
        runs: list[list[Run]] = [[], []]
        for _ in range(args.runs):
            for side, tree, out in zip(runs, trees, outs, strict=True):
                side.append(run_command(tree, recording, out))
    summary = compare(*runs)
    for field in ("wall", "cpu", "job", "loop"):
        print(f"{field:5s} median  A {summary[field]['a']:.3f} s  B {summary[field]['b']:.3f} s")
    print(f"B faster in {summary['b_faster_pairs']} of {summary['pairs']} pairs, by a median "
          f"{summary['wall_difference']:.3f} s (A {args.a}, B {args.b})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
