"""The README's benchmark table, generated from `results/latest.json`.

The table between the markers below in README.md is never edited by hand: the benchmark
run rewrites it (`python -m benchmarks` does, or `python -m benchmarks.readme_table`
alone from the saved results), and a test fails when README.md and the results disagree.
`HIGHLIGHTS` chooses the rows: (topic, stage, start of the method) of each row shown.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from benchmarks.report import markdown_table
from scanmap_driver.files import atomic_path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = Path(__file__).resolve().parent / "results" / "latest.json"
BEGIN = "<!-- benchmarks:begin (generated from benchmarks/results/latest.json) -->"
END = "<!-- benchmarks:end -->"

HIGHLIGHTS = [
    ("triangulation", "triangulation", "numba kernel, pinhole"),
    ("laser", "frame budget", "extraction + decoding + triangulation"),
    ("laser", "laser extraction", "com on red"),
    ("laser", "encoder decoding", "blurred-code correlation"),
    ("calibration", "range after wall calibration", "wall-calibrated"),
    ("registration", "registration", "ours: ScanOdometry"),
    ("grid", "grid accuracy", ""),
    ("grid", "grid insert", "numba, bundled rays"),
    ("grid", "distance field", ""),
    ("grid", "distance query", ""),
    ("grid", "nearest query", ""),
    ("loop_closure", "loop closure", "ours: ScanOdometry + LoopCloser"),
    ("localise", "localisation", ""),
    ("mapping", "pipeline", "scanmap map"),
    ("mapping", "mapper (online)", ""),
    ("simulator", "simulator", "sampled ray casting"),
    ("simulator", "simulator", "simulate recording"),
]


def highlight_rows(rows: list[dict]) -> list[dict]:
    """The rows `HIGHLIGHTS` names, in its order (a row once)."""
    chosen: list[dict] = []
    for topic, stage, method in HIGHLIGHTS:
        for row in rows:
            if (row.get("topic") == topic and row.get("stage") == stage
                    and str(row.get("method", "")).startswith(method)
                    and not any(row is seen for seen in chosen)):
                chosen.append(row)
    return chosen


def stamp_line(result: dict) -> str:
    """Where and when the figures were measured."""
    machine = result.get("machine", {})
    target = f"{machine['cpu_target']}, " if "cpu_target" in machine else ""
    return (f"Measured {result.get('created', '?')} at commit {result.get('commit', '?')} on "
            f"{machine.get('cpu_model', '?')} ({target}{machine.get('cores', '?')} cores), "
            f"{'quick' if result.get('quick') else 'full'} run; medians, peers in the same "
            "run. Every row: `benchmarks/results/latest.md`.")


def render(result: dict) -> str:
    """The README block (markers included) for a results file's content."""
    table = markdown_table(highlight_rows(result["rows"]))
    return f"{BEGIN}\n{stamp_line(result)}\n\n{table}\n{END}"


def replace_block(text: str, block: str) -> str:
    """`text` with the part between the markers replaced by `block`."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise ValueError("README.md has no benchmark markers")
    return text[:start] + block + text[end + len(END):]


def update_readme(readme: Path = README, results: Path = RESULTS) -> None:
    """Rewrite README.md's benchmark table from the results file."""
    text = replace_block(readme.read_text(), render(json.loads(results.read_text())))
    with atomic_path(readme) as tmp:
        tmp.write_text(text)


if __name__ == "__main__":
    update_readme()
    sys.exit(0)
