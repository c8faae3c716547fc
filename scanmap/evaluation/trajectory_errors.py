"""Trajectory error measures against a reference.

ATE (absolute trajectory error, RMSE of positions after an optional SE(2)/SE(3)
alignment: Umeyama/Horn least squares) and relative errors over segments of a given
travelled length (1 m by default), which measure local drift without alignment.

A reference that is itself an estimate (the corrected poses of a real log) has errors
of its own, which every estimate scored against it inherits. `shared_error` measures
them: what two independent estimates' relative errors have in common is the reference's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from scanmap_driver.errors import MapError
from scanmap_driver.transforms import invert_pose, make_pose

Alignment = Literal["se3", "se2", "none"]


def align_points(source: np.ndarray, target: np.ndarray, mode: Alignment = "se3") -> np.ndarray:
    """4x4 rigid transform T minimising sum |T source_i - target_i|^2 (Umeyama, no scale).

    mode "se2" rotates about z only (and translates in x, y, z); "none" returns identity.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if mode == "none":
        return np.eye(4)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise MapError(f"align_points: need two (N, 3) arrays, got {source.shape} and "
                       f"{target.shape}")
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    dims = 2 if mode == "se2" else 3
    cross = (target - mu_t)[:, :dims].T @ (source - mu_s)[:, :dims]
    u, _, vt = np.linalg.svd(cross)
    fix = np.eye(dims)
    fix[-1, -1] = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = np.eye(3)
    rotation[:dims, :dims] = u @ fix @ vt
    return make_pose(rotation, mu_t - rotation @ mu_s)


def ate_rmse(estimate: np.ndarray, reference: np.ndarray, align: Alignment = "se3") -> float:
    """RMSE (m) of positions of (N, 4, 4) `estimate` against `reference` after alignment."""
    estimate, reference = _matched(estimate, reference)
    transform = align_points(estimate[:, :3, 3], reference[:, :3, 3], align)
    moved = estimate[:, :3, 3] @ transform[:3, :3].T + transform[:3, 3]
    return float(np.sqrt(np.mean(np.sum((moved - reference[:, :3, 3]) ** 2, axis=1))))


@dataclass(frozen=True)
class RelativeErrors:
    """Errors of relative motions over segments of (about) `length` metres of travel.

    vectors (K, 3) m: translation of the error of the motion from pose i to pose j (in
    pose i's reference frame), with j the first pose at least `length` further along the
    reference path; translation (K,) m: their lengths; rotation (K,) rad: the error's
    angle. travelled (K,): the reference path length of each segment.
    """

    length: float
    vectors: np.ndarray
    rotation: np.ndarray
    travelled: np.ndarray

    @property
    def translation(self) -> np.ndarray:
        """(K,) translational error of each segment (m)."""
        return np.linalg.norm(self.vectors, axis=1)

    @property
    def mean_translation(self) -> float:
        """Mean translational error (m) of the segments (NaN if none)."""
        return float(self.translation.mean()) if self.translation.size else float("nan")

    @property
    def per_metre(self) -> float:
        """Translational drift: total segment error over total segment length (m/m)."""
        return float(self.translation.sum() / self.travelled.sum()) if self.travelled.size \
            else float("nan")


def relative_errors(estimate: np.ndarray, reference: np.ndarray,
                    length: float = 1.0) -> RelativeErrors:
    """Relative pose errors over every segment of `length` m of reference travel."""
    estimate, reference = _matched(estimate, reference)
    if length <= 0:
        raise MapError(f"relative_errors: length must be positive, got {length}")
    steps = np.linalg.norm(np.diff(reference[:, :3, 3], axis=0), axis=1)
    distance = np.concatenate([[0.0], np.cumsum(steps)])
    ends = np.searchsorted(distance, distance + length, side="left")
    starts = np.flatnonzero(ends < len(distance))
    ends = ends[starts]
    vectors, rot = np.zeros((starts.size, 3)), np.zeros(starts.size)
    for k, (i, j) in enumerate(zip(starts, ends, strict=True)):
        ref_motion = invert_pose(reference[i]) @ reference[j]
        est_motion = invert_pose(estimate[i]) @ estimate[j]
        error = invert_pose(ref_motion) @ est_motion
        vectors[k] = error[:3, 3]
        rot[k] = np.arccos(np.clip((np.trace(error[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
    return RelativeErrors(length, vectors, rot, distance[ends] - distance[starts])


def shared_error(first: RelativeErrors, second: RelativeErrors) -> float:
    """Mean translational error (m) the two estimates' relative errors have in common.

    Each estimate's error against the reference is its own error minus the reference's.
    When the two estimates err independently of each other, the mean of the product
    first.vectors x second.vectors^T is the second moment of the reference's error alone;
    this returns the mean length of a zero-mean Gaussian with that second moment: what a
    perfect estimate would score against this reference. Estimates whose errors share a
    cause (the same scans, the same kind of matcher) make it an upper bound.
    """
    if first.vectors.shape != second.vectors.shape or not first.vectors.size:
        raise MapError(f"shared_error: need relative errors over the same segments, got "
                       f"{first.vectors.shape} and {second.vectors.shape}")
    moment = first.vectors.T @ second.vectors / len(first.vectors)
    variances = np.linalg.eigvalsh((moment + moment.T) / 2.0)
    return _mean_gaussian_length(np.sqrt(np.clip(variances, 0.0, None)))


def _mean_gaussian_length(sigmas: np.ndarray) -> float:
    """E|x| for x ~ N(0, diag(sigmas^2)) in 3-D.

    x = diag(sigmas) r u with r = |z| (chi, 3 dof, mean 2 sqrt(2/pi)) independent of the
    direction u, uniform on the sphere: E|x| = E[r] E|diag(sigmas) u|, the second a smooth
    integral over the sphere (Gauss-Legendre in cos(theta), uniform in phi).
    """
    cos_theta, weights = np.polynomial.legendre.leggauss(48)
    phi = (np.arange(96) + 0.5) * (2.0 * np.pi / 96)
    sin_theta = np.sqrt(1.0 - cos_theta ** 2)
    u = np.stack([np.outer(sin_theta, np.cos(phi)), np.outer(sin_theta, np.sin(phi)),
                  np.outer(cos_theta, np.ones_like(phi))])
    stretched = np.sqrt(np.tensordot(np.asarray(sigmas) ** 2, u ** 2, axes=1))
    direction_mean = float(weights @ stretched.mean(axis=1)) / 2.0
    return 2.0 * np.sqrt(2.0 / np.pi) * direction_mean


def _matched(estimate: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    estimate = np.asarray(estimate, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if estimate.shape != reference.shape or estimate.shape[1:] != (4, 4):
        raise MapError(f"trajectories must both be (N, 4, 4), got {estimate.shape} and "
                       f"{reference.shape}")
    if len(estimate) == 0:
        raise MapError("trajectories are empty")
    return estimate, reference
