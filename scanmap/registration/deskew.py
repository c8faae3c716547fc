"""De-skew: move each point of a scan to where it would be seen from the scan's start pose.

A scan takes about 2 s; a robot driving at 0.5 m/s moves 1 m meanwhile, so points are
each in `base_link` at their own time. Given the motion of `base_link` from the first
frame (t0) to the last (t1) (from odometry, or a constant-velocity prediction), the
motion to time t is interpolated at s = (t - t0) / (t1 - t0) with constant velocity
(rotation vector and translation scaled by s: `lie.pose_log`), and point p seen at t moves to
T(s) p in `base_link` at t0.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from scanmap.registration.lie import pose_log


def deskew_points(points: np.ndarray, times: np.ndarray, motion: np.ndarray,
                  t0: float, t1: float) -> np.ndarray:
    """(N, 3) float64 points in base_link at t0; `motion` is base_link(t1) in base_link(t0).

    Times outside [t0, t1] are clamped; t1 <= t0 or a non-finite motion leaves points as
    they are (in float64).
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    times = np.ascontiguousarray(times, dtype=np.float64).reshape(-1)
    twist = deskew_twist(motion, t0, t1)
    inv_span = 1.0 / (t1 - t0) if t1 > t0 else 0.0
    return _deskew_kernel(points, times, float(t0), inv_span, twist)


def deskew_twist(motion: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """(translation, rotation vector) of the scan's motion per unit of s (zeros if unknown)."""
    if not (t1 > t0) or not np.isfinite(motion).all():
        return np.zeros(6)
    return pose_log(motion)


@njit(cache=True, nogil=True)
def motion_at(s, twist):
    """The interpolated motion at fraction s: (cos a, sin a, axis (3), translation (3))."""
    wx, wy, wz = s * twist[3], s * twist[4], s * twist[5]
    angle = math.sqrt(wx * wx + wy * wy + wz * wz)
    if angle == 0.0:
        return 1.0, 0.0, 0.0, 0.0, 1.0, s * twist[0], s * twist[1], s * twist[2]
    return (math.cos(angle), math.sin(angle), wx / angle, wy / angle, wz / angle,
            s * twist[0], s * twist[1], s * twist[2])


@njit(cache=True, nogil=True)
def apply_motion(px, py, pz, m):
    """Point moved by a `motion_at` tuple (Rodrigues rotation, then translation)."""
    c, sn, ax, ay, az, tx, ty, tz = m
    kp = (ax * px + ay * py + az * pz) * (1.0 - c)
    return (px * c + (ay * pz - az * py) * sn + ax * kp + tx,
            py * c + (az * px - ax * pz) * sn + ay * kp + ty,
            pz * c + (ax * py - ay * px) * sn + az * kp + tz)


@njit(cache=True, nogil=True)
def scan_fraction(t, t0, inv_span):
    """s in [0, 1] of time t within the scan (0 for a non-finite time)."""
    if not math.isfinite(t):
        return 0.0
    return min(1.0, max(0.0, (t - t0) * inv_span))


@njit(cache=True, nogil=True)
def _deskew_kernel(points, times, t0, inv_span, twist):
    out = np.empty_like(points)
    last_s = 0.0
    m = motion_at(0.0, twist)
    for i in range(points.shape[0]):
        s = scan_fraction(times[i], t0, inv_span)
        if s != last_s:  # points of one frame share a time: one sin/cos per frame
            m = motion_at(s, twist)
            last_s = s
        out[i, 0], out[i, 1], out[i, 2] = apply_motion(points[i, 0], points[i, 1],
                                                       points[i, 2], m)
    return out
