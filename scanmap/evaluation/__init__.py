"""Errors against a reference: the simulator's ground truth (`ground_truth`: ranges,
headings, trajectory, map) and trajectory measures (`trajectory_errors`: ATE, relative
error, the error a noisy reference shares). See docs/architecture.md."""

from scanmap.evaluation.ground_truth import (
    heading_errors,
    map_errors,
    range_errors,
    trajectory_errors,
)
from scanmap.evaluation.trajectory_errors import (
    RelativeErrors,
    align_points,
    ate_rmse,
    relative_errors,
    shared_error,
)

__all__ = ["RelativeErrors", "align_points", "ate_rmse", "heading_errors", "map_errors",
           "range_errors", "relative_errors", "shared_error", "trajectory_errors"]
