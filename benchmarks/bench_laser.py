"""Frame processing: laser extraction (speed against subpixel error for every estimator
and fit channel), encoder decoding (heading error), and the whole per-frame budget
(extraction + decoding + triangulation, goal < 0.5 ms per 640x480 frame on one core);
MJPG decoding of the frame apart. Truth: synthetic frames with exact stripe centres and
forward-rendered disk frames (scanmap_driver/sim/synthetic_frames.py); the real
laser-on/laser-off pairs when ../shared/data/real is present.

Peer: `simple_peak`, the usual simple detector (each channel Gaussian-smoothed in 2D,
sigma 1.2 px, so across the lines too; score R - (G+B)/2; argmax per line; 3-point
Gaussian on the score).

Real flat board (`flat_board`; 3DScanScience 3.2, two laser lines on a chessboard): a
plane's laser line is straight once the lens is undone. The measure, the same for both
detectors: the camera is calibrated from the 16 chessboard captures (12x7 squares,
13 mm); the board's rows are those of its inner corners (found on the laser-off frame's
red) widened by half a square; each laser line is extracted on its own half of the image
(split midway between the two lines of the laser-on minus laser-off red). On those rows
each detector's positions are undistorted and a total-least-squares line is fitted, the
points farther than 1 px dropped and the line refitted (5 rounds). rows: board rows
whose position lies within 1 px of the line; outliers: board rows with a position
farther (a row where the laser is absent but a position is reported counts here); rms:
px RMS distance of the rows' positions from the line.

Run: python -m benchmarks.bench_laser [--quick]
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from benchmarks.timing import first_call_time, median_time
from scanmap_driver.encoder import decode_heading, laser_line_range
from scanmap_driver.jpeg import jpeg_to_bgr
from scanmap_driver.laser import ESTIMATORS, LaserConfig, extract_stripe
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.synthetic_frames import disk_frame, saturated_core_frame, stripe_frame
from scanmap_driver.triangulation import triangulate

CICLOP = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "laser" / \
    "ciclop_3dscanscience"
REAL = CICLOP / "3.1_laser_segmentation"
BOARD = CICLOP / "3.2_laser_in_pattern"
BOARD_IMAGES = ("laser-0-255-255-8", "laser-0-255-255-8-x")  # + laser-background-...
OUTLIER_PX = 1.0

CONDITIONS = {  # name -> synthetic stripe (sigma 1.5 px); MJPG is what the webcam sends
    "dark": {},
    "noise 5": {"noise": 5.0},
    "saturated": {"amplitude": 600.0},
    "mjpg": {"jpeg": 85},
    "saturated mjpg": {"amplitude": 600.0, "jpeg": 85},
    "bright mjpg": {"level": 120.0, "amplitude": 150.0, "red_objects": 4, "jpeg": 85},
}


def median_cpu_time(func: Callable[[], object], repeats: int) -> float:
    """Median CPU time (s) of this thread per call (the wall-clock median is median_s)."""
    return median_time(func, repeats, clock=time.thread_time)


def stripe_errors(settings: LaserConfig, frames: dict) -> dict[str, tuple[float, float]]:
    """Per condition: (RMS error px of the found peaks, fraction of lines found right)."""
    out = {}
    for name, pairs in frames.items():
        errors, right = [], []
        for image, truth in pairs:
            err = extract_stripe(image, settings).peak - truth
            good = np.abs(err) < 1.5
            errors.append(err[good])
            right.append(good.mean())
        e = np.concatenate(errors)
        out[name] = (float(np.sqrt(np.mean(e**2))), float(np.mean(right)))
    return out


def naive_peak(image: np.ndarray, t: int = 150) -> np.ndarray:
    """Peer: the paper's eq. 1 mask and a per-column argmax of red with a 3-point Gaussian,
    in plain numpy (no ridge test, no saturation handling)."""
    b, g, r = (image[:, :, k].astype(np.float64) for k in range(3))
    score = np.where((r > t) & (g < t) & (b < t), r, 0.0)
    v = np.clip(score.argmax(axis=0), 1, image.shape[0] - 2)
    cols = np.arange(image.shape[1])
    la, lb, lc = (np.log(np.maximum(r[v + k, cols], 1.0)) for k in (-1, 0, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.clip(0.5 * (la - lc) / (la - 2 * lb + lc), -1, 1)
    return np.where(score.max(axis=0) > 0, v + np.nan_to_num(d), np.nan)


def simple_peak(image: np.ndarray, by_rows: bool = False) -> np.ndarray:
    """Peer: the simple detector (module doc) in OpenCV and numpy; a position per line."""
    blur = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 1.2)
    score = blur[:, :, 2] - 0.5 * (blur[:, :, 0] + blur[:, :, 1])
    if not by_rows:
        score = score.T
    lines = np.arange(score.shape[0])
    v = np.clip(score.argmax(1), 1, score.shape[1] - 2)
    a, b, c = (score[lines, v + k] for k in (-1, 0, 1))
    la, lb, lc = (np.log(np.maximum(x, 1e-6)) for x in (a, b, c))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.clip(0.5 * (la - lc) / (la - 2 * lb + lc), -1, 1)
    return np.where((a > 0) & (b > 0) & (c > 0), v + np.nan_to_num(d), np.nan)


def board_camera() -> tuple[np.ndarray, np.ndarray, float]:
    """(camera matrix, distortion, RMS px) from the 16 Ciclop chessboard captures."""
    from scanmap_driver.calibration import Chessboard, calibrate_camera

    result = calibrate_camera(sorted((CICLOP / "4.2_camera_calibration_captures").glob(
        "frame*.jpg")), Chessboard((12, 7), 0.013))
    return result.camera.matrix, np.asarray(result.camera.dist_coeffs), result.rms


def board_setup(name: str) -> tuple[np.ndarray, int, int, list[tuple[int, int]]]:
    """(laser-on frame, first and end board row, the two lines' column ranges)."""
    on = cv2.imread(str(BOARD / f"{name}.png"))
    off = cv2.imread(str(BOARD / f"{name.replace('laser-', 'laser-background-')}.png"))
    found, corners = cv2.findChessboardCornersSB(
        off[:, :, 2], (11, 6), flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE)
    if not found:
        raise RuntimeError(f"{name}: the chessboard is not found")
    v = corners.reshape(-1, 2)[:, 1]
    half_square = 0.5 * (v.max() - v.min()) / 5
    r0, r1 = int(v.min() - half_square), int(v.max() + half_square)
    diff = np.clip(on[r0:r1, :, 2].astype(np.float32) - off[r0:r1, :, 2], 0, None).sum(0)
    profile = cv2.GaussianBlur(diff[None], (0, 0), 5).ravel()
    first = int(profile.argmax())
    rest = profile.copy()
    rest[max(0, first - 60):first + 60] = 0
    mid = (first + int(rest.argmax())) // 2
    return on, r0, r1, [(0, mid), (mid, on.shape[1])]


def line_fit(rows: np.ndarray, cols: np.ndarray, matrix: np.ndarray,
             dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance px of each undistorted point from the TLS line, inlier mask): points
    farther than OUTLIER_PX are dropped and the line refitted, 5 rounds."""
    points = cv2.undistortPoints(np.column_stack([cols, rows]).reshape(-1, 1, 2).astype(
        np.float64), matrix, dist, P=matrix).reshape(-1, 2)
    keep = np.ones(len(points), bool)
    for _ in range(5):
        centre = points[keep].mean(0)
        normal = np.linalg.svd(points[keep] - centre)[2][1]
        residual = (points - centre) @ normal
        keep = np.abs(residual) <= OUTLIER_PX
    return residual, keep


def straightness(detect: Callable[[np.ndarray], np.ndarray], name: str, matrix: np.ndarray,
                 dist: np.ndarray) -> dict[str, float]:
    """rows, outliers and rms (module doc) of `detect` (crop -> position per row)."""
    on, r0, r1, halves = board_setup(name)
    rows = outliers = 0
    residuals = []
    for c0, c1 in halves:
        peak = detect(np.ascontiguousarray(on[r0:r1, c0:c1]))
        found = np.flatnonzero(np.isfinite(peak))
        residual, keep = line_fit(found + r0, peak[found] + c0, matrix, dist)
        rows += int(keep.sum())
        outliers += int((~keep).sum())
        residuals.append(residual[keep])
    res = np.concatenate(residuals)
    return {"rows": rows, "outliers": outliers, "board_rows": 2 * (r1 - r0),
            "rms_px": float(np.sqrt(np.mean(res**2)))}


DETECTORS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "ours (default)": lambda crop: extract_stripe(crop, LaserConfig(axis="rows")).peak,
    "simple": lambda crop: simple_peak(crop, by_rows=True),
}


def flat_board() -> dict[str, dict[str, dict[str, float]]] | None:
    """{image: {detector: rows, outliers, rms}} on the real flat board, or None."""
    if not (BOARD / f"{BOARD_IMAGES[0]}.png").exists():
        return None
    matrix, dist, _ = board_camera()
    return {name: {label: straightness(detect, name, matrix, dist)
                   for label, detect in DETECTORS.items()} for name in BOARD_IMAGES}


def saturated_core_centring(n_frames: int) -> dict[str, dict[str, float]]:
    """Per detector: fraction of lines within 1 px and RMS px of those, on
    `saturated_core_frame` (white core 8 px, red clipped ~19 px, red-lit scene)."""
    rng = np.random.default_rng(5)
    frames = [saturated_core_frame(rng) for _ in range(n_frames)]
    out = {}
    for label, detect in (("ours (default)", lambda f: extract_stripe(f).peak),
                          ("simple", simple_peak)):
        err = np.abs(np.concatenate([detect(f) - t for f, t in frames]))
        near = err < 1.0
        out[label] = {"within_1px": float(near.mean()),
                      "rms_px": float(np.sqrt(np.mean(err[near] ** 2)))}
    return out


def real_agreement() -> tuple[float, float] | None:
    """(per-row agreement with the difference image, median s) on the real pair, or None."""
    if not (REAL / "laser.png").exists():
        return None
    on = cv2.imread(str(REAL / "laser.png"))
    off = cv2.imread(str(REAL / "laser_background.png"))
    settings = LaserConfig(axis="rows")
    result = extract_stripe(on, settings)
    diff = np.clip(on[:, :, 2].astype(np.float32) - off[:, :, 2], 0, None)
    smooth = cv2.GaussianBlur(diff, (0, 0), 2.0)
    rows = np.flatnonzero(diff.max(1) >= 60)
    agree = 0
    for row in rows:
        if np.isfinite(result.peak[row]):
            p = round(result.peak[row])
            agree += smooth[row, max(0, p - 4):p + 5].max() >= 0.5 * smooth[row].max()
    return agree / rows.size, median_time(lambda: extract_stripe(on, settings), repeats=5)


def run(quick: bool = False) -> list[dict]:
    """Rows: extraction options, the naive peer, decoding, the frame budget, MJPG decode."""
    rng = np.random.default_rng(0)
    model = reference_scanner()
    n_frames = 1 if quick else 3
    repeats = 10 if quick else 50
    frames = {name: [stripe_frame(rng, **kw) for _ in range(n_frames)]
              for name, kw in CONDITIONS.items()}
    timing_frame = frames["mjpg"][0][0]
    compile_s = first_call_time(lambda: extract_stripe(timing_frame))
    rows = []
    naive = {}
    for name, pairs in frames.items():
        err = np.concatenate([naive_peak(image) - truth for image, truth in pairs])
        good = np.abs(err) < 1.5
        naive[name] = float(np.sqrt(np.mean(err[good] ** 2))) if good.any() else math.nan
    naive_s = median_time(lambda: naive_peak(timing_frame), repeats=repeats)
    for channel in ("red", "luma"):
        for estimator in ESTIMATORS:
            settings = LaserConfig(estimator=estimator, fit_channel=channel)
            errors = stripe_errors(settings, frames)
            rows.append({
                "stage": "laser extraction", "method": f"{estimator} on {channel}",
                "settings": "bright method, auto threshold, 640x480",
                "median_s": median_time(lambda s=settings: extract_stripe(timing_frame, s),
                                        repeats=repeats),
                "error": errors["mjpg"][0], "error_unit": "px RMS (MJPG q85)",
                "by_condition": {k: {"rms_px": v[0], "found": v[1]} for k, v in errors.items()},
                "compile_s": compile_s,
                "peers": {"naive eq.1 argmax + gauss3 (numpy)": {
                    "median_s": naive_s, "error": naive["mjpg"]}},
            })
    dark = LaserConfig(method="dark")
    rows.append({
        "stage": "laser extraction",
        "method": f"dark method (eq. 1), {dark.estimator} on {dark.fit_channel}",
        "settings": "auto t, 640x480", "median_s": median_time(
            lambda: extract_stripe(timing_frame, dark), repeats=repeats),
        "error": stripe_errors(dark, {"mjpg": frames["mjpg"]})["mjpg"][0],
        "error_unit": "px RMS (MJPG q85)", "peers": {}})

    n_disk = 4 if quick else 16
    headings = rng.uniform(-math.pi, math.pi, n_disk)
    disk_cases = {"blur 4 px": {}, "blur 10 px, noise 6, MJPG q75": {
        "blur": 10.0, "noise": 6.0, "jpeg": 75}}
    disk_frames = {}
    for name, kw in disk_cases.items():
        disk_frames[name] = [disk_frame(model, h, rng, **kw) for h in headings]
        errs = [math.degrees(math.remainder(decode_heading(f, model).heading - h, 2 * math.pi))
                for f, h in zip(disk_frames[name], headings, strict=True)]
        rows.append({
            "stage": "encoder decoding", "method": "blurred-code correlation + edges",
            "settings": name, "median_s": median_time(
                lambda f=disk_frames[name][0]: decode_heading(f, model), repeats=repeats),
            "error": float(np.sqrt(np.nanmean(np.square(errs)))), "error_unit": "deg RMS",
            "max_error_deg": float(np.nanmax(np.abs(errs))),
            "unreadable": int(np.isnan(errs).sum()), "peers": {}})

    frame = timing_frame.copy()
    frame[:, 560:] = disk_frames["blur 4 px"][0][:, 560:]
    laser = LaserConfig(line_range=laser_line_range(model))

    def whole_frame():
        stripe = extract_stripe(frame, laser)
        heading = decode_heading(frame, model)
        found = np.flatnonzero(np.isfinite(stripe.peak))
        return triangulate(model, found.astype(np.float64), stripe.peak[found], heading.heading)

    parts = {
        "extraction": median_cpu_time(lambda: extract_stripe(frame, laser), repeats),
        "decoding": median_cpu_time(lambda: decode_heading(frame, model), repeats),
        "triangulation": median_cpu_time(lambda: triangulate(
            model, np.arange(560.0), np.full(560, 240.0), 0.3), repeats),
    }
    jpeg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])[1]
    rows.append({
        "stage": "frame budget", "method": "extraction + decoding + triangulation",
        "settings": "640x480, 560 laser lines, goal < 0.5 ms on one core",
        "median_s": median_time(whole_frame, repeats=repeats), "error": None,
        "cpu_s": median_cpu_time(whole_frame, repeats), "parts_cpu_s": parts, "peers": {}})
    data = jpeg.tobytes()
    rows.append({
        "stage": "video decoding", "method": "jpeg_to_bgr (simplejpeg) of one MJPG frame",
        "settings": "640x480 q85 (separate from the budget); the same pixels as OpenCV's",
        "median_s": median_time(lambda: jpeg_to_bgr(data), repeats=repeats),
        "error": float(np.abs(jpeg_to_bgr(data).astype(int)
                              - cv2.imdecode(jpeg, cv2.IMREAD_COLOR)).max()),
        "error_unit": "largest pixel difference to cv2.imdecode",
        "peers": {"cv2.imdecode": {"median_s": median_time(
            lambda: cv2.imdecode(jpeg, cv2.IMREAD_COLOR), repeats=repeats), "error": None}}})
    real = real_agreement()
    if real is not None:
        rows.append({
            "stage": "laser extraction", "method": "default settings, real laser pair",
            "settings": "3DScanScience laser.png 1280x960, axis rows",
            "median_s": real[1], "error": 1.0 - real[0],
            "error_unit": "rows off the difference-image stripe (fraction)", "peers": {}})
    centring = saturated_core_centring(1 if quick else 3)
    rows.append({
        "stage": "laser extraction", "method": "default settings, saturated core",
        "settings": "white core 8 px, red clipped ~19 px, red-lit scene, 640x480",
        "median_s": None, "error": 1.0 - centring["ours (default)"]["within_1px"],
        "error_unit": "lines off the true centre by 1 px or more (fraction)",
        "saturated_core": centring,
        "peers": {"simple": {"error": 1.0 - centring["simple"]["within_1px"]}}})
    board = flat_board()
    if board is not None:
        for name, by_detector in board.items():
            ours, simple = by_detector["ours (default)"], by_detector["simple"]
            rows.append({
                "stage": "laser extraction", "method": "default settings, real flat board",
                "settings": f"3DScanScience {name}, 2 lines, straight-line fit (module doc)",
                "median_s": None, "error": ours["rms_px"], "error_unit": "px RMS off the line",
                "flat_board": by_detector, "peers": {"simple": {"error": simple["rms_px"]}}})
    return rows


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    table = run(quick="--quick" in sys.argv)
    print(markdown_table(table))
    print("\nsubpixel RMS error (px) / fraction of lines found, by condition:")
    print(f"{'option':24s}" + "".join(f"{k:>17s}" for k in CONDITIONS))
    for row in table:
        if "by_condition" in row:
            cells = "".join(f"{v['rms_px']:9.3f} /{v['found']:6.3f}"
                            for v in row["by_condition"].values())
            print(f"{row['method']:24s}{cells}  {row['median_s'] * 1e6:6.0f} us")
    for row in table:
        if "saturated_core" in row:
            print("\nsaturated core: " + ", ".join(
                f"{k} {v['within_1px']:.1%} of lines within 1 px (RMS {v['rms_px']:.3f} px)"
                for k, v in row["saturated_core"].items()))
        if "flat_board" in row:
            print(f"\nflat board {row['settings'].split()[1]}: " + "; ".join(
                f"{k} rows {v['rows']}/{v['board_rows']} outliers {v['outliers']} "
                f"rms {v['rms_px']:.3f} px" for k, v in row["flat_board"].items()))
        if "error_unit" in row and row["error_unit"].startswith("rows off"):
            print(f"\nreal bust pair: {1 - row['error']:.3f} of the stripe rows agree "
                  "with the laser-on minus laser-off difference")
    for row in table:
        if "parts_cpu_s" in row:
            parts = {k: f"{v * 1e6:.0f} us" for k, v in row["parts_cpu_s"].items()}
            print(f"\nframe budget, CPU time of one core: {parts}, whole frame "
                  f"{row['cpu_s'] * 1e6:.0f} us (wall median {row['median_s'] * 1e6:.0f} us)")
