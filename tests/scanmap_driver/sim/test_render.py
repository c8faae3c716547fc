"""Rendered frames: the laser where the truth says, truth that triangulates back exactly."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap_driver import reference_scanner, triangulate
from scanmap_driver.sim import Scene, builtin_scene, plan_scans
from scanmap_driver.sim.camera_effects import SimCameraConfig
from scanmap_driver.sim.laser_stripe import head_poses, points_from_fan
from scanmap_driver.sim.render import LaserAppearance, Renderer
from scanmap_driver.sim.scene import LIGHTING
from scanmap_driver.transforms import transform_points
from scanmap_driver.triangulation import project_head_points

from .scene_sdf import surface_distance

MODEL = reference_scanner()


@pytest.fixture(scope="module")
def office():
    scene = builtin_scene("office").with_ambient(LIGHTING["dark"])
    return scene, plan_scans(scene, MODEL, seed=2, count=2)[1]


def _check_truth_triangulates_back(scene, truth):
    stripe = truth.stripe
    result = triangulate(MODEL, stripe.u, stripe.v, stripe.heading)
    assert result.valid.sum() >= 0.9 * len(stripe)
    ok = result.valid
    np.testing.assert_allclose(result.points_base[ok], stripe.base[ok], atol=1e-6, rtol=0)
    # ... and the true points lie on the scene's surfaces (an independent analytic model)
    assert surface_distance(scene, stripe.map).max() < 5e-4


@pytest.mark.parametrize("frame", [8, 30, 47])
def test_laser_pixels_of_the_truth_mask_triangulate_to_their_true_points(office, frame):
    """The issue's done-when test: renderer and scanner model agree exactly."""
    scene, plan = office
    rendered = Renderer(scene, MODEL).render(plan, frame, np.random.default_rng(frame))
    truth = rendered.truth
    rows, cols = np.nonzero(truth.laser_mask)
    assert cols.size > 500
    stripe = truth.stripe
    lit = stripe.select(stripe.lit)
    # every masked pixel belongs to a lit stripe point of its column, within the profile
    for col in np.unique(cols)[::7]:
        centres = lit.v[lit.u == col]
        assert centres.size, f"column {col} is lit in the mask but has no truth"
        masked = rows[cols == col]
        assert np.abs(masked[:, None] - centres[None, :]).min(axis=1).max() < 12
    # the masked columns' truth triangulates back
    in_mask = np.isin(lit.u, cols)
    picked = lit.select(in_mask)
    result = triangulate(MODEL, picked.u, picked.v, picked.heading)
    np.testing.assert_allclose(result.points_base[result.valid], picked.base[result.valid],
                               atol=1e-6, rtol=0)
    assert result.valid.mean() > 0.9
    _check_truth_triangulates_back(scene, truth)
    # the delivered frame is what a webcam gives
    assert rendered.image.shape == (480, 640, 3) and rendered.image.dtype == np.uint8
    assert rendered.jpeg[:2] == b"\xff\xd8"


def _centroids(layer, stripe, half=6):
    """(u, v_true, centroid) for single, unclipped stripe points of a light layer."""
    out = []
    for u, v, lit in zip(stripe.u.astype(int), stripe.v, stripe.lit, strict=True):
        rows = np.arange(int(v) - half, int(v) + half + 1)
        if not lit or rows[0] < 0 or rows[-1] >= layer.shape[0] or (stripe.u == u).sum() > 1:
            continue
        profile = layer[rows, u].astype(np.float64)
        if profile.sum() > 0:
            out.append((u, v, (profile * rows).sum() / profile.sum()))
    return np.array(out)


def test_the_stripe_is_drawn_at_the_true_row(office):
    """Before the motor starts (no motion) and without speckle, the laser light's centroid on
    each column is the truth's subpixel row; through the camera (colour mosaic, gamma,
    JPEG) it stays within a fraction of a pixel."""
    scene, plan = office
    assert plan.motion.heading_at(plan.frame_times[0]) == plan.motion.heading_at(0.0)
    camera = SimCameraConfig(read_noise=0.0, full_well=1e12, exposure=0.004)
    renderer = Renderer(scene.with_ambient(0.0), MODEL, camera, LaserAppearance(speckle=0.0))
    light = renderer.light(plan, 0, np.random.default_rng(0))
    found = _centroids(light.laser, light.truth.stripe)
    assert len(found) > 300
    np.testing.assert_allclose(found[:, 2], found[:, 1], atol=0.01)
    image = renderer.render(plan, 0, np.random.default_rng(0)).image[:, :, 2] / 255.0
    linear = np.where(image <= 0.04045, image / 12.92, ((image + 0.055) / 1.055) ** 2.4)
    unsaturated = linear < 0.99
    seen = _centroids(np.where(unsaturated, linear, 0.0), light.truth.stripe)
    peaks = linear[np.round(seen[:, 1]).astype(int), seen[:, 0].astype(int)]
    seen = seen[(peaks > 0.05) & (seen[:, 0] < 540)]
    assert len(seen) > 100
    assert np.median(np.abs(seen[:, 2] - seen[:, 1])) < 0.15


def test_rolling_shutter_truth_uses_each_rows_heading(office):
    scene, plan = office
    camera = SimCameraConfig(rolling_shutter=0.03)
    truth = Renderer(scene, MODEL, camera).render(plan, 30, np.random.default_rng(1)).truth
    spread = truth.stripe.heading - truth.heading
    # rows 0..479 are read over 30 ms: at ~3 rad/s the headings span about 0.09 rad
    assert spread.max() - spread.min() > 0.03
    _check_truth_triangulates_back(scene, truth)


def test_rendering_is_deterministic_for_a_seed(office):
    scene, plan = office
    renderer = Renderer(scene, MODEL)
    a = renderer.render(plan, 20, np.random.default_rng(5))
    b = renderer.render(plan, 20, np.random.default_rng(5))
    c = renderer.render(plan, 20, np.random.default_rng(6))
    assert a.jpeg == b.jpeg and a.jpeg != c.jpeg


def test_ideal_mode_finds_the_same_stripe_as_the_renderer(office):
    scene, plan = office
    renderer = Renderer(scene, MODEL)
    for frame in (12, 33):
        truth = renderer.render(plan, frame, np.random.default_rng(0)).truth
        rendered = truth.stripe.select(truth.primary)
        cast = points_from_fan(renderer.world, MODEL, truth.base_pose[None],
                               np.array([truth.heading]))
        cast = cast.select(cast.strongest_per_column())
        common, ia, ib = np.intersect1d(rendered.u, cast.u, return_indices=True)
        assert common.size >= 0.97 * max(len(rendered), len(cast))
        same = np.abs(rendered.v[ia] - cast.v[ib]) < 1e-6
        assert same.mean() > 0.97


def test_motion_blurs_the_scene_and_sweeps_the_laser_as_the_geometry_says():
    """At full speed the scene is smeared along the image rows by the head's turn; the
    laser co-rotates, so it only sweeps by as much as its row moves between the shutter
    opening and closing, which the laser fan cast at those headings tells independently."""
    scene = builtin_scene("corridor").with_ambient(LIGHTING["bright"])
    plan = plan_scans(scene, MODEL, seed=0, count=1)[0]
    fastest = int(np.argmax(np.diff(plan.frame_headings)))
    camera = SimCameraConfig(exposure=0.02)
    renderer = Renderer(scene, MODEL, camera, LaserAppearance(speckle=0.0))
    still = renderer.light(plan, 0, np.random.default_rng(0))
    fast = renderer.light(plan, fastest, np.random.default_rng(0))
    green = [f.radiance[:, :500, 1] for f in (still, fast)]
    along_rows = [np.abs(np.diff(g, axis=0)).mean() for g in green]
    along_cols = [np.abs(np.diff(g, axis=1)).mean() for g in green]
    assert along_rows[1] < 0.5 * along_rows[0]  # smeared along v
    assert along_cols[1] > 0.6 * along_cols[0]  # much less across
    # the laser: width^2 = sigma^2 + sweep^2 / 12 for a uniform sweep
    truth = fast.truth
    time = truth.time
    ends = []
    for dt in (-0.5 * camera.exposure, 0.5 * camera.exposure):
        heading = plan.motion.heading_at(time + dt)
        cast = points_from_fan(renderer.world, MODEL, truth.base_pose[None], np.array([heading]))
        ends.append(cast.select(cast.strongest_per_column()))
    common, ia, ib = np.intersect1d(ends[0].u, ends[1].u, return_indices=True)
    sweep = dict(zip(common.astype(int), np.abs(ends[0].v[ia] - ends[1].v[ib]), strict=True))
    assert np.median(list(sweep.values())) > 2.0  # this frame's stripe does sweep
    checked = 0
    for u, v, _ in _centroids(fast.laser, truth.stripe, half=14):
        u = int(u)
        rows = np.arange(int(v) - 14, int(v) + 15)
        profile = fast.laser[rows, u].astype(np.float64)
        centre = (profile * rows).sum() / profile.sum()
        width = np.sqrt((profile * (rows - centre) ** 2).sum() / profile.sum())
        if u in sweep and u < 500 and sweep[u] < 16:
            sigma = 1.5  # corridor walls are beyond 0.7 m: defocus adds < 0.3 px
            expected = np.sqrt(sigma ** 2 + sweep[u] ** 2 / 12)
            assert width == pytest.approx(expected, abs=0.35)
            checked += 1
    assert checked > 100


def test_the_encoder_disk_shows_its_code_where_the_geometry_puts_it(office):
    """Sector centres of the disk (fixed in base_link) projected into a still frame: the
    rendered disk is white on '1' sectors and black on '0' sectors."""
    scene, plan = office
    renderer = Renderer(scene.with_ambient(0.0), MODEL)
    light = renderer.light(plan, 0, np.random.default_rng(0))
    disk = MODEL.encoder
    angles = disk.zero_offset + (np.arange(disk.sectors) + 0.5) * disk.sector_angle
    radius = 0.5 * (disk.inner_radius + disk.outer_radius)
    points = np.column_stack([radius * np.cos(angles), radius * np.sin(angles),
                              np.full(angles.size, disk.height)])
    _, base_head = head_poses(MODEL, np.eye(4)[None], np.array([light.truth.heading]))
    head = transform_points(np.linalg.inv(base_head[0]), points)
    pixels = project_head_points(MODEL, head)
    seen = []
    for (u, v), bit in zip(pixels, disk.bits(), strict=True):
        if not (0 <= u < 640 and 0 <= v < 480):
            continue
        col, row = round(float(u)), round(float(v))
        if light.disk[row, col] > 0.99:
            seen.append((bit, light.radiance[row, col, 1]))
    assert len(seen) >= 5  # more than the 5 sectors that fix the heading
    white = [value for bit, value in seen if bit == 1]
    black = [value for bit, value in seen if bit == 0]
    assert min(white, default=1.0) > 0.3 and max(black, default=0.0) < 0.1


def test_people_are_rendered_where_their_track_puts_them_at_each_scan():
    """A person 1 m ahead of the robot at scan 0, gone from scan 1: the frames of scan 0
    light them and those of scan 1 do not, and every lit point lies on the scene as that
    scan sees it (`Scene.at_scan`, the analytic surfaces)."""
    data = builtin_scene("people").to_dict()
    data["people"] = [{"radius": 0.2, "height": 1.7, "color": [90, 70, 160], "name": "p",
                       "track": [[0, 1.0, 0.0], [0.5, 1.0, 0.0], [1, 30.0, 0.0]]}]
    scene = Scene.from_dict(data)
    renderer = Renderer(scene, MODEL)
    on_person = []
    for plan in plan_scans(scene, MODEL, seed=0, count=2):
        lit = 0
        for frame in range(0, plan.frame_times.shape[0], 4):
            stripe = renderer.light(plan, frame, np.random.default_rng(frame)).truth.stripe
            points = stripe.select(stripe.lit).map
            assert surface_distance(scene.at_scan(plan.index), points).max() < 5e-3
            lit += int((np.abs(np.hypot(points[:, 0] - 1.0, points[:, 1]) - 0.2) < 5e-3).sum())
        on_person.append(lit)
    assert on_person[0] > 50 and on_person[1] == 0
