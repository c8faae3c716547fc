"""Benchmark output: the markdown table and the speed-against-error plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from scanmap_driver.files import atomic_path


def _fmt_time(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-"
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds / 1e-9:.3g} ns"


def _fmt_error(row: dict[str, Any]) -> str:
    error = row.get("error")
    if error is None:
        return "-"
    return f"{error:.3g} {row.get('error_unit', '')}".strip()


def _fmt_peers(row: dict[str, Any]) -> str:
    parts = []
    for name, peer in (row.get("peers") or {}).items():
        ratio = ""
        if peer.get("median_s") and row.get("median_s"):
            ratio = f", {peer['median_s'] / row['median_s']:.3g}x our time"
        error = f", err {peer['error']:.3g}" if peer.get("error") is not None else ""
        parts.append(f"{name}: {_fmt_time(peer.get('median_s'))}{error}{ratio}")
    return "; ".join(parts) or "-"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """One markdown row per benchmark row: stage, method, settings, time, error, peers."""
    lines = ["| stage | method | settings | median time | error | peers (same run) |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row.get('stage', '')} | {row.get('method', '')} | "
                     f"{row.get('settings', '')} | {_fmt_time(row.get('median_s'))} | "
                     f"{_fmt_error(row)} | {_fmt_peers(row)} |")
    return "\n".join(lines)


def speed_error_plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Scatter of median time against error, one panel per stage, peers in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = [s for s in dict.fromkeys(r.get("stage") for r in rows)
              if any(r.get("error") is not None and r.get("median_s") for r in rows
                     if r.get("stage") == s)]
    if not stages:
        return
    cols = min(3, len(stages))
    nrows = math.ceil(len(stages) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5 * cols, 3.6 * nrows), squeeze=False)
    for ax, stage in zip(axes.flat, stages, strict=False):
        for row in (r for r in rows if r.get("stage") == stage):
            if row.get("error") is None or not row.get("median_s"):
                continue
            ax.scatter(row["median_s"], max(row["error"], 1e-12), color="tab:blue")
            ax.annotate(row.get("method", ""), (row["median_s"], max(row["error"], 1e-12)),
                        fontsize=7)
            for name, peer in (row.get("peers") or {}).items():
                if peer.get("median_s") and peer.get("error") is not None:
                    ax.scatter(peer["median_s"], max(peer["error"], 1e-12), color="grey",
                               marker="s")
                    ax.annotate(name, (peer["median_s"], max(peer["error"], 1e-12)),
                                fontsize=7, color="grey")
        ax.set_xscale("log")
        ax.set_yscale("log")
        unit = next((r.get("error_unit", "") for r in rows if r.get("stage") == stage), "")
        ax.set_title(stage, fontsize=9)
        ax.set_xlabel("median time (s)")
        ax.set_ylabel(f"error ({unit})")
    for ax in list(axes.flat)[len(stages):]:
        ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
