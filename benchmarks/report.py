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
        if "failed" in peer:
            parts.append(f"{name}: failed ({peer['failed']})")
            continue
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
        cells = [str(row.get("stage", "")), str(row.get("method", "")),
                 str(row.get("settings", "")), _fmt_time(row.get("median_s")),
                 _fmt_error(row), _fmt_peers(row)]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def _plottable(row: dict[str, Any]) -> bool:
    """A row with a positive error and a time: a point on a log-log speed-error plot."""
    return bool(row.get("median_s")) and (row.get("error") or 0.0) > 0.0


def speed_error_plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Median time against error, one panel per stage; ours in blue, peers in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    stages = [s for s in dict.fromkeys(r.get("stage") for r in rows)
              if any(_plottable(r) for r in rows if r.get("stage") == s)]
    if not stages:
        return
    cols = min(3, len(stages))
    nrows = math.ceil(len(stages) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 3.8 * nrows), squeeze=False)
    for ax, stage in zip(axes.flat, stages, strict=False):
        stage_rows = [r for r in rows if r.get("stage") == stage and _plottable(r)]
        for row in stage_rows:
            ax.scatter(row["median_s"], row["error"], color="tab:blue", zorder=3)
            ax.annotate(row.get("method", "")[:28], (row["median_s"], row["error"]),
                        fontsize=6, xytext=(3, 3), textcoords="offset points")
            for name, peer in (row.get("peers") or {}).items():
                if peer.get("median_s") and (peer.get("error") or 0.0) > 0.0:
                    ax.scatter(peer["median_s"], peer["error"], color="grey", marker="s",
                               s=14, zorder=2)
                    ax.annotate(name[:20], (peer["median_s"], peer["error"]), fontsize=6,
                                color="grey", xytext=(3, -7), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_minor_formatter(NullFormatter())
        ax.set_title(stage, fontsize=9)
        ax.set_xlabel("median time (s)", fontsize=8)
        ax.set_ylabel(stage_rows[0].get("error_unit", "error")[:40], fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(stages):]:
        ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80, format="png")
    plt.close(fig)
