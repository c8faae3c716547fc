"""One registration: align a prepared scan to the local map, recover, judge the outcome.

The judgement is what keeps garbage out of the map: too few points, too few matches
(no overlap), a non-finite or implausibly large correction (divergence) are reported as
such, with the prior's pose, instead of a pose that merely minimised something.

The matcher also judges itself against the prior: a correction the prior's covariance
makes implausible (beyond `consistency_level`) is either odometry's failure (a slip, a
bump) or the matcher's (a wrong minimum: aliasing, a poor map). The map decides: only
if it fits the scan clearly better at the matched pose than at the prior's (the coarse
search's likelihood score, independent of ICP's cost) does the match stand; otherwise
the scan keeps the prior's pose, reported INCONSISTENT, and stays out of the map.
"""

from __future__ import annotations

import numpy as np

from scanmap.registration.chi_square import chi_square_quantile
from scanmap.registration.config import RegistrationConfig
from scanmap.registration.icp import ALL_AXES, Alignment, align
from scanmap.registration.lie import PLANAR_AXES, between
from scanmap.registration.local_map import LocalMap
from scanmap.registration.preprocess import Source
from scanmap.registration.prior import Prior
from scanmap.registration.recovery import coarse_search, pose_scores
from scanmap.registration.result import RegistrationResult, RegistrationStatus

_RECOVERY_GAIN = 0.1  # the coarse search must beat the guess's score by this much
_ACCEPT_GAIN = 0.05  # and the search's alignment must beat the first one's by this much


def register_scan(source: Source, local_map: LocalMap, prior: Prior, threshold: float,
                  config: RegistrationConfig, expected_fitness: float = 0.0
                  ) -> RegistrationResult:
    """Register `source` against `local_map`; the result's pose is map-local.

    expected_fitness: the fitness recent scans registered with (0: unknown); below
    `config.recovery_drop` of it, as below `config.recovery_fitness`, a coarse search
    looks for a better start; ICP from there wins if it matches more points and the
    map's likelihood score (independent of ICP's cost) prefers it."""
    if len(source) < config.min_points:
        return _failure(prior, RegistrationStatus.TOO_FEW_POINTS, len(source),
                        f"{len(source)} source points after filtering, need "
                        f"{config.min_points}")
    best = align(source, local_map, prior.pose, prior, threshold, config)
    recovered = False
    if _fitness(best, source) < max(config.recovery_fitness,
                                    config.recovery_drop * expected_fitness):
        start, score, guess_score = coarse_search(source, local_map, prior.pose, config)
        if score > guess_score + _RECOVERY_GAIN:
            second = align(source, local_map, start, prior, threshold, config)
            if second.finite and _fitness(second, source) > _fitness(best, source):
                found, kept = pose_scores(source, local_map, [second.pose, best.pose], config)
                if found > kept + _ACCEPT_GAIN:
                    best, recovered = second, True
    fitness = _fitness(best, source)
    if not best.finite:
        return _failure(prior, RegistrationStatus.DIVERGED, len(source),
                        "the solution is not finite")
    if fitness < config.min_fitness:
        return _failure(prior, RegistrationStatus.NO_OVERLAP, len(source),
                        f"only {fitness:.0%} of the points match the map "
                        f"(need {config.min_fitness:.0%})", fitness)
    correction = between(prior.pose, best.pose)
    moved, turned = np.linalg.norm(correction[:3]), np.linalg.norm(correction[3:])
    if moved > config.max_correction or turned > config.max_rotation:
        return _failure(prior, RegistrationStatus.DIVERGED, len(source),
                        f"correction of {moved:.2f} m, {np.degrees(turned):.0f} deg from the "
                        "guess is beyond max_correction / max_rotation", fitness)
    axes = PLANAR_AXES if config.planar else ALL_AXES
    distance2 = float(correction[axes] @ prior.information(axes) @ correction[axes])
    if distance2 > chi_square_quantile(config.consistency_level, len(axes)):
        matched, guessed = pose_scores(source, local_map, [best.pose, prior.pose], config)
        if matched < guessed + _RECOVERY_GAIN:
            return _failure(prior, RegistrationStatus.INCONSISTENT, len(source),
                            f"correction {np.sqrt(distance2):.1f} sigma from the prior, and "
                            f"the map fits it no better (score {matched:.2f} against "
                            f"{guessed:.2f})", fitness)
    directions = np.zeros((int(best.degeneracy.degenerate.sum()), 6))
    directions[:, axes] = best.degeneracy.degenerate_directions
    return RegistrationResult(pose=best.pose, covariance=best.covariance,
                              status=RegistrationStatus.OK,
                              fitness=fitness, inlier_rmse=best.inlier_rmse,
                              degenerate_directions=directions, iterations=best.iterations,
                              recovered=recovered, num_points=len(source),
                              message="recovered by coarse search" if recovered else "")


def _fitness(alignment: Alignment, source: Source) -> float:
    return alignment.inliers / max(len(source), 1)


def _failure(prior: Prior, status: RegistrationStatus, num_points: int, message: str,
             fitness: float = float("nan")) -> RegistrationResult:
    return RegistrationResult(pose=prior.pose.copy(), covariance=prior.covariance.copy(),
                              status=status, fitness=fitness, num_points=num_points,
                              message=message)
