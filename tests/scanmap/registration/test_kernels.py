"""Each Numba kernel of registration against its plain-numpy reference."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap.registration.config import RegistrationConfig
from scanmap.registration.deskew import deskew_points
from scanmap.registration.icp import ALL_AXES, PLANAR_AXES, _gauss_newton, evaluate
from scanmap.registration.lie import pose_exp
from scanmap.registration.local_map import BLOB, LINE, LocalMap
from scanmap.registration.planes import PLANE, eigen_sym2, eigen_sym3, fit_voxel
from scanmap.registration.preprocess import prepare_source
from scanmap.registration.prior import OdometryNoiseConfig, Prior
from scanmap.registration.recovery import (
    _NEAR_BEST,
    _block_bounds,
    _pruned_scores,
    _shift_scores,
    distance_to_occupied,
)
from scanmap.registration.voxel_hash import (
    COORD_LIMIT,
    build_table,
    first_per_voxel,
    grown,
    key_coords,
    new_table,
    table_find,
    table_insert,
    voxel_key,
)
from scanmap_driver.transforms import make_pose, rot_x, rot_z, se2_to_pose
from tests.scanmap.registration import reference
from tests.scanmap.registration.scenes import corridor, make_scan, office

coords = st.integers(-COORD_LIMIT + 1, COORD_LIMIT - 1)


@given(coords, coords, coords)
def test_voxel_key_round_trips(ix, iy, iz):
    key = voxel_key(ix, iy, iz)
    assert key >= 0
    assert key_coords(key) == (ix, iy, iz)


def test_voxel_key_refuses_out_of_range():
    assert voxel_key(COORD_LIMIT, 0, 0) == -1
    assert voxel_key(0, -COORD_LIMIT, 0) == -1


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(coords, coords, coords), min_size=1, max_size=300))
def test_hash_table_behaves_like_a_dict(cells):
    keys, values = new_table(4)
    expected = {}
    for i, cell in enumerate(cells):
        if 2 * (len(expected) + 1) > keys.size:
            keys, values = grown(keys, values)
        key = voxel_key(*cell)
        expected.setdefault(key, i)
        assert table_insert(keys, values, key, i) == expected[key]
    for key, value in expected.items():
        assert table_find(keys, values, key) == value
    assert table_find(keys, values, voxel_key(COORD_LIMIT - 1, 5, 5)) in (
        -1, expected.get(voxel_key(COORD_LIMIT - 1, 5, 5)))
    unique = np.array(list(expected))
    keys2, values2 = build_table(unique)
    assert [table_find(keys2, values2, k) for k in unique] == list(range(len(unique)))


def first_per_voxel_by_sorting(points, voxel):
    """first_per_voxel's plain definition: np.unique on the voxels of the finite points."""
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    if not finite.size:
        return finite
    cells = np.floor(points[finite] / voxel).astype(np.int64)
    _, first = np.unique(cells - cells.min(axis=0), axis=0, return_index=True)
    return finite[np.sort(first)]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 400),
       voxel=st.sampled_from([0.01, 0.05, 0.3]),
       far=st.sampled_from([0.0, 3.0e4]), bad=st.floats(0.0, 0.3))
def test_first_per_voxel_matches_its_plain_definition(seed, n, voxel, far, bad):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1.0, 1.0, (n, 3)) + far  # far from the origin too
    points[rng.random(n) < bad, rng.integers(0, 3)] = rng.choice([np.nan, np.inf, -np.inf])
    first, whole = first_per_voxel(points, voxel)
    assert whole
    np.testing.assert_array_equal(first, first_per_voxel_by_sorting(points, voxel))


def test_first_per_voxel_says_when_points_span_too_many_voxels():
    points = np.array([[0.0, 0.0, 0.0], [COORD_LIMIT * 0.01 + 1.0, 0.0, 0.0]])
    assert not first_per_voxel(points, 0.01)[1]


symmetric = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6)


@given(symmetric)
def test_eigen_sym3_matches_lapack(v):
    m = np.array([[v[0], v[1], v[2]], [v[1], v[3], v[4]], [v[2], v[4], v[5]]])
    l0, l1, l2, *n = eigen_sym3(v[0], v[1], v[2], v[3], v[4], v[5])
    values, vectors = np.linalg.eigh(m)
    # The trigonometric solution loses digits near a double root (acos of -1 or 1): 1e-7
    # of the matrix scale, far below the thickness-to-spread ratios the fits test.
    np.testing.assert_allclose([l0, l1, l2], values, atol=1e-7 * max(1.0, np.abs(v).max()))
    if values[1] - values[0] > 1e-3:  # a well separated smallest eigenvalue: unique vector
        assert abs(abs(np.dot(n, vectors[:, 0])) - 1.0) < 1e-8


@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_eigen_sym2_matches_lapack(a, b, c):
    small, large, nx, ny = eigen_sym2(a, b, c)
    values, vectors = np.linalg.eigh(np.array([[a, b], [b, c]]))
    np.testing.assert_allclose([small, large], values, atol=1e-9)
    if values[1] - values[0] > 1e-6:
        assert abs(abs(nx * vectors[0, 0] + ny * vectors[1, 0]) - 1.0) < 1e-6


def _stats(points, variance=1e-6):
    squares = np.array([points[:, 0] @ points[:, 0], points[:, 0] @ points[:, 1],
                        points[:, 0] @ points[:, 2], points[:, 1] @ points[:, 1],
                        points[:, 1] @ points[:, 2], points[:, 2] @ points[:, 2]])
    return len(points), points.sum(axis=0), squares, variance * len(points)


def _fit(points, scans_2d=False, variance=1e-6):
    normal, line = np.zeros(3), np.zeros(3)
    n, sums, squares, noise = _stats(points, variance)
    flags, _, _, _ = fit_voxel(n, sums, squares, noise, 0.1, 4, 0.1, scans_2d, normal, line)
    return flags, normal, line


def test_fit_tells_walls_floors_and_corners_apart():
    rng = np.random.default_rng(0)
    u = rng.uniform(-0.05, 0.05, (40, 2))
    wall = np.column_stack([0.8 * u[:, 0], -0.6 * u[:, 0], u[:, 1]])  # normal (0.6, 0.8, 0)
    flags, normal, line = _fit(wall)
    assert flags == PLANE | LINE
    assert abs(abs(line @ [0.6, 0.8, 0.0]) - 1) < 1e-9
    assert abs(abs(normal[:2] @ [0.6, 0.8]) - 1) < 1e-6
    floor = np.column_stack([u, np.zeros(40)])
    assert _fit(floor)[0] == PLANE  # a plane, but no wall: it does not rise
    corner = np.vstack([np.column_stack([u[:20, 0], np.zeros(20), u[:20, 1]]),
                        np.column_stack([np.zeros(20), u[20:, 0], u[20:, 1]])])
    assert _fit(corner)[0] == 0
    stripe = np.column_stack([0.8 * u[:, 0], -0.6 * u[:, 0], 1.7 * u[:, 0]])  # one laser line
    assert _fit(stripe)[0] == LINE  # a wall's trace, though no plane in 3-D
    scan_2d = np.column_stack([u[:, 0], 0.3 * u[:, 0], np.full(40, 0.3)])
    assert _fit(scan_2d, scans_2d=False)[0] == 0  # flat: not a wall of a 3-D scan
    assert _fit(scan_2d, scans_2d=True)[0] == LINE


def test_a_2d_scan_s_points_that_are_no_line_are_a_blob_with_their_spread():
    """2-D scans only: a corner (or a post) is still a place in the plane; its narrowest
    and widest spread are the eigen-pairs of its horizontal covariance."""
    rng = np.random.default_rng(3)
    u = rng.uniform(-0.05, 0.05, 40)
    corner = np.column_stack([np.r_[u[:20], np.zeros(20)], np.r_[np.zeros(20), u[20:]],
                              np.full(40, 0.3)])
    line = np.zeros(3)
    n, sums, squares, noise = _stats(corner)
    flags, _, narrow, wide = fit_voxel(n, sums, squares, noise, 0.1, 4, 0.1, True,
                                       np.zeros(3), line)
    values, vectors = np.linalg.eigh(np.cov(corner[:, :2].T, bias=True))
    assert flags == BLOB
    np.testing.assert_allclose([narrow, wide], values, atol=1e-12)
    assert abs(abs(line[:2] @ vectors[:, 0]) - 1) < 1e-9
    assert not _fit(corner, scans_2d=False)[0] & BLOB  # never on a 3-D scan
    wall = np.column_stack([u, 0.3 * u, np.full(40, 0.3)])
    assert _fit(wall, scans_2d=True)[0] == LINE  # a line is a wall, never a blob


def test_fit_thickness_must_be_explained_by_noise():
    rng = np.random.default_rng(1)
    u = rng.uniform(-0.05, 0.05, (60, 2))
    thick = np.column_stack([u[:, 0], rng.normal(0, 0.006, 60), u[:, 1]])
    assert _fit(thick, variance=0.006 ** 2)[0] & LINE  # 6 mm noise, 6 mm thick: a wall
    assert not _fit(thick, variance=0.001 ** 2)[0] & LINE  # 1 mm noise: not a wall


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 1000), st.floats(-0.3, 0.3))
def test_deskew_matches_scipy(seed, turn):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-4, 4, (200, 3))
    times = np.sort(rng.uniform(10.0, 12.0, 200))
    motion = make_pose(rot_z(turn) @ rot_x(0.05), [0.4, -0.1, 0.02])
    ours = deskew_points(points, times, motion, 10.0, 12.0)
    np.testing.assert_allclose(ours, reference.deskew(points, times, motion, 10.0, 12.0),
                               atol=1e-10)
    np.testing.assert_allclose(deskew_points(points, times, motion, 12.0, 10.0), points)


def test_prepare_source_matches_reference():
    rng = np.random.default_rng(2)
    scan = make_scan(corridor(), (3.0, 0.1, 0.2), rng, columns=120, rows=30)
    config = RegistrationConfig()
    source = prepare_source(scan.points, config, scan.range_sigma)
    points = scan.points.astype(np.float64)
    r = np.hypot(points[:, 0], points[:, 1])
    keep = (r >= config.min_range) & (r <= config.max_range) & (points[:, 2] >= 0.05)
    points, r, sigma2 = points[keep], r[keep], scan.range_sigma[keep].astype(np.float64) ** 2
    groups = reference.group_by_voxel(points, config.voxel_size)
    inside, expected = [], []
    for cell, idx in groups.items():
        margin = 3 * np.sqrt(sigma2[idx].mean())
        if r[idx].mean() + margin > config.max_range or r[idx].mean() - margin < 0.3:
            continue  # within noise of a range limit: neither matched nor mapped
        inside.append(idx)
        near = reference.neighbourhood(groups, cell)
        thin, long, _, zz = reference.wall_fit(points[near])
        limit = min(0.1 * long, 9 * sigma2[near].mean() + 0.002 ** 2)
        is_wall = thin <= limit and long >= 0.02 ** 2 / 12 and zz >= 0.02 ** 2 / 12
        if len(near) < config.min_plane_points or is_wall:
            expected.append(points[near].mean(axis=0))
    assert 0 < len(np.concatenate(inside)) < len(points)
    np.testing.assert_allclose(np.sort(source.cloud, axis=0),
                               np.sort(points[np.concatenate(inside)], axis=0))
    expected = np.array(expected)
    assert 100 < len(source) == len(expected)
    np.testing.assert_allclose(np.sort(source.points, axis=0), np.sort(expected, axis=0),
                               atol=1e-9)


def test_local_map_planes_match_reference():
    rng = np.random.default_rng(3)
    scan = make_scan(corridor(), (5.0, 0.0, 0.0), rng, columns=150, rows=30)
    points = scan.points.astype(np.float64) + [5.0, 0.0, 0.0]
    variance = scan.range_sigma.astype(np.float64) ** 2
    local_map = LocalMap(voxel_size=0.1, max_count=10 ** 6)
    local_map.insert(points, 1, variance)
    groups = reference.group_by_voxel(points, 0.1)
    assert len(local_map) == len(groups)
    checked = 0
    for slot in range(len(local_map)):
        cell = key_coords(local_map.voxel_keys[slot])
        near = reference.neighbourhood(groups, cell)
        np.testing.assert_allclose(local_map.means[slot], points[near].mean(axis=0), atol=1e-9)
        if local_map.flags[slot] & LINE:
            _, _, normal, _ = reference.wall_fit(points[near])
            assert abs(abs(normal @ local_map.line_normals[slot]) - 1) < 1e-6
            checked += 1
    assert checked > 50


def _beams(ranges: np.ndarray, step_deg: float = 1.0) -> np.ndarray:
    """A 2-D laser scan's points (z = 0) for `ranges` over consecutive beams."""
    angles = np.radians(step_deg * np.arange(len(ranges)) - 45.0)
    return np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles),
                            np.zeros(len(ranges))])


def test_sparse_2d_walls_get_lines_from_a_wider_square():
    """A 2-D laser's far wall puts about one beam in each 10 cm voxel: the face neighbours
    hold too few points to fit a line, so the wider square in the scan plane judges it
    (numpy reference); a corner inside that square is still no line."""
    angles = np.radians(0.5 * np.arange(180) - 45.0)
    wall = 8.0 / np.cos(angles)  # a wall 8 m ahead, beams 0.5 deg apart: 7-14 cm on it
    rng = np.random.default_rng(5)
    points = _beams(wall + rng.normal(0, 0.005, wall.size), 0.5)
    corner = np.array([[6.0 + 0.12 * i, 0.03, 0.0] for i in range(4)]
                      + [[6.03, 0.12 * i + 0.15, 0.0] for i in range(3)])
    points = np.vstack([points[np.abs(points[:, 1]) > 1.0], corner])
    local_map = LocalMap(voxel_size=0.1, max_count=10 ** 6, radius=20.0, flatness=0.3,
                         scans_2d=True)
    local_map.insert(points, 1, 2.5e-5)
    groups = reference.group_by_voxel(points, 0.1)
    lines = 0
    for slot in range(len(local_map)):
        cell = key_coords(local_map.voxel_keys[slot])
        near = reference.neighbourhood(groups, cell)
        if len(near) < 4:
            near = reference.square_neighbourhood(groups, cell, 2)
        np.testing.assert_allclose(local_map.means[slot], points[near].mean(axis=0), atol=1e-9)
        on_corner = abs(points[near, 0] - 6.0).max() < 0.5
        assert bool(local_map.flags[slot] & LINE) == (not on_corner and len(near) >= 4)
        lines += bool(local_map.flags[slot] & LINE)
        if local_map.flags[slot] & LINE:
            _, _, normal, _ = reference.wall_fit(points[near])
            assert abs(abs(normal @ local_map.line_normals[slot]) - 1) < 1e-6
            assert abs(local_map.line_normals[slot][0]) > 0.99  # the wall faces the sensor
    assert lines > 40


def test_normal_equations_match_reference():
    rng = np.random.default_rng(4)
    config = RegistrationConfig()
    local_map = LocalMap()
    pose0 = se2_to_pose(4.0, 0.05, 0.03)
    scan0 = make_scan(corridor(), (4.0, 0.05, 0.03), rng)
    local_map.insert(prepare_source(scan0.points, config).cloud @ pose0[:3, :3].T
                     + pose0[:3, 3], 1)
    scan = make_scan(corridor(), (4.3, 0.0, 0.0), rng)
    source = prepare_source(scan.points, config, scan.range_sigma)
    n = len(local_map)
    cells = np.array([key_coords(k) for k in local_map.voxel_keys[:n]])
    for pose, threshold in ((se2_to_pose(4.32, 0.01, 0.01), 0.08), (se2_to_pose(4.2, 0, 0), 0.2)):
        ours = evaluate(source, local_map, pose, threshold, config)
        rings = 1 if threshold <= local_map.voxel_size else 2
        theirs = reference.normal_equations(
            source.points, source.normals, source.variance, pose, cells, local_map.means[:n],
            local_map.line_normals[:n], local_map.line_var[:n],
            (local_map.flags[:n] & LINE) > 0, 0.1, rings, 1, threshold, threshold / 3,
            config.sigma_floor ** 2, np.cos(config.max_normal_angle))
        assert ours[2][0] == theirs[2][0] > 100  # the same inliers
        for a, b in zip(ours, theirs, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())


def corners_and_wall_scan(pose: tuple[float, float, float], rng: np.random.Generator,
                          beams: int = 720) -> np.ndarray:
    """A 2-D laser scan (points at 0.3 m, base_link) from `pose` of a wall at y = 3 and
    five box corners (two 0.15 m faces each): their pooled points are no line (BLOB).
    Exact ray-segment intersections, 5 mm range noise."""
    segments = [((-8.0, 3.0), (8.0, 3.0))]
    for cx, cy in ((1.5, 1.0), (2.5, -1.2), (-1.0, 2.0), (-2.0, -1.5), (0.5, -2.5)):
        sx, sy = -np.sign(cx) * 0.15, -np.sign(cy) * 0.15  # faces towards the origin
        segments += [((cx, cy), (cx + sx, cy)), ((cx, cy), (cx, cy + sy))]
    x, y, yaw = pose
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    d = np.column_stack([np.cos(angles + yaw), np.sin(angles + yaw)])
    ranges = np.full(beams, np.inf)
    for a, b in segments:
        e = np.subtract(b, a)
        w = np.subtract(a, (x, y))
        det = d[:, 0] * -e[1] + d[:, 1] * e[0]
        ok = np.abs(det) > 1e-12
        det = np.where(ok, det, 1.0)
        t = (w[0] * -e[1] + w[1] * e[0]) / det
        u = (d[:, 0] * w[1] - d[:, 1] * w[0]) / det
        hit = ok & (t > 0) & (u >= 0) & (u <= 1) & (t < ranges)
        ranges = np.where(hit, t, ranges)
    ranges = ranges + rng.normal(0.0, 0.005, beams)
    keep = ranges < 8.0
    return np.column_stack([np.cos(angles[keep]) * ranges[keep],
                            np.sin(angles[keep]) * ranges[keep], np.full(keep.sum(), 0.3)])


def test_normal_equations_match_reference_with_blobs():
    """2-D scans of box corners: points matched to a corner's blob give two residuals each
    (its narrowest and widest spread), the wall's points one."""
    rng = np.random.default_rng(6)
    config = RegistrationConfig.for_2d_scans()
    local_map = LocalMap(scans_2d=True, flatness=config.flatness)
    for k in range(3):
        pose = se2_to_pose(0.05 * k, 0.0, 0.0)
        cloud = prepare_source(corners_and_wall_scan((0.05 * k, 0.0, 0.0), rng), config).cloud
        local_map.insert(cloud, k + 1, 1e-4, pose)
    n = len(local_map)
    assert (local_map.flags[:n] & BLOB).any() and (local_map.flags[:n] & LINE).any()
    source = prepare_source(corners_and_wall_scan((0.2, 0.03, 0.02), rng), config)
    cells = np.array([key_coords(k) for k in local_map.voxel_keys[:n]])
    pose = se2_to_pose(0.21, 0.02, 0.015)
    for threshold in (0.08, 0.3):
        ours = evaluate(source, local_map, pose, threshold, config)
        theirs = reference.normal_equations(
            source.points, source.normals, source.variance, pose, cells, local_map.means[:n],
            local_map.line_normals[:n], local_map.line_var[:n],
            (local_map.flags[:n] & LINE) > 0, 0.1, 1 if threshold <= 0.1 else 2, 1,
            threshold, threshold / 3, config.sigma_floor ** 2,
            np.cos(config.max_normal_angle), (local_map.flags[:n] & BLOB) > 0,
            local_map.spread_var[:n])
        assert ours[2][0] == theirs[2][0] > ours[2][4] == theirs[2][4] > 20  # blobs: 2 each
        for a, b in zip(ours, theirs, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())


def _gauss_newton_case(case: str):
    """(source, local map, start, prior, config, axes) of a registration: a 2-D laser
    scan of a wall and box corners (lines and blobs), a featureless corridor (degenerate
    along its axis), an office in SE(3) (all six axes)."""
    rng = np.random.default_rng(7)
    if case == "2-D blobs":
        config = RegistrationConfig.for_2d_scans()
        local_map = LocalMap(scans_2d=True, flatness=config.flatness)
        for k in range(3):
            cloud = prepare_source(corners_and_wall_scan((0.05 * k, 0.0, 0.0), rng),
                                   config).cloud
            local_map.insert(cloud, k + 1, 1e-4, se2_to_pose(0.05 * k, 0.0, 0.0))
        source = prepare_source(corners_and_wall_scan((0.2, 0.03, 0.02), rng), config)
        start = se2_to_pose(0.25, 0.0, 0.0)
    else:
        config = RegistrationConfig(planar=case != "SE(3) office")
        scene = corridor(with_features=False) if case == "featureless corridor" else office()
        local_map = LocalMap(config.map_voxel_size, config.map_radius, config.map_max_count,
                             config.min_plane_points, config.flatness)
        for k, pose in enumerate([(0.0, 0.0, 0.2), (0.15, 0.0, 0.22)]):
            scan = make_scan(scene, pose, rng)
            t = se2_to_pose(*pose)
            local_map.insert(prepare_source(scan.points, config, scan.range_sigma).cloud
                             @ t[:3, :3].T + t[:3, 3], k + 1)
        scan = make_scan(scene, (0.3, 0.02, 0.25), rng)
        source = prepare_source(scan.points, config, scan.range_sigma)
        start = se2_to_pose(0.34, -0.01, 0.23) @ pose_exp(
            np.array([0.0, 0.0, 0.02, 0.01, -0.01, 0.0]) * (not config.planar))
    prior = Prior(start, OdometryNoiseConfig().odometry_covariance(se2_to_pose(0.3, 0, 0)))
    return source, local_map, start, prior, config, PLANAR_AXES if config.planar else ALL_AXES


@pytest.mark.parametrize("case", ["2-D blobs", "featureless corridor", "SE(3) office"])
def test_gauss_newton_matches_its_reference(case):
    """The compiled loop takes the reference's steps: the same iterations, the same pose
    to rounding, through the degenerate projection and the noise scale alike."""
    source, local_map, start, prior, config, axes = _gauss_newton_case(case)
    lever = float(np.sqrt(np.mean(np.sum(source.points[:, :2] ** 2, axis=1))))
    degenerate = []
    for threshold in (0.08, 0.3):
        ours = _gauss_newton(source, local_map, start, prior, threshold, config, axes, lever)
        theirs = reference.gauss_newton(source, local_map, start, prior, threshold, config,
                                        axes, lever)
        assert ours[1] == theirs[1] > 1
        np.testing.assert_allclose(ours[0], theirs[0], rtol=0, atol=1e-10)
        assert np.abs(ours[0] - start).max() > 1e-3  # it moved
        hessian, _, stats = evaluate(source, local_map, ours[0], threshold, config)
        degenerate.append(reference.analyse_degeneracy(
            hessian[np.ix_(axes, axes)], stats[3] / max(stats[0], 1.0), lever,
            np.isin(axes, [3, 4, 5]), config.min_constraint).degenerate.any())
    assert any(degenerate) == (case == "featureless corridor")


def test_gauss_newton_reports_a_step_that_is_not_finite():
    """A prior whose information is NaN: the loop stops at once with a NaN pose, as the
    reference does, and `align` reports it as not finite."""
    source, local_map, start, prior, config, axes = _gauss_newton_case("2-D blobs")

    class NanPrior:
        pose = prior.pose

        @staticmethod
        def information(axes):
            return np.full((len(axes), len(axes)), np.nan)

    for run in (_gauss_newton, reference.gauss_newton):
        pose, iterations = run(source, local_map, start, NanPrior, 0.3, config, axes, 10.0)
        assert iterations == 1 and np.isnan(pose).all()


@pytest.mark.parametrize("shifts", [0, 3])
def test_shift_scores_match_reference(shifts):
    rng = np.random.default_rng(5)
    grid = rng.uniform(0, 1, (30, 25))
    cells = rng.integers(-2, 32, (50, 2))
    np.testing.assert_allclose(_shift_scores(grid, cells, shifts),
                               reference.shift_scores(grid, cells, shifts), atol=1e-12)



@settings(max_examples=200, deadline=None)
@given(st.data())
def test_branch_and_bound_scores_every_shift_the_exhaustive_search_would_keep(data):
    """Each block's bound is at least every score in it, and the pruned scores equal the
    exhaustive ones wherever given, and are given wherever a score is within _NEAR_BEST of
    the yaw's best and at least the floor (what the search's choice depends on)."""
    shape = data.draw(st.tuples(st.integers(1, 40), st.integers(1, 40)))
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 32 - 1)))
    grid = rng.uniform(0, 1, shape).astype(np.float32) ** data.draw(st.sampled_from([1, 8]))
    shifts, block = data.draw(st.integers(0, 7)), data.draw(st.integers(1, 5))
    cells = rng.integers(-10, 50, (data.draw(st.integers(1, 3)),
                                   data.draw(st.integers(1, 40)), 2))
    floor = data.draw(st.floats(0.0, 1.0))
    pooled = cv2.dilate(grid, np.ones((block, block), np.uint8), anchor=(0, 0),
                        borderType=cv2.BORDER_CONSTANT, borderValue=0.0)
    bounds = _block_bounds(pooled, cells, shifts, block)
    for i in range(len(cells)):
        exhaustive = _shift_scores(grid, cells[i], shifts)
        for p in range(bounds.shape[1]):
            for q in range(bounds.shape[2]):
                inside = exhaustive[p * block:(p + 1) * block, q * block:(q + 1) * block]
                assert bounds[i, p, q] >= inside.max()
        pruned = _pruned_scores(grid, cells[i], shifts, block, bounds[i], floor)
        given_ = pruned > -np.inf
        np.testing.assert_array_equal(pruned[given_], exhaustive[given_])
        needed = (exhaustive >= _NEAR_BEST * exhaustive.max()) & (exhaustive >= floor)
        assert given_[needed].all()


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_coarse_search_distances_match_scipy(data):
    """The coarse search's distance to the nearest map voxel (OpenCV) against scipy's exact
    Euclidean distance transform."""
    from scipy.ndimage import distance_transform_edt

    shape = data.draw(st.tuples(st.integers(1, 50), st.integers(1, 50)))
    cells = data.draw(st.lists(st.tuples(st.integers(0, shape[0] - 1),
                                         st.integers(0, shape[1] - 1)), min_size=1))
    occupied = np.zeros(shape, bool)
    occupied[tuple(np.array(cells).T)] = True
    np.testing.assert_allclose(distance_to_occupied(occupied),
                               distance_transform_edt(~occupied), rtol=1e-6, atol=1e-5)
