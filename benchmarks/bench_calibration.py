"""Range error after the wall calibration, on simulator ground truth.

A "true" scanner differs from the nominal one by a few millimetres and milliradians (an
uncalibrated build). It records two wall scans (1.2 m and 3 m) and one office scan. The
wall calibration starts from the nominal model; the office frames are then processed
(extraction, heading decoding, triangulation) with the nominal, the calibrated and the
true model, and each point is compared with the truth of its frame and image line.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

from scanmap_driver import reference_scanner, triangulate
from scanmap_driver.calibration.wall import apply_corrections, calibrate_wall_recordings
from scanmap_driver.encoder import decode_heading, fill_unreadable, laser_line_range
from scanmap_driver.laser import LaserConfig, extract_stripe
from scanmap_driver.recording import Recording
from scanmap_driver.sim import builtin_scene, load_scene
from scanmap_driver.sim.simulate import simulate_recording

BUILD_ERRORS = {"laser_normal_1": 0.003, "laser_normal_2": -0.002, "vertical_separation": -0.005,
                "camera_tilt": 0.004, "camera_height": 0.008, "zero_offset": 0.02}
WALLS = (1.2, 3.0)
BINS = ((0.3, 1.5), (1.5, 3.0), (3.0, 4.0))
OUTLIER = 0.1  # m: a wrong peak (another surface, a reflection), not a measurement error


def wall_scene(folder: Path, distance: float):
    scene = {"format": "scanmap.scene/1", "name": f"wall {distance} m",
             "floor": {"color": [120, 110, 100]}, "ambient": 0.6,
             "objects": [{"type": "box", "center": [distance + 0.05, 0.0, 1.25],
                          "size": [0.1, 10.0, 2.5], "color": [210, 205, 200]}],
             "scan_poses": [[0.0, 0.0, 0.0]]}
    path = folder / f"wall_{distance}.json"
    path.write_text(json.dumps(scene))
    return load_scene(path)


def range_errors(recording: Recording, model) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal range error (m) and true range of every detected truth line."""
    truth = np.load(recording.ground_truth / "scan_0000.npz")
    settings = LaserConfig(line_range=laser_line_range(model))
    frames = list(recording.frames(0))
    results = [decode_heading(f.image, model) for f in frames]
    headings = fill_unreadable(np.array([r.heading for r in results]),
                               np.array([r.ok for r in results]),
                               np.array([f.time for f in frames]))
    errors, ranges = [], []
    for frame, heading in zip(frames, headings, strict=True):
        stripe = extract_stripe(frame.image, settings)
        mine = (truth["laser_frame"] == frame.index) & truth["laser_primary"] \
            & ~truth["laser_shadowed"]
        u = truth["laser_u"][mine].astype(int)
        keep = np.isfinite(stripe.peak[u])
        points = triangulate(model, u[keep].astype(float), stripe.peak[u[keep]], heading)
        true_points = truth["laser_base"][mine][keep]
        ok = points.valid
        true_range = np.hypot(true_points[ok, 0], true_points[ok, 1])
        errors.append(np.hypot(points.points_base[ok, 0], points.points_base[ok, 1])
                      - true_range)
        ranges.append(true_range)
    return np.concatenate(errors), np.concatenate(ranges)


def run(quick: bool = False) -> list[dict]:
    """Rows: range RMS per range bin for the nominal, calibrated and true models."""
    nominal = reference_scanner()
    true_model = apply_corrections(nominal, BUILD_ERRORS)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        walls = []
        for distance in WALLS:
            simulate_recording(wall_scene(folder, distance), folder / f"wall_{distance}",
                               true_model, seed=3)
            walls.append(Recording.open(folder / f"wall_{distance}"))
        start = time.perf_counter()
        result = calibrate_wall_recordings(walls, WALLS, nominal)
        calibration_s = time.perf_counter() - start
        simulate_recording(builtin_scene("office"), folder / "office", true_model, seed=5,
                           scans=1)
        office = Recording.open(folder / "office")
        for label, model in (("nominal (uncalibrated)", nominal),
                             ("wall-calibrated", result.model), ("true parameters", true_model)):
            errors, ranges = range_errors(office, model)
            for low, high in BINS:
                inside = (ranges >= low) & (ranges < high)
                err = errors[inside]
                inlier = err[np.abs(err) <= OUTLIER]
                rows.append({
                    "stage": "range after wall calibration", "method": label,
                    "settings": f"office scan, true range {low}-{high} m, {inside.sum()} pts",
                    "median_s": calibration_s if label == "wall-calibrated" else None,
                    "error": float(np.sqrt(np.mean(inlier**2))) if inlier.size else None,
                    "error_unit": f"m RMS (inliers, |error| <= {OUTLIER} m)",
                    "p95": float(np.percentile(np.abs(err), 95)) if err.size else None,
                    "outlier_rate": float(np.mean(np.abs(err) > OUTLIER)) if err.size else None,
                    "peers": {},
                })
    return rows


if __name__ == "__main__":
    for row in run():
        print(f"{row['method']:24s} {row['settings']:44s} rms {row['error'] * 1000:6.1f} mm "
              f"p95 {row['p95'] * 1000:6.1f} mm outliers {row['outlier_rate']:.4f}")
