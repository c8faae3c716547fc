"""Triangulation: laser pixels and headings to 3D points, with validity and uncertainty.

The paper's ray-plane intersection (eq. 2) with the pinhole camera (not its eq. 4, which
is off by a factor 2): a pixel (u, v) is undistorted to normalised coordinates (x, y),
its ray [x, y, 1] in the optical frame is intersected with the laser plane, and the point
is carried through the frame chain camera -> head -> base_link (eqs. 3-5 done right).

Pixel convention is OpenCV's: u is the column (0..width-1), v the row. With the camera on
its side, each image line across the stripe is a fixed u, and the stripe's subpixel peak
on it is v.

Invalid results are NaN points with a reason code, never huge or wrong points. The
range uncertainty is the displacement of the point for `pixel_sigma` pixels of peak
error along the image line: sigma = |dP/dv| * pixel_sigma.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from .scanner_model import ScannerModel

MAX_UNDISTORT_ITERATIONS = 20


class Reason(enum.IntEnum):
    """Why a pixel gave no point (VALID when it did)."""

    VALID = 0
    NAN_INPUT = 1
    OUTSIDE_IMAGE = 2
    UNDISTORT_FAILED = 3
    PARALLEL = 4
    BEHIND_CAMERA = 5
    TOO_NEAR = 6
    TOO_FAR = 7


@dataclass(frozen=True)
class Triangulation:
    """Points for N pixels; rows whose `reason` is not VALID are NaN."""

    points_base: np.ndarray  # (N, 3) float64, base_link
    points_head: np.ndarray  # (N, 3) float64, head
    range_sigma: np.ndarray  # (N,) float64, metres
    reason: np.ndarray  # (N,) uint8, Reason codes

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of rows that gave a point."""
        return self.reason == Reason.VALID


@njit(cache=True, nogil=True)
def undistort_normalized(xd: float, yd: float, dist: np.ndarray) -> tuple[float, float, float,
                                                                          float, bool]:
    """Invert OpenCV's 5-term distortion by Newton's method.

    Returns x, y and the derivatives dx/dyd, dy/dyd (the undistorted shift for a unit
    shift of the distorted normalised row coordinate), and whether it converged.
    """
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    x, y = xd, yd
    a = 1.0
    b = 0.0
    c = 0.0
    d = 1.0
    for _ in range(MAX_UNDISTORT_ITERATIONS):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
        fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
        a = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        c = b
        d = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = a * d - b * c
        if det == 0.0 or not np.isfinite(det):
            return x, y, 0.0, 0.0, False
        step_x = (d * fx - b * fy) / det
        step_y = (a * fy - c * fx) / det
        x -= step_x
        y -= step_y
        if abs(step_x) + abs(step_y) < 1e-15 * (1.0 + abs(x) + abs(y)):
            det = a * d - b * c
            return x, y, -b / det, a / det, True
    return x, y, 0.0, 0.0, False


@njit(cache=True, nogil=True)
def _triangulate_kernel(u, v, heading, intrinsics, dist, width, height, r_hc, c_h, n_c, d_c,
                        mount, min_range, max_range, sin_min_angle, pixel_sigma,
                        out_base, out_head, out_sigma, out_reason):
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    distorted = dist[0] != 0.0 or dist[1] != 0.0 or dist[2] != 0.0 or dist[3] != 0.0 \
        or dist[4] != 0.0
    nan = np.nan
    for i in range(u.shape[0]):
        reason = 0
        ui, vi, th = u[i], v[i], heading[i]
        if not (np.isfinite(ui) and np.isfinite(vi) and np.isfinite(th)):
            reason = 1
        elif ui < -0.5 or ui > width - 0.5 or vi < -0.5 or vi > height - 0.5:
            reason = 2
        x = (ui - cx) / fx
        y = (vi - cy) / fy
        dxdv = 0.0
        dydv = 1.0 / fy
        if reason == 0 and distorted:
            x, y, dx_dyd, dy_dyd, ok = undistort_normalized(x, y, dist)
            if not ok:
                reason = 3
            dxdv = dx_dyd / fy
            dydv = dy_dyd / fy
        if reason == 0:
            denom = n_c[0] * x + n_c[1] * y + n_c[2]
            norm = np.sqrt(x * x + y * y + 1.0)
            if abs(denom) < sin_min_angle * norm:
                reason = 4
            else:
                t = d_c / denom
                if t <= 0.0:
                    reason = 5
                else:
                    pcx, pcy, pcz = t * x, t * y, t
                    hx = r_hc[0, 0] * pcx + r_hc[0, 1] * pcy + r_hc[0, 2] * pcz + c_h[0]
                    hy = r_hc[1, 0] * pcx + r_hc[1, 1] * pcy + r_hc[1, 2] * pcz + c_h[1]
                    hz = r_hc[2, 0] * pcx + r_hc[2, 1] * pcy + r_hc[2, 2] * pcz + c_h[2]
                    rng = np.sqrt(hx * hx + hy * hy)
                    if rng < min_range:
                        reason = 6
                    elif rng > max_range:
                        reason = 7
                    else:
                        dt = -t * (n_c[0] * dxdv + n_c[1] * dydv) / denom
                        ex = dt * x + t * dxdv
                        ey = dt * y + t * dydv
                        ez = dt
                        out_sigma[i] = np.sqrt(ex * ex + ey * ey + ez * ez) * pixel_sigma
                        out_head[i, 0] = hx
                        out_head[i, 1] = hy
                        out_head[i, 2] = hz
                        c, s = np.cos(th), np.sin(th)
                        rx = c * hx - s * hy
                        ry = s * hx + c * hy
                        for k in range(3):
                            out_base[i, k] = (mount[k, 0] * rx + mount[k, 1] * ry
                                              + mount[k, 2] * hz + mount[k, 3])
        out_reason[i] = reason
        if reason != 0:
            out_sigma[i] = nan
            for k in range(3):
                out_head[i, k] = nan
                out_base[i, k] = nan


def triangulate(model: ScannerModel, u: np.ndarray, v: np.ndarray,
                heading: np.ndarray | float) -> Triangulation:
    """Points for pixels (u, v) seen at `heading` (rad; scalar or one per pixel)."""
    u = np.ascontiguousarray(u, dtype=np.float64).ravel()
    v = np.ascontiguousarray(v, dtype=np.float64).ravel()
    if u.shape != v.shape:
        raise ValueError(f"u and v differ in length: {u.shape[0]} != {v.shape[0]}")
    heading = np.ascontiguousarray(np.broadcast_to(np.asarray(heading, dtype=np.float64),
                                                   u.shape))
    n = u.shape[0]
    out_base = np.empty((n, 3))
    out_head = np.empty((n, 3))
    out_sigma = np.empty(n)
    out_reason = np.empty(n, dtype=np.uint8)
    _triangulate_kernel(u, v, heading, *_kernel_constants(model),
                        out_base, out_head, out_sigma, out_reason)
    return Triangulation(out_base, out_head, out_sigma, out_reason)


@functools.lru_cache(maxsize=32)
def _kernel_constants(model: ScannerModel) -> tuple:
    """The model reduced to the kernel's arguments (cached: models are frozen)."""
    cam = model.camera
    r_hc = model.camera_mount.rotation
    c_h = np.array(model.camera_mount.position)
    n_h = np.array(model.laser.normal)
    return (np.array([cam.fx, cam.fy, cam.cx, cam.cy]), cam.dist_coeffs, float(cam.width),
            float(cam.height), r_hc, c_h, r_hc.T @ n_h,
            float(n_h @ (np.array(model.laser.origin) - c_h)), model.head_mount.pose,
            model.min_range, model.max_range, float(np.sin(model.min_ray_plane_angle)),
            model.pixel_sigma)


def pixel_rays(model: ScannerModel, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """Camera centre and unit ray directions in `head` for pixels (u, v), distortion removed.

    Rays whose undistortion fails are NaN.
    """
    u = np.asarray(u, dtype=np.float64).ravel()
    v = np.asarray(v, dtype=np.float64).ravel()
    cam = model.camera
    x = (u - cam.cx) / cam.fx
    y = (v - cam.cy) / cam.fy
    dist = cam.dist_coeffs
    if np.any(dist != 0.0):
        x, y = _undistort_many(x, y, dist)
    rays = np.column_stack([x, y, np.ones_like(x)])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return np.array(model.camera_mount.position), rays @ model.camera_mount.rotation.T


@njit(cache=True, nogil=True)
def _undistort_many(xd: np.ndarray, yd: np.ndarray, dist: np.ndarray):
    x = np.empty_like(xd)
    y = np.empty_like(yd)
    for i in range(xd.shape[0]):
        xi, yi, _, _, ok = undistort_normalized(xd[i], yd[i], dist)
        x[i] = xi if ok else np.nan
        y[i] = yi if ok else np.nan
    return x, y


def project_head_points(model: ScannerModel, points_head: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of `head` points with OpenCV's distortion model (k1, k2, p1, p2, k3);
    NaN behind the camera. The formula of cv2.projectPoints, in numpy: the binding also
    builds the (2N x 14) Jacobian, most of its time on a scan's points (tested against it)."""
    cam = model.camera
    pose = model.camera_mount.pose
    local = np.einsum("ij,jk->ik", np.asarray(points_head, dtype=np.float64) - pose[:3, 3],
                      pose[:3, :3])  # without BLAS threads (see sim.geometry.rotate)
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = local[:, 0] / local[:, 2], local[:, 1] / local[:, 2]
    k1, k2, p1, p2, k3 = cam.distortion
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    pixels = np.column_stack([cam.fx * xd + cam.cx, cam.fy * yd + cam.cy])
    pixels[~(local[:, 2] > 0.0)] = np.nan
    return pixels
