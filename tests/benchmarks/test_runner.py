"""The benchmark runner writes its JSON, table and plot (timings themselves are not tested)."""

from __future__ import annotations

import json

from benchmarks.__main__ import main


def test_runner_writes_results(tmp_path):
    assert main(["--quick", "--only", "triangulation", "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "latest.json").read_text())
    rows = result["rows"]
    assert result["failed"] == [] and rows
    assert all(row["stage"] == "triangulation" for row in rows)
    # The error column is a real measurement: OpenCV's projection triangulates back exactly.
    assert max(row["error"] for row in rows) < 1e-9
    assert "| triangulation |" in (tmp_path / "latest.md").read_text()
    assert (tmp_path / "latest.png").read_bytes()[:4] == b"\x89PNG"
