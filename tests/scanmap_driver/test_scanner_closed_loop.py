"""The closed loop: the real `Scanner` drives the simulated firmware on a pseudo-terminal
while a simulated webcam renders the office scene for the head's true motion; frames go
through the real pipeline (laser extraction, encoder decoding, triangulation in
`assembly.ScanAssembler`). The scan must match the simulator's ground truth as well as
the offline path does (a simulated recording of the same scene replayed through the same
assembler).

Rendering takes 0.1-0.2 s per frame here, so the simulated world runs 5 times slower than
the real scanner: the head turns in about 9 s and the camera delivers 5 frames/s, the
same ~50 frames per turn.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from scanmap_driver import reference_scanner
from scanmap_driver.camera import RenderedCamera
from scanmap_driver.motor import MotorController
from scanmap_driver.scanner import (
    Scanner,
    ScanSettings,
    encoder_headings,
    replay_recording,
)
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.firmware import SimulatedFirmware, scene_renderer
from scanmap_driver.sim.motor_model import MotorParameters
from scanmap_driver.sim.render import Renderer
from scanmap_driver.sim.simulate import simulate_recording
from scanmap_driver.sim.truth import ScanTruth, truth_path

pytest.importorskip("scanmap_driver.encoder", reason="the encoder decoder is not there yet")
from scanmap_driver.assembly import ScanAssembler  # noqa: E402 (needs the encoder)

SLOW = 5.0


def frame_errors(scan, truth_points) -> np.ndarray:
    """Distance (m) from each scan point to the nearest true stripe point of its frame."""
    errors = np.full(len(scan), np.nan)
    for k in np.unique(scan.frame_index):
        rows = scan.frame_index == k
        true = truth_points(int(k))
        if len(true):
            errors[rows] = cKDTree(true).query(scan.points[rows])[0]
    return errors


def test_live_scan_matches_ground_truth_as_well_as_the_offline_path(tmp_path):
    model = reference_scanner()
    scene = builtin_scene("office")

    # the offline path: a simulated recording of the same place, replayed
    simulate_recording(scene, tmp_path / "rec", model, seed=3, scans=1, workers=1)
    (offline, _), = replay_recording(tmp_path / "rec")
    truth = ScanTruth.load(truth_path(tmp_path / "rec", 0))

    def offline_truth(k):
        rows = (truth.laser["frame"] == k) & truth.laser["primary"]
        return truth.laser["base"][rows]

    offline_error = frame_errors(offline, offline_truth)

    # the live loop
    slow = MotorParameters(full_speed=MotorParameters().full_speed / SLOW)
    truths = []
    settings = ScanSettings(continuous=True, time_limit=40.0, frame_timeout=3.0,
                            stall_time=3.0)
    with SimulatedFirmware(slow, start_angle=1.0) as firmware:
        camera = RenderedCamera(scene_renderer(Renderer(scene, model), firmware,
                                               scene.scan_poses[0], seed=4, truths=truths),
                                frame_rate=25.0 / SLOW)
        with MotorController.connect(firmware.port) as motor, \
                Scanner(camera, motor, encoder_headings(model), lambda: ScanAssembler(model),
                        settings) as scanner:
            result = scanner.scan()
        camera.close()
    by_time = {round(t.time, 6): t for t in truths}

    def live_truth(k):
        t = by_time[round(float(result.frame_times[k]), 6)]
        return t.stripe.base[t.primary]

    live_error = frame_errors(result.scan, live_truth)
    true_headings = np.array([by_time[round(float(t), 6)].heading for t in result.frame_times])
    decoded = np.isfinite(result.headings)
    heading_error = np.abs((result.headings[decoded] - true_headings[decoded] + math.pi)
                           % (2 * math.pi) - math.pi)

    assert result.fault is None
    assert result.coverage >= 2 * math.pi + math.radians(10)
    assert true_headings[-1] - true_headings[0] >= 2 * math.pi + math.radians(5)
    assert np.median(heading_error) < math.radians(1.0)
    assert len(result.scan) > 0.7 * len(offline)
    for q in (50, 90):
        live, off = np.nanpercentile(live_error, q), np.nanpercentile(offline_error, q)
        assert live <= 1.5 * off + 0.005, (q, live, off)
