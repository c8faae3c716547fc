"""TUM trajectory I/O and the ATE / relative error measures, against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.evaluation.trajectory_errors import (
    _mean_gaussian_length,
    align_points,
    ate_rmse,
    relative_errors,
    shared_error,
)
from scanmap.io.trajectory import Trajectory, read_tum, write_tum
from scanmap_driver.errors import MapError
from scanmap_driver.transforms import make_pose, rot_x, rot_y, rot_z, se2_to_pose


def _random_poses(rng, n, scale=10.0):
    return np.array([make_pose(rot_z(a) @ rot_y(b) @ rot_x(c), rng.uniform(-scale, scale, 3))
                     for a, b, c in rng.uniform(-np.pi, np.pi, (n, 3))])


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), offset=st.sampled_from([0.0, 1e4, -3e5]))
def test_tum_round_trip_is_exact(tmp_path_factory, seed, offset):
    rng = np.random.default_rng(seed)
    poses = _random_poses(rng, 7)
    poses[:, :3, 3] += offset
    trajectory = Trajectory(1.7e9 + np.arange(7) * 0.1, poses)
    path = tmp_path_factory.mktemp("tum") / "t.txt"
    write_tum(path, trajectory)
    back = read_tum(path)
    np.testing.assert_allclose(back.times, trajectory.times, atol=1e-6)
    np.testing.assert_allclose(back.poses, poses, atol=1e-9)


@pytest.mark.parametrize("text, fragment", [
    ("0 1 2 3 0 0 0\n", ":1: expected 8 fields"),
    ("# c\n0 1 2 3 0 0 0 x\n", ":2: non-numeric"),
    ("0 1 2 3 0 0 0 2\n", ":1: quaternion norm"),
    ("0 nan 2 3 0 0 0 1\n", ":1: non-finite"),
])
def test_bad_tum_files_name_the_line(tmp_path, text, fragment):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(MapError, match=fragment):
        read_tum(path)


def test_missing_tum_file(tmp_path):
    with pytest.raises(MapError, match="file not found"):
        read_tum(tmp_path / "none.txt")


def test_alignment_recovers_a_known_transform():
    rng = np.random.default_rng(3)
    points = rng.uniform(-5, 5, (50, 3))
    truth = make_pose(rot_z(0.7) @ rot_x(0.2), [3.0, -1.0, 2.0])
    target = points @ truth[:3, :3].T + truth[:3, 3]
    np.testing.assert_allclose(align_points(points, target, "se3"), truth, atol=1e-9)
    planar = se2_to_pose(1.0, 2.0, -2.5)
    planar[2, 3] = 0.4
    target = points @ planar[:3, :3].T + planar[:3, 3]
    np.testing.assert_allclose(align_points(points, target, "se2"), planar, atol=1e-9)
    # A mirror image is not a rotation: the alignment must stay proper.
    mirrored = points * [1, -1, 1]
    assert np.linalg.det(align_points(points, mirrored, "se3")[:3, :3]) == pytest.approx(1.0)


def test_ate_of_a_shifted_noisy_trajectory():
    rng = np.random.default_rng(5)
    reference = _random_poses(rng, 400)
    noise = rng.normal(0, 0.01, (400, 3))
    estimate = reference.copy()
    estimate[:, :3, 3] += noise
    moved = np.einsum("ij,njk->nik", se2_to_pose(5.0, -3.0, 1.0), estimate)
    expected = np.sqrt(np.mean(np.sum((noise - noise.mean(0)) ** 2, axis=1)))
    assert ate_rmse(moved, reference, "se2") == pytest.approx(expected, rel=0.02)
    assert ate_rmse(moved, reference, "se3") == pytest.approx(expected, rel=0.02)
    assert ate_rmse(moved, reference, "none") > 1.0


def test_relative_error_of_a_scaled_straight_line():
    xs = np.arange(0.0, 20.0, 0.25)
    reference = np.array([se2_to_pose(x, 0.0, 0.0) for x in xs])
    estimate = np.array([se2_to_pose(1.02 * x, 0.0, 0.0) for x in xs])
    errors = relative_errors(estimate, reference, 1.0)
    assert len(errors.translation) == len(xs) - 4
    np.testing.assert_allclose(errors.translation, 0.02, atol=1e-12)
    np.testing.assert_allclose(errors.rotation, 0.0, atol=1e-7)
    assert errors.per_metre == pytest.approx(0.02)
    assert errors.mean_translation == pytest.approx(0.02)


def test_relative_error_sees_a_heading_error_along_a_segment():
    # Same positions, heading 0.01 rad * i: the 1 m motion from pose i is seen turned by
    # 0.01 * i, a chord error of 2 sin(0.005 i), and the heading changes by 0.02 per metre.
    xs = np.arange(0.0, 5.0, 0.5)
    reference = np.array([se2_to_pose(x, 0.0, 0.0) for x in xs])
    estimate = np.array([se2_to_pose(x, 0.0, 0.01 * i) for i, x in enumerate(xs)])
    errors = relative_errors(estimate, reference, 1.0)
    i = np.arange(len(xs) - 2)
    np.testing.assert_allclose(errors.rotation, 0.02, atol=1e-9)
    np.testing.assert_allclose(errors.translation, 2 * np.sin(0.005 * i), atol=1e-9)


def _wander(rng, n, step=0.5):
    """A planar path: steps of `step` m with random turns."""
    x = y = theta = 0.0
    poses = []
    for _ in range(n):
        poses.append(se2_to_pose(x, y, theta))
        theta += rng.normal(0.0, 0.3)
        x, y = x + step * np.cos(theta), y + step * np.sin(theta)
    return np.array(poses)


def _jitter(rng, poses, sigma, sigma_heading):
    """Each pose moved by independent Gaussian noise (m, rad) in its own frame."""
    return np.array([p @ se2_to_pose(*rng.normal(0.0, sigma, 2), rng.normal(0.0, sigma_heading))
                     for p in poses])


def test_shared_error_finds_the_error_of_a_noisy_reference():
    # The reference is the truth with per-pose noise; two estimates are the truth with
    # larger, independent noise. What their errors share is what the truth itself scores.
    rng = np.random.default_rng(3)
    truth = _wander(rng, 4000)
    reference = _jitter(rng, truth, 0.015, 0.004)
    first, second = (_jitter(rng, truth, s, 0.008) for s in (0.03, 0.04))
    against = [relative_errors(e, reference, 1.0) for e in (first, second)]
    truth_score = relative_errors(truth, reference, 1.0).mean_translation
    assert shared_error(*against) == pytest.approx(truth_score, rel=0.15)  # ~10% scatter
    assert min(a.mean_translation for a in against) > 2 * truth_score  # each alone overstates


def test_shared_error_of_independent_errors_against_a_perfect_reference_is_small():
    rng = np.random.default_rng(4)
    truth = _wander(rng, 4000)
    first, second = (relative_errors(_jitter(rng, truth, 0.03, 0.008), truth, 1.0)
                     for _ in range(2))
    assert shared_error(first, second) < 0.25 * first.mean_translation


def test_shared_error_needs_the_same_segments():
    rng = np.random.default_rng(5)
    truth = _wander(rng, 40)
    with pytest.raises(MapError, match="same segments"):
        shared_error(relative_errors(truth, truth, 1.0), relative_errors(truth[:20], truth[:20]))


@pytest.mark.parametrize(("sigmas", "expected"), [
    ((1.0, 0.0, 0.0), np.sqrt(2 / np.pi)),        # half-normal
    ((2.0, 2.0, 0.0), 2.0 * np.sqrt(np.pi / 2)),  # Rayleigh
    ((1.0, 1.0, 1.0), 2.0 * np.sqrt(2 / np.pi)),  # Maxwell
])
def test_mean_gaussian_length_matches_closed_forms(sigmas, expected):
    assert _mean_gaussian_length(np.array(sigmas)) == pytest.approx(expected, rel=5e-4)


def test_mismatched_trajectories_are_refused():
    with pytest.raises(MapError, match="both be"):
        ate_rmse(np.zeros((3, 4, 4)), np.zeros((4, 4, 4)))
    with pytest.raises(MapError, match="poses must be"):
        Trajectory(np.zeros(3), np.zeros((2, 4, 4)))
