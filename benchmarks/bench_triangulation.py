"""Triangulation throughput (Numba kernel vs a plain-numpy implementation) and exactness."""

from __future__ import annotations

import cv2
import numpy as np

from benchmarks.timing import first_call_time, median_time
from scanmap_driver.scanner_model import CameraIntrinsics, reference_scanner
from scanmap_driver.triangulation import triangulate


def numpy_triangulate(model, u, v, heading):
    """Plain vectorised numpy, no distortion: the peer the kernel must beat."""
    cam = model.camera
    rays = np.column_stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)])
    rotation = model.camera_mount.rotation
    centre = np.array(model.camera_mount.position)
    normal = np.array(model.laser.normal)
    n_cam = rotation.T @ normal
    t = ((np.array(model.laser.origin) - centre) @ normal) / (rays @ n_cam)
    head = (t[:, None] * rays) @ rotation.T + centre
    c, s = np.cos(heading), np.sin(heading)
    return np.column_stack([c * head[:, 0] - s * head[:, 1], s * head[:, 0] + c * head[:, 1],
                            head[:, 2]])


def round_trip_error(model, n: int) -> float:
    """Max |triangulated - true| (m) for points on the plane projected by OpenCV."""
    rng = np.random.default_rng(1)
    normal = np.array(model.laser.normal)
    e1 = np.cross(normal, [0, 0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    points = np.array(model.laser.origin) + rng.uniform(-3, 3, (n, 1)) * e1 \
        + rng.uniform(-3, 3, (n, 1)) * e2
    rotation = model.camera_mount.rotation
    cam_pts = (points - np.array(model.camera_mount.position)) @ rotation
    pix, _ = cv2.projectPoints(cam_pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                               model.camera.matrix, model.camera.dist_coeffs)
    pix = pix.reshape(-1, 2)
    result = triangulate(model, pix[:, 0], pix[:, 1], 0.0)
    # Inside the calibrated field of view, where the distortion polynomial is one-to-one.
    x, y = cam_pts[:, 0] / cam_pts[:, 2], cam_pts[:, 1] / cam_pts[:, 2]
    ok = result.valid & (cam_pts[:, 2] > 0) & (np.abs(x) < 0.3) & (np.abs(y) < 0.22)
    return float(np.abs(result.points_head[ok] - points[ok]).max())


def run(quick: bool = False) -> list[dict]:
    """Rows: one frame (640 lines) and a large batch, with and without distortion."""
    model = reference_scanner()
    distorted = model.with_changes(camera=CameraIntrinsics(
        width=640, height=480, fx=1012.0, fy=1018.0, cx=322.4, cy=236.1,
        distortion=(-0.21, 0.09, 0.0012, -0.0007, -0.02)))
    rng = np.random.default_rng(0)
    rows = []
    compile_s = first_call_time(lambda: triangulate(model, np.zeros(1), np.zeros(1), 0.0))
    for name, n in (("one frame", 640), ("batch", 200_000 if quick else 2_000_000)):
        u = np.tile(np.arange(640.0), n // 640 + 1)[:n]
        v = rng.uniform(0, 479, n)
        for label, m in (("pinhole", model), ("with distortion", distorted)):
            ours = median_time(lambda m=m, u=u, v=v: triangulate(m, u, v, 0.3),
                               repeats=5 if quick else 20)
            peers = {}
            if label == "pinhole":
                peers["numpy"] = {"median_s": median_time(
                    lambda u=u, v=v: numpy_triangulate(model, u, v, 0.3),
                    repeats=5 if quick else 20)}
            rows.append({
                "stage": "triangulation", "method": f"numba kernel, {label}",
                "settings": f"{name}, {n} points", "median_s": ours,
                "points_per_s": n / ours,
                "error": round_trip_error(m, 2000), "error_unit": "m (max vs OpenCV projection)",
                "compile_s": compile_s, "peers": peers,
            })
    return rows


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    table = run()
    print(markdown_table(table))
    for row in table:
        print(f"{row['method']:32s} {row['settings']:28s} {row['points_per_s'] / 1e6:7.1f} Mpts/s")
