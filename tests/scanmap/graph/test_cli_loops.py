"""`scanmap map --loop-closure` reports the loops it closed and draws them on the overhead."""

from __future__ import annotations

import json

import cv2
import numpy as np

from scanmap.cli import main
from scanmap.io.overhead import LOOP_BGR


def test_the_map_command_reports_and_draws_its_loops(ring_ideal, tmp_path, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    for item in ring_ideal:
        item.scan.save(scans / f"scan_{item.scan.index:04d}.npz")
    assert main(["map", str(scans), "--out", str(tmp_path / "map"), "--loop-closure"]) == 0
    printed = capsys.readouterr().out
    loops = json.loads((tmp_path / "map" / "report.json").read_text())["loops"]
    assert loops["enabled"] and loops["closed"] > 0 and loops["optimisations"] > 0
    assert f"loop closure: {loops['closed']} loops closed" in printed
    overhead = cv2.imread(str(tmp_path / "map" / "overhead.png"))
    assert (overhead == np.array(LOOP_BGR, np.uint8)).all(axis=2).sum() > 20  # the edges


def test_without_loop_closure_nothing_is_reported_or_drawn(ring_ideal, tmp_path, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    for item in ring_ideal[:5]:
        item.scan.save(scans / f"scan_{item.scan.index:04d}.npz")
    assert main(["map", str(scans), "--out", str(tmp_path / "map")]) == 0
    assert "loop closure" not in capsys.readouterr().out
    overhead = cv2.imread(str(tmp_path / "map" / "overhead.png"))
    assert not (overhead == np.array(LOOP_BGR, np.uint8)).all(axis=2).any()
