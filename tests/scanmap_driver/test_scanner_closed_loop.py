"""The closed loop: the real `Scanner` drives the simulated firmware on a pseudo-terminal
while a simulated webcam renders the office scene for the head's true motion; frames go
through the real pipeline (laser extraction, encoder decoding, triangulation in
`assembly.ScanAssembler`). The scan must match the simulator's ground truth as well as
the offline path does (a simulated recording of the same place processed by the same
assembler). The measurement is `benchmarks.bench_scanner_device.closed_loop`.

Rendering takes 0.1-0.2 s per frame here, so the simulated world runs 5 times slower than
the real scanner: the head turns in about 9 s and the camera delivers 5 frames/s, the
same ~50 frames per turn.
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks.bench_scanner_device import closed_loop


def test_live_scan_matches_ground_truth_as_well_as_the_offline_path():
    live, offline = closed_loop(seed=3)
    result = live["result"]
    assert result.fault is None
    assert result.coverage >= 2 * math.pi + math.radians(10)
    assert live["true_turn"] >= 2 * math.pi + math.radians(5)
    assert np.median(live["heading_error"]) < math.radians(0.5)
    # frames a loaded machine could not render in time are dropped (and counted): compare
    # points per frame
    frames = len(result.frame_times)
    assert frames >= 20 and frames + result.dropped_frames + result.overflow_frames >= 40
    assert len(live["scan"]) / frames > 0.7 * len(offline["scan"]) / offline["frames"]
    for q in (50, 90):
        ours = np.nanpercentile(live["errors"], q)
        theirs = np.nanpercentile(offline["errors"], q)
        assert ours <= 1.5 * theirs + 0.005, (q, ours, theirs)
