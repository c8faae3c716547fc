"""`scanmap scan` end to end without hardware: `--simulate` drives the simulated firmware
on a pseudo-terminal and a rendered webcam; `--record` keeps the raw recording; and
`scanmap process` of that recording (the same assembler, offline) gives the same scan."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from scanmap.cli import main
from scanmap_driver.recording import Recording
from scanmap_driver.scan import Scan


def test_simulated_scan_is_recorded_and_replays_to_the_same_points(tmp_path, capsys):
    code = main(["scan", "--simulate", "office", "--rotation", "continuous",
                 "--record", str(tmp_path / "rec"), "--out", str(tmp_path / "live")])
    err = capsys.readouterr().err
    assert code == 0 and "scan 0: done" in err, err
    live = Scan.load(tmp_path / "live" / "scan_0000.npz")
    recording = Recording.open(tmp_path / "rec")
    (record,) = recording.scans
    assert record.complete and recording.source == "simulator"
    # about 50 frames a turn; a loaded machine renders fewer in time (dropped, counted)
    assert record.frame_times.size >= live.frame_index.max() + 1 >= 20
    assert [e["command"] for e in record.motor_log][:2] == ["status", "run"]
    assert np.ptp(np.unwrap(live.heading)) >= 2 * math.pi

    assert main(["process", str(tmp_path / "rec"), "--no-ply",
                 "--out", str(tmp_path / "replayed")]) == 0
    replayed = Scan.load(tmp_path / "replayed" / "scan_0000.npz")
    assert len(replayed) == len(live)
    assert np.allclose(replayed.points, live.points, atol=1e-6)
    assert np.array_equal(replayed.frame_index, live.frame_index)
    assert np.allclose(replayed.time - replayed.time[0], live.time - live.time[0], atol=1e-6)


@pytest.mark.parametrize(("argv", "message"), [
    (["scan", "--camera", "0"], "--out DIR and/or --record DIR"),
    (["scan", "--out", "scans"], "--port TTY is required"),
])
def test_scan_without_a_port_or_output_says_what_is_missing(argv, message):
    with pytest.raises(SystemExit, match=re.escape(message)):
        main(argv)
