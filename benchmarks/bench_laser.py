"""Frame processing: laser extraction (speed against subpixel error for every estimator
and fit channel), encoder decoding (heading error), and the whole per-frame budget
(extraction + decoding + triangulation, goal < 0.5 ms per 640x480 frame on one core);
MJPG decoding of the frame apart. Truth: synthetic frames with exact stripe centres and
forward-rendered disk frames (scanmap_driver/sim/synthetic_frames.py); the real
laser-on/laser-off pairs when ../shared/data/real is present.

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
from scanmap_driver.laser import ESTIMATORS, LaserConfig, extract_stripe
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.synthetic_frames import disk_frame, stripe_frame
from scanmap_driver.triangulation import triangulate

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "laser" / \
    "ciclop_3dscanscience" / "3.1_laser_segmentation"

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


def real_agreement() -> tuple[float, float] | None:
    """(per-row agreement with the difference image, median s) on the real pair, or None."""
    if not (REAL / "laser.png").exists():
        return None
    on = cv2.imread(str(REAL / "laser.png"))
    off = cv2.imread(str(REAL / "laser_background.png"))
    settings = LaserConfig(axis="rows", stripe_width=8.0)
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
    rows.append({
        "stage": "video decoding", "method": "cv2.imdecode of one MJPG frame",
        "settings": "640x480 q85 (separate from the budget)",
        "median_s": median_time(lambda: cv2.imdecode(jpeg, cv2.IMREAD_COLOR),
                                repeats=repeats), "error": None, "peers": {}})
    real = real_agreement()
    if real is not None:
        rows.append({
            "stage": "laser extraction", "method": "default settings, real laser pair",
            "settings": "3DScanScience laser.png 1280x960, axis rows, stripe 8 px",
            "median_s": real[1], "error": 1.0 - real[0],
            "error_unit": "rows off the difference-image stripe (fraction)", "peers": {}})
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
        if "parts_cpu_s" in row:
            parts = {k: f"{v * 1e6:.0f} us" for k, v in row["parts_cpu_s"].items()}
            print(f"\nframe budget, CPU time of one core: {parts}, whole frame "
                  f"{row['cpu_s'] * 1e6:.0f} us (wall median {row['median_s'] * 1e6:.0f} us)")
