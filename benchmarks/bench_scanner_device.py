"""The scanner as a device: the serial link's round trip, and the live scanning loop's
points against the simulator's ground truth beside the offline path's.

The live loop is the real `Scanner` on the simulated firmware (a pty) with a webcam that
renders the office scene for the head's true motion; the offline path processes a
simulated recording of the same place (`processing.recording_scans`, the same
`ScanAssembler`). Times are the assembly's (extraction, decoding, triangulation) per
frame; the offline one also decodes the JPEGs from the file. Rendering is
slower than a webcam, so the simulated world runs `SLOW` times slower than life.

    python -m benchmarks.bench_scanner_device
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.timing import median_time
from scanmap_driver import reference_scanner
from scanmap_driver.assembly import ScanAssembler
from scanmap_driver.camera import RenderedCamera
from scanmap_driver.heading_decoder import encoder_headings
from scanmap_driver.motor import MotorController
from scanmap_driver.processing import recording_scans
from scanmap_driver.recording import Recording
from scanmap_driver.scan import Scan
from scanmap_driver.scanner import ScanConfig, Scanner
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.firmware import SimulatedFirmware, scene_renderer
from scanmap_driver.sim.motor_model import MotorModelConfig
from scanmap_driver.sim.render import Renderer
from scanmap_driver.sim.simulate import simulate_recording
from scanmap_driver.sim.truth import ScanTruth, truth_path

SLOW = 5.0


class TimedAssembler:
    """A ScanAssembler that adds up the time spent in it."""

    def __init__(self, model) -> None:
        self.inner = ScanAssembler(model)
        self.seconds = 0.0

    def add_frame(self, image: np.ndarray, timestamp: float) -> float | None:
        start = time.perf_counter()
        heading = self.inner.add_frame(image, timestamp)
        self.seconds += time.perf_counter() - start
        return heading

    def finish(self, *args, **kwargs):
        start = time.perf_counter()
        result = self.inner.finish(*args, **kwargs)
        self.seconds += time.perf_counter() - start
        return result


def frame_errors(scan: Scan, truth_points) -> np.ndarray:
    """Distance (m) from each scan point to the nearest true stripe point of its frame."""
    errors = np.full(len(scan), np.nan)
    for k in np.unique(scan.frame_index):
        rows = scan.frame_index == k
        true = truth_points(int(k))
        if len(true):
            errors[rows] = cKDTree(true).query(scan.points[rows])[0]
    return errors


def offline_scan(folder: Path, scene, model, seed: int) -> dict:
    """Simulate a one-scan recording and process it: the scan, its point errors, timing."""
    simulate_recording(scene, folder, model, seed=seed, scans=1, workers=1)
    list(recording_scans(Recording.open(folder)))  # warm-up: Numba caches, lazy tables
    start = time.perf_counter()
    (scan, _, _), = recording_scans(Recording.open(folder))
    seconds = time.perf_counter() - start
    truth = ScanTruth.load(truth_path(folder, 0))

    def truth_points(k: int) -> np.ndarray:
        rows = (truth.laser["frame"] == k) & truth.laser["primary"]
        return truth.laser["base"][rows]

    frames = int(truth.frame_time.size)
    return {"scan": scan, "errors": frame_errors(scan, truth_points),
            "seconds_per_frame": seconds / frames, "frames": frames}


def live_scan(scene, model, seed: int, slow: float = SLOW) -> dict:
    """One scan of the real Scanner on the simulated firmware and webcam."""
    motor = MotorModelConfig(full_speed=MotorModelConfig().full_speed / slow)
    truths = []
    assemblers = []

    def assembler() -> TimedAssembler:
        assemblers.append(TimedAssembler(model))
        return assemblers[-1]

    settings = ScanConfig(continuous=True, time_limit=8.0 * slow, frame_timeout=1.0 * slow,
                            stall_time=1.0 * slow)
    with SimulatedFirmware(motor, start_angle=1.0, seed=seed) as firmware:
        render = scene_renderer(Renderer(scene, model), firmware, scene.scan_poses[0],
                                seed=seed, truths=truths)
        with RenderedCamera(render, frame_rate=model.camera.frame_rate / slow) as camera, \
                MotorController.connect(firmware.port) as controller, \
                Scanner(camera, controller, encoder_headings(model), assembler,
                        settings) as scanner:
            result = scanner.scan()
    by_time = {round(t.time, 6): t for t in truths}
    frame_truth = [by_time[round(float(t), 6)] for t in result.frame_times]

    def truth_points(k: int) -> np.ndarray:
        return frame_truth[k].stripe.base[frame_truth[k].primary]

    true_headings = np.array([t.heading for t in frame_truth])
    decoded = np.isfinite(result.headings)
    heading_error = np.abs((result.headings[decoded] - true_headings[decoded] + math.pi)
                           % (2 * math.pi) - math.pi)
    return {"result": result, "scan": result.scan,
            "errors": frame_errors(result.scan, truth_points),
            "heading_error": heading_error,
            "seconds_per_frame": assemblers[0].seconds / max(len(result.frame_times), 1),
            "true_turn": float(true_headings[-1] - true_headings[0])}


def closed_loop(seed: int = 3) -> tuple[dict, dict]:
    """(live, offline) measurements in the office scene at its first scan pose."""
    model = reference_scanner()
    scene = builtin_scene("office")
    with tempfile.TemporaryDirectory() as tmp:
        offline = offline_scan(Path(tmp) / "rec", scene, model, seed)
    return live_scan(scene, model, seed + 1), offline


def link_round_trip(requests: int) -> tuple[float, int]:
    """Median STATUS round trip (s) to the simulated firmware over its pty, and failures."""
    failures = 0
    with SimulatedFirmware(reset_on_open=False) as firmware, \
            MotorController.connect(firmware.port, heartbeat=None) as motor:
        def status() -> None:
            nonlocal failures
            try:
                motor.status()
            except Exception:
                failures += 1
        seconds = median_time(status, repeats=requests)
    return seconds, failures


def run(quick: bool = False) -> list[dict]:
    """Rows: the link round trip; the live loop's points and headings against the offline
    path's (both against the simulator's ground truth), with the assembler's median time
    per frame (extraction, decoding) in each."""
    seconds, failures = link_round_trip(50 if quick else 500)
    rows = [{"stage": "motor link", "method": "STATUS round trip, pyserial over a pty",
             "settings": "simulated firmware", "median_s": seconds, "error": failures,
             "error_unit": "failed requests", "peers": {}}]
    live, offline = closed_loop()
    result = live["result"]
    rows.append({
        "stage": "scanning loop", "method": "Scanner live: sim firmware + rendered webcam",
        "settings": f"office, 1 scan, world {SLOW:g}x slower",
        "median_s": live["seconds_per_frame"],
        "error": float(np.nanmedian(live["errors"])),
        "error_unit": "m (median distance to the true stripe point of the frame)",
        "error_p90": float(np.nanpercentile(live["errors"], 90)),
        "heading_error_deg": float(np.degrees(np.median(live["heading_error"]))),
        "points": len(live["scan"]), "frames": len(result.frame_times),
        "dropped_frames": result.dropped_frames + result.overflow_frames,
        "coverage_deg": float(np.degrees(result.coverage)),
        "peers": {"offline processing": {
            "median_s": offline["seconds_per_frame"],
            "error": float(np.nanmedian(offline["errors"])),
            "error_p90": float(np.nanpercentile(offline["errors"], 90)),
            "points": len(offline["scan"]), "frames": offline["frames"]}},
    })
    return rows


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    table = run(quick=False)
    print(markdown_table(table))
    for row in table[1:]:
        print({k: v for k, v in row.items() if k not in ("stage", "method", "settings")})
