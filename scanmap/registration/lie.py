"""Pose increments: 6-vectors (translation, rotation vector) in the body frame.

Registration perturbs a pose on the right, T' = T * exp(delta), with the decoupled
exponential exp(rho, phi) = [Exp(phi) | rho]: rho moves the body along its own axes and
phi turns it about its own origin, so the lever arm of a rotation is a point's range
(metres), not its distance from a far map origin. Planar poses use (x, y, yaw) = the
components 0, 1, 5 of the 6-vector. `so3_exp` and `so3_log` are compiled (Numba, on float
arrays): the Gauss-Newton loop of `_kernels` calls them too.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

PLANAR_AXES = np.array([0, 1, 5])  # x, y, yaw inside (x, y, z, roll, pitch, yaw)


@njit(cache=True, nogil=True)
def so3_exp(phi: np.ndarray) -> np.ndarray:
    """3x3 rotation of a rotation vector (Rodrigues)."""
    angle = math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    rotation = np.eye(3)
    if angle < 1e-12:
        return rotation
    kx, ky, kz = phi[0] / angle, phi[1] / angle, phi[2] / angle
    skew = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    return rotation + math.sin(angle) * skew + (1.0 - math.cos(angle)) * (skew @ skew)


@njit(cache=True, nogil=True)
def so3_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector of a 3x3 rotation (angle in [0, pi])."""
    trace = rotation[0, 0] + rotation[1, 1] + rotation[2, 2]
    angle = math.acos(min(max((trace - 1.0) / 2.0, -1.0), 1.0))
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                     rotation[1, 0] - rotation[0, 1]])
    if angle < 1e-6:
        return 0.5 * axis
    if np.pi - angle < 1e-4:  # near pi the antisymmetric part vanishes: use the diagonal
        k = np.sqrt(np.maximum((np.diag(rotation) + 1.0) / 2.0, 0.0))
        i = int(np.argmax(k))
        k = (rotation[:, i] + np.eye(3)[:, i]) / (2.0 * k[i])
        return angle * k / math.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
    return angle / (2.0 * math.sin(angle)) * axis


def pose_exp(delta: np.ndarray) -> np.ndarray:
    """4x4 pose of a 6-vector (translation, rotation vector), decoupled."""
    pose = np.eye(4)
    pose[:3, :3] = so3_exp(delta[3:])
    pose[:3, 3] = delta[:3]
    return pose


def pose_log(pose: np.ndarray) -> np.ndarray:
    """6-vector (translation, rotation vector) of a 4x4 pose (inverse of `pose_exp`)."""
    return np.concatenate([pose[:3, 3], so3_log(pose[:3, :3])])


def retract(pose: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """pose * exp(delta) (a product of rotations stays orthonormal to rounding)."""
    return pose @ pose_exp(delta)


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """6-vector taking pose `a` to pose `b` in a's body frame: log(a^-1 b)."""
    rotation = a[:3, :3].T
    relative = np.eye(4)
    relative[:3, :3] = rotation @ b[:3, :3]
    relative[:3, 3] = rotation @ (b[:3, 3] - a[:3, 3])
    return pose_log(relative)


def transport(covariance: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Covariance (6x6) of a body-frame perturbation of a pose T, expressed at T @ step.

    T exp(d) step = T step exp(J d) to first order, with J = [[Rs^T, -Rs^T [ts]x],
    [0, Rs^T]] for step = (Rs, ts) and the decoupled `pose_exp`: an uncertain heading
    moves the point `step` ahead sideways.
    """
    rotation_t = step[:3, :3].T
    tx, ty, tz = step[:3, 3]
    skew = np.array([[0.0, -tz, ty], [tz, 0.0, -tx], [-ty, tx, 0.0]])
    jacobian = np.zeros((6, 6))
    jacobian[:3, :3] = rotation_t
    jacobian[:3, 3:] = -rotation_t @ skew
    jacobian[3:, 3:] = rotation_t
    return jacobian @ covariance @ jacobian.T
