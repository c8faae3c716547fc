"""Run every benchmark module and write results/latest.json, latest.md and latest.png.

Usage: python -m benchmarks [--quick] [--only TOPIC ...]
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import platform
import subprocess
import sys
import time
import traceback
from pathlib import Path

import benchmarks
from benchmarks.readme_table import update_readme
from benchmarks.report import markdown_table, speed_error_plot
from scanmap_driver.files import atomic_path, write_json

RESULTS = Path(__file__).resolve().parent / "results"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks; returns 1 if any module failed."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="small sizes, for CI")
    parser.add_argument("--only", nargs="*", default=None, help="topics, e.g. triangulation")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--replot", action="store_true",
                        help="only redraw latest.md, latest.png and the README table from "
                             "latest.json")
    args = parser.parse_args(argv)
    if args.replot:
        rows = json.loads((args.out / "latest.json").read_text())["rows"]
        write_table_and_plot(rows, args.out)
        if args.out == RESULTS:
            update_readme()
        return 0
    rows, failures = [], []
    for info in sorted(pkgutil.iter_modules(benchmarks.__path__), key=lambda m: m.name):
        if not info.name.startswith("bench_"):
            continue
        topic = info.name.removeprefix("bench_")
        if args.only is not None and topic not in args.only:
            continue
        print(f"== {topic}", flush=True)
        start = time.perf_counter()
        try:
            module = importlib.import_module(f"benchmarks.{info.name}")
            new_rows = module.run(quick=args.quick)
        except Exception:  # a failing module is reported, the others still run
            failures.append(topic)
            traceback.print_exc()
            continue
        for row in new_rows:
            row.setdefault("topic", topic)
        rows.extend(new_rows)
        print(markdown_table(new_rows))
        print(f"   ({time.perf_counter() - start:.1f} s)", flush=True)
    result = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "quick": args.quick,
              "commit": _commit(), "machine": _machine(), "only": args.only,
              "failed": failures, "rows": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "latest.json", result)
    write_table_and_plot(rows, args.out)
    if args.out == RESULTS and args.only is None:  # a whole run is what the README quotes
        update_readme()
    print(f"wrote {args.out}/latest.json, latest.md, latest.png")
    return 1 if failures else 0


def _commit() -> str:
    """The checkout's commit, marked `-dirty` with uncommitted changes."""
    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                                capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("-dirty" if dirty.strip() else "")


def _machine() -> dict:
    """Python, platform, CPU model and cores of this machine, and the CPU the kernels are
    compiled for (LLVM's name, as Numba targets it): machines that all call themselves
    "AMD EPYC" ran the vectorised laser kernels 3x apart (znver3, without AVX-512, in
    the run of 2026-11-27), which the model name alone does not tell."""
    from llvmlite import binding

    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"python": sys.version.split()[0], "platform": platform.platform(),
            "cpu_model": model, "cpu_target": binding.get_host_cpu_name(),
            "cores": os.cpu_count()}


def write_table_and_plot(rows: list[dict], out: Path) -> None:
    """latest.md (the table) and latest.png (speed against error) from the rows."""
    with atomic_path(out / "latest.md") as tmp:
        tmp.write_text(markdown_table(rows) + "\n")
    speed_error_plot(rows, out / "latest.png")


if __name__ == "__main__":
    sys.exit(main())
