"""Each Numba kernel of the simulator against a plain-numpy reference."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.special import erf

from scanmap_driver import reference_scanner
from scanmap_driver.sim.geometry import NO_HIT, plane_distance, transform_per_frame
from scanmap_driver.sim.hitmap import cast_rows, fill_between_rows
from scanmap_driver.sim.laser_light import WINDOW, draw_stripes
from scanmap_driver.sim.laser_stripe import camera_rays
from scanmap_driver.sim.motion_blur import blur_along_flow, rotation_flow
from scanmap_driver.sim.shading import DIRECT_SHARE, shade_scene
from scanmap_driver.sim.texture import (
    COARSE_CELL,
    COARSE_WEIGHT,
    FINE_CELL,
    LATTICE,
    TABLE,
    surface_axes,
    texture_factor,
)
from scanmap_driver.triangulation import project_head_points


def _noise_reference(x, y):
    ix, iy = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    tx, ty = x - ix, y - iy
    sx, sy = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
    x0, y0, x1, y1 = ix % LATTICE, iy % LATTICE, (ix + 1) % LATTICE, (iy + 1) % LATTICE
    bottom = (1 - sx) * TABLE[x0, y0] + sx * TABLE[x1, y0]
    top = (1 - sx) * TABLE[x0, y1] + sx * TABLE[x1, y1]
    return (1 - sy) * bottom + sy * top


def _texture_reference(a, b, contrast):
    n = COARSE_WEIGHT * _noise_reference(a / COARSE_CELL, b / COARSE_CELL) \
        + (1 - COARSE_WEIGHT) * _noise_reference(a / FINE_CELL + 17.0, b / FINE_CELL + 31.0)
    return 1.0 + contrast * (2.0 * n - 1.0)


def test_texture_matches_numpy_and_stays_in_range():
    rng = np.random.default_rng(0)
    points = rng.uniform(-30, 30, (5000, 3))
    normals = np.array([[0, 0, 1.0], [0.6, 0.8, 0.0], [-1.0, 0.0, 0.0]])
    axes = surface_axes(normals)
    plane = rng.integers(0, 3, 5000)
    got = texture_factor(points, plane, axes, 0.3)
    a = np.einsum("ij,ij->i", axes[plane, 0], points)
    b = np.einsum("ij,ij->i", axes[plane, 1], points)
    np.testing.assert_allclose(got, _texture_reference(a, b, 0.3), rtol=1e-6)
    assert got.min() >= 0.7 and got.max() <= 1.3 and abs(got.mean() - 1.0) < 0.02
    # the axes lie in their planes and are orthonormal
    np.testing.assert_allclose(np.einsum("pij,pj->pi", axes, normals), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pij,pkj->pik", axes, axes),
                               np.broadcast_to(np.eye(2), (3, 2, 2)), atol=1e-12)


def test_plane_distance_matches_numpy():
    rng = np.random.default_rng(1)
    planes = np.column_stack([rng.normal(size=(6, 3)), rng.normal(size=6)])
    planes[:, :3] /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    plane = rng.integers(-1, 6, 200).astype(np.int32)
    origins, directions = rng.normal(size=(200, 3)), rng.normal(size=(200, 3))
    got = plane_distance(planes, plane, origins, directions)
    p = planes[np.maximum(plane, 0)]
    want = (p[:, 3] - (p[:, :3] * origins).sum(1)) / (p[:, :3] * directions).sum(1)
    want[plane == NO_HIT] = np.inf
    np.testing.assert_allclose(got, want, rtol=1e-12)


def _fill_reference(plane, t, rows, planes_head, centre, directions):
    plane, t = plane.copy(), t.copy()
    todo = np.zeros(plane.shape, dtype=bool)
    for r0, r1 in itertools.pairwise(rows):
        between = slice(r0 + 1, r1)
        same = plane[r0] == plane[r1]
        todo[between] = ~same[None, :]
        p = np.broadcast_to(plane[r0], plane[between].shape)
        d = directions[between]
        n = planes_head[np.maximum(p, 0)]
        fill = (n[..., 3] - n[..., :3] @ centre) / (n[..., :3] * d).sum(-1)
        fill[p == NO_HIT] = np.inf
        keep = np.broadcast_to(same[None, :], fill.shape)
        plane[between] = np.where(keep, p, plane[between])
        t[between] = np.where(keep, fill, t[between])
    return plane, t, todo


def test_fill_between_rows_matches_numpy():
    model = reference_scanner()
    rays = camera_rays(model)
    rng = np.random.default_rng(2)
    planes_head = np.array([[1.0, 0.0, 0.0, 3.0], [0.0, 0.0, 1.0, 0.0], [0.6, 0.8, 0.0, 2.0]])
    rows = cast_rows(480, 5)
    plane = np.full((480, 640), -7, dtype=np.int32)
    t = np.full((480, 640), -1.0)
    plane[rows] = rng.integers(-1, 3, (rows.size, 640)).astype(np.int32)
    t[rows] = 1.0
    want = _fill_reference(plane, t, rows, planes_head, rays.centre, rays.directions)
    todo = fill_between_rows(plane, t, rows, planes_head, rays.centre, rays.directions)
    np.testing.assert_array_equal(todo, want[2])
    np.testing.assert_array_equal(plane[~todo], want[0][~todo])
    np.testing.assert_allclose(t[~todo], want[1][~todo], rtol=1e-12)


def test_rotation_flow_matches_finite_differences_of_the_projection():
    model = reference_scanner()
    rays = camera_rays(model)
    rng = np.random.default_rng(3)
    t = rng.uniform(0.2, 6.0, (480, 640))
    flow = rotation_flow(t, rays.directions, rays.centre, model.camera_mount.rotation,
                         model.camera.fx, model.camera.fy)
    points = (rays.centre + t[..., None] * rays.directions).reshape(-1, 3)
    step = 1e-6

    def turned(angle):  # a point fixed outside the head, seen after the head turns by angle
        c, s = np.cos(-angle), np.sin(-angle)
        return np.column_stack([c * points[:, 0] - s * points[:, 1],
                                s * points[:, 0] + c * points[:, 1], points[:, 2]])

    numeric = (project_head_points(model, turned(step))
               - project_head_points(model, turned(-step))) / (2 * step)
    np.testing.assert_allclose(flow.reshape(-1, 2), numeric, rtol=1e-4, atol=1e-2)
    # Far points move about f px per radian along v (the rows), little along u.
    assert np.median(np.abs(flow[..., 1])) == pytest.approx(model.camera.fy, rel=0.1)


def _blur_reference(image, flow, offsets, samples=4000):
    """Dense sampling of each pixel's path along v (rows piecewise constant, the edge row
    beyond the image), then the mean drift along u by linear interpolation."""
    height, width, _ = image.shape
    boxed = np.zeros_like(image, dtype=np.float64)
    fractions = (np.arange(samples) + 0.5) / samples
    for row in range(height):
        for col in range(width):
            for a, b in itertools.pairwise(offsets[row]):
                v = row - flow[row, col, 1] * (a + fractions * (b - a))
                rows = np.clip(np.floor(v + 0.5), 0, height - 1).astype(int)
                boxed[row, col] += image[rows, col].mean(0)
            boxed[row, col] /= offsets.shape[1] - 1
    out = np.empty_like(boxed)
    for row in range(height):
        u = np.clip(np.arange(width) - flow[row, :, 0] * offsets[row].mean(), 0, width - 1)
        for c in range(image.shape[2]):
            out[row, :, c] = np.interp(u, np.arange(width), boxed[row, :, c])
    return out


def test_blur_along_flow_matches_dense_sampling():
    rng = np.random.default_rng(4)
    image = rng.random((12, 9, 2)).astype(np.float32)
    # paths of 0.4 to 9 px along v, partly leaving the image
    speed = rng.uniform(100, 300, (12, 9)) * rng.choice([-1, 1], (12, 9))
    flow = np.stack([rng.uniform(-40, 40, (12, 9)), speed], axis=-1).astype(np.float32)
    offsets = np.cumsum(rng.uniform(0.004, 0.015, (12, 3)), axis=1) - 0.015
    got = blur_along_flow(image, flow, offsets)
    np.testing.assert_allclose(got, _blur_reference(image, flow, offsets), atol=2e-3)


def test_blur_without_motion_is_the_identity():
    image = np.random.default_rng(5).random((6, 7, 3)).astype(np.float32)
    got = blur_along_flow(image, np.ones((6, 7, 2), np.float32), np.zeros((6, 2)))
    np.testing.assert_array_equal(got, image)


def test_shade_scene_matches_numpy():
    rng = np.random.default_rng(6)
    height, width = 5, 7
    directions = rng.normal(size=(height, width, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    normals = rng.normal(size=(4, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    axes = surface_axes(normals)
    albedo = rng.random((4, 3))
    plane = rng.integers(-1, 4, (height, width)).astype(np.int32)
    t = rng.uniform(0.5, 3, (height, width))
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                         [0, 0, 1.0]])
    shift, centre = np.array([1.0, 2.0, 0.0]), np.array([-0.07, 0.0, 1.0])
    light = np.array([0.0, 0.6, 0.8])
    got = shade_scene(plane, t, directions, centre, rotation, shift, normals, axes, albedo,
                      light, 0.5, 0.3)
    points = (centre + t[..., None] * directions) @ rotation.T + shift
    p = np.maximum(plane, 0)
    n = normals[p]
    facing = (n * light).sum(-1)
    back = (n * (directions @ rotation.T)).sum(-1) > 0
    facing = np.where(back, -facing, facing)
    level = 0.5 * (1 - DIRECT_SHARE + DIRECT_SHARE * np.maximum(facing, 0))
    a = (axes[p, 0] * points).sum(-1)
    b = (axes[p, 1] * points).sum(-1)
    want = (level * _texture_reference(a, b, 0.3))[..., None] * albedo[p]
    want[plane == NO_HIT] = 0
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)


@settings(max_examples=40, deadline=None)
@given(v0=st.floats(20, 50), sweep=st.floats(-6, 6), sigma=st.floats(0.8, 3.0))
@example(v0=20.0, sweep=6.103515625e-05, sigma=1.0)  # a sweep too short to integrate
def test_draw_stripes_matches_the_swept_gaussian(v0, sweep, sigma):
    layer = np.zeros((80, 3), dtype=np.float32)
    grain = np.ones((1, WINDOW), dtype=np.float32)
    draw_stripes(layer, np.array([1]), np.array([v0]), np.array([v0 + sweep]),
                 np.array([2.0]), np.array([sigma]), grain)
    rows = np.arange(80.0)
    a, b = min(v0, v0 + sweep), max(v0, v0 + sweep)
    if b - a < 1e-3:
        # a sweep this short is the still Gaussian at its middle (at v0 it is off by up
        # to 5e-4 px, 1e-4 in the profile)
        want = 2.0 * np.exp(-0.5 * ((rows - 0.5 * (a + b)) / sigma) ** 2)
    else:
        want = 2.0 * sigma * np.sqrt(np.pi / 2) / (b - a) * (
            erf((rows - a) / (np.sqrt(2) * sigma)) - erf((rows - b) / (np.sqrt(2) * sigma)))
    inside = (rows >= np.floor(a - 4 * sigma)) & (rows <= np.ceil(b + 4 * sigma))
    np.testing.assert_allclose(layer[:, 1], np.where(inside, want, 0.0), atol=1e-5)
    assert np.all(layer[:, [0, 2]] == 0)
    # the drawn light's centroid is the sweep's middle
    centroid = (layer[:, 1] * rows).sum() / layer[:, 1].sum()
    assert centroid == pytest.approx(0.5 * (a + b), abs=0.02)


def test_transform_per_frame_matches_numpy():
    rng = np.random.default_rng(7)
    poses = np.tile(np.eye(4), (5, 1, 1))
    for pose in poses:
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        pose[:3, :3], pose[:3, 3] = q, rng.normal(size=3)
    frame = rng.integers(0, 5, 300)
    vectors = rng.normal(size=(300, 3))
    rotated = np.einsum("nij,nj->ni", poses[frame, :3, :3], vectors)
    np.testing.assert_allclose(transform_per_frame(poses, frame, vectors, False), rotated,
                               rtol=1e-12)
    np.testing.assert_allclose(transform_per_frame(poses, frame, vectors, True),
                               rotated + poses[frame, :3, 3], rtol=1e-12)
