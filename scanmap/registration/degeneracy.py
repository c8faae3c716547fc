"""Degeneracy: which pose directions the scan's geometry does not constrain.

The Gauss-Newton Hessian H = sum w J^T J of the point-to-plane residuals is the
information the geometry holds about the pose increment. Rotations are first scaled by
a lever arm L (the points' RMS range), so that an eigenvalue counts, in every direction,
the "well-aligned points" (weight w at lever arm L) constraining it. A direction whose
eigenvalue is below `min_constraint` such points is degenerate: a featureless corridor
along its axis, a round room about yaw. Following Zhang, Kaess and Singh (ICRA 2016,
"solution remapping"), the geometric information and gradient are projected out of the
degenerate subspace, so the prior (odometry) alone decides there instead of noise.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True, eq=False)
class Degeneracy:
    """Eigen-analysis of a scaled Hessian and the projector onto its constrained subspace.

    eigenvalues (k,) ascending, in well-aligned points (already divided by the weight of
    one). eigenvectors (k, k): their columns in the scaled space. degenerate (k,) bool.
    scale (k,): the parameter scaling used.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    degenerate: np.ndarray
    scale: np.ndarray

    @cached_property
    def directions(self) -> np.ndarray:
        """(k, k) unit columns in the unscaled parameter space, matching eigenvalues, each
        with its largest component positive (stable reports). Only reports need them:
        Gauss-Newton's projection does not, and it runs every iteration."""
        directions = self.eigenvectors / self.scale[:, None]
        directions /= np.linalg.norm(directions, axis=0)
        signs = np.sign(directions[np.argmax(np.abs(directions), axis=0),
                                   range(len(self.eigenvalues))])
        signs[signs == 0] = 1.0
        return directions * signs

    @property
    def degenerate_directions(self) -> np.ndarray:
        """(m, k) unit rows: the directions the geometry does not constrain."""
        return self.directions[:, self.degenerate].T

    def project(self, hessian: np.ndarray, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(H, g) with the degenerate subspace removed (in the unscaled parameters)."""
        if not self.degenerate.any():
            return hessian, gradient
        good = self.eigenvectors[:, ~self.degenerate]
        projector = good @ good.T
        d = self.scale
        h_scaled = hessian / np.outer(d, d)
        g_scaled = gradient / d
        h_kept = projector @ h_scaled @ projector
        g_kept = projector @ g_scaled
        return h_kept * np.outer(d, d), g_kept * d


def analyse_degeneracy(hessian: np.ndarray, unit_weight: float, lever_arm: float,
                       rotation_mask: np.ndarray, min_constraint: float) -> Degeneracy:
    """Degeneracy of `hessian` (k x k, parameters with rotations where rotation_mask).

    unit_weight: the information of one well-aligned point (mean inlier weight).
    lever_arm: metres per radian for the scaling (points' RMS range).
    """
    hessian = np.asarray(hessian, dtype=np.float64)
    scale = np.where(rotation_mask, max(lever_arm, 1e-3), 1.0)
    scaled = hessian / np.outer(scale, scale) / max(unit_weight, 1e-300)
    values, vectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
    return Degeneracy(values, vectors, values < min_constraint, scale)
