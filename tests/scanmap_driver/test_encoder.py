"""Heading decoding: kernels against numpy, accuracy on forward-rendered disk frames, hard
cases, symmetric-code tracking, and the heading sequence helpers."""

from __future__ import annotations

import math
import threading
from dataclasses import fields, replace

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr

from scanmap_driver import encoder
from scanmap_driver.encoder import (
    EncoderConfig,
    code_period,
    coverage,
    decode_heading,
    fill_unreadable,
    laser_line_range,
    ring_geometry,
)
from scanmap_driver.encoder_disk import EncoderDisk
from scanmap_driver.errors import ScanError
from scanmap_driver.scanner_model import CameraIntrinsics, HeadMount, reference_scanner
from scanmap_driver.sim.synthetic_frames import disk_frame, srgb
from scanmap_driver.triangulation import project_head_points

MODEL = reference_scanner()


def heading_error(result, truth: float) -> float:
    return math.degrees(math.remainder(result.heading - truth, 2 * math.pi))


def decode_many(model, headings, rng, **render):
    errors, failures = [], []
    for theta in headings:
        result = decode_heading(disk_frame(model, theta, rng, **render), model)
        (errors.append(heading_error(result, theta)) if result.ok
         else failures.append(result.reason))
    return np.array(errors), failures


# ---------------------------------------------------------------- the test renderer itself


def test_renderer_projection_matches_opencv():
    model = MODEL.with_changes(camera=CameraIntrinsics(
        width=640, height=480, fx=1000.0, fy=1005.0, cx=322.0, cy=236.0,
        distortion=(-0.2, 0.05, 0.001, -0.002, 0.01)))
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0.0, 0.2, 200), rng.uniform(-0.05, 0.05, 200),
                           rng.uniform(0.85, 0.95, 200)])
    pose = model.camera_mount.pose
    cam_pts = (pts - pose[:3, 3]) @ pose[:3, :3]
    ref, _ = cv2.projectPoints(cam_pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                               model.camera.matrix, model.camera.dist_coeffs)
    assert np.allclose(project_head_points(model, pts), ref.reshape(-1, 2), atol=1e-6)


# ---------------------------------------------------------------- the ring's geometry

WHOLE_IMAGE_MODELS = {
    "reference": MODEL,
    "distorted": MODEL.with_changes(camera=CameraIntrinsics(
        width=640, height=480, fx=1000.0, fy=1005.0, cx=322.0, cy=236.0,
        distortion=(-0.2, 0.05, 0.001, -0.002, 0.01))),
    "small sensor": MODEL.with_changes(camera=CameraIntrinsics(
        width=320, height=240, fx=507.0, fy=507.0, cx=159.5, cy=119.5)),
    "rolled": MODEL.with_changes(camera_mount=replace(MODEL.camera_mount, roll=0.05)),
}


@pytest.mark.parametrize("name", WHOLE_IMAGE_MODELS)
def test_ring_geometry_on_the_disk_region_equals_the_whole_image(name):
    """The disk is located on every 8th pixel first; the geometry computed on that region
    is the one computed on every pixel of the image (the plain reference)."""
    model = WHOLE_IMAGE_MODELS[name]
    cam = model.camera
    whole = encoder._cached_ring_geometry(model, EncoderConfig(),
                                          (0, cam.height, 0, cam.width))
    fast = ring_geometry(model, EncoderConfig())
    row0, row1, col0, col1 = encoder.disk_region(model)
    assert (row1 - row0) * (col1 - col0) < 0.5 * cam.width * cam.height
    for field in fields(whole):
        assert np.array_equal(getattr(fast, field.name), getattr(whole, field.name)), field.name


def test_ring_geometry_is_computed_once_for_threads_that_ask_together():
    model = MODEL.with_changes(camera_mount=replace(MODEL.camera_mount, roll=0.01))
    before = encoder._cached_ring_geometry.cache_info().misses
    start = threading.Barrier(3)
    results = []

    def ask():
        start.wait()
        results.append(ring_geometry(model, EncoderConfig()))

    threads = [threading.Thread(target=ask) for _ in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert encoder._cached_ring_geometry.cache_info().misses == before + 1
    assert results[0] is results[1] is results[2]


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=50))
def test_normal_cdf_matches_scipy(values):
    x = np.array(values)
    assert np.allclose(encoder.normal_cdf(x), ndtr(x), rtol=1e-13, atol=1e-15,
                       equal_nan=True)


# ---------------------------------------------------------------- kernels against numpy


def test_ring_profile_matches_bincount():
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    geo = ring_geometry(MODEL, EncoderConfig())
    grey = image.reshape(-1, 3).astype(float).mean(axis=1)[geo.pixels]
    expected = np.bincount(geo.bins, weights=grey) / geo.bin_count
    got = encoder.ring_profile(image.reshape(-1), geo.pixels, geo.bins, geo.bin_count, False)
    assert np.allclose(got, expected, atol=1e-9)
    linear = encoder.ring_profile(image.reshape(-1), geo.pixels, geo.bins, geo.bin_count, True)
    # the sRGB decoding of OpenCV's colour conversion to linear light, as a peer
    assert np.allclose(srgb(linear / 255.0) * 255.0, expected, atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(sigma_deg=st.floats(0.2, 3.0), shift=st.floats(-3.2, 3.2))
def test_blurred_code_matches_numerical_convolution(sigma_deg, shift):
    disk = MODEL.encoder
    bits = disk.bits().astype(float)
    angles = np.linspace(-0.6, 0.6, 25) + shift
    sigma = math.radians(sigma_deg)
    fine = np.linspace(-5 * sigma, 5 * sigma, 4001)
    kernel = np.exp(-0.5 * (fine / sigma) ** 2)
    kernel /= kernel.sum()
    expected = [np.sum(disk.value_at(a + fine) * kernel) for a in angles]
    got = encoder.blurred_code(bits, disk.zero_offset, angles, np.full(25, sigma))
    assert np.allclose(got, expected, atol=2e-3)


def test_code_levels_and_edge_headings_on_a_rendered_profile():
    """A profile of the blurred code at heading theta: every edge in view gives theta back
    from a wrong start, and the levels away from the edges are the printed ones."""
    geo = ring_geometry(MODEL, EncoderConfig())
    disk = MODEL.encoder
    theta = 0.7
    sigma = np.full(geo.bin_angle.size, math.radians(1.0))
    profile = 50.0 + 100.0 * encoder.blurred_code(geo.bits, disk.zero_offset,
                                                  geo.bin_angle + theta, sigma)
    dark, light = encoder.code_levels(profile, geo.bin_angle, geo.bits, disk.zero_offset,
                                      theta, 0.3 * disk.sector_angle)
    assert dark == pytest.approx(50.0, abs=0.5) and light == pytest.approx(150.0, abs=0.5)
    found = np.empty(geo.edges.size)
    n = encoder.edge_headings(profile, geo.bin_angle, geo.edges, geo.rising,
                              theta + math.radians(2.0), 100.0, 0.5 * disk.sector_angle, found)
    head_edges = np.angle(np.exp(1j * (geo.edges - theta)))
    in_view = np.sum((head_edges > geo.bin_angle[0] + 0.1) & (head_edges < geo.bin_angle[-1]
                                                               - 0.1))
    assert n >= in_view >= 1
    assert np.abs(found[:n] - theta).max() < math.radians(0.01)


def test_correlate_matches_numpy():
    rng = np.random.default_rng(10)
    templates = rng.normal(size=(40, 256))
    profile = rng.normal(size=40)
    assert np.allclose(encoder.correlate(templates, profile), profile @ templates)


def test_correlation_peak_matches_numpy():
    rng = np.random.default_rng(2)
    scores = rng.uniform(-1, 1, 256)
    cand = np.arange(256) * (2 * np.pi / 256)
    best, margin = encoder.correlation_peak(scores, cand, 2 * np.pi, math.radians(11.25))
    far = np.abs(np.angle(np.exp(1j * (cand - cand[scores.argmax()])))) > math.radians(11.25)
    assert best == scores.argmax()
    assert margin == pytest.approx(scores.max() - scores[far].max())


def test_code_period():
    assert code_period(MODEL.encoder.code) == 32
    assert code_period("01" * 16) == 2
    assert code_period("0011" * 8) == 4


# ---------------------------------------------------------------- accuracy


def test_heading_rms_under_0_05_deg():
    rng = np.random.default_rng(3)
    headings = rng.uniform(-math.pi, math.pi, 12)
    errors, failures = decode_many(MODEL, headings, rng)
    assert not failures
    assert np.sqrt(np.mean(errors**2)) < 0.05
    assert np.abs(errors).max() < 0.1


@pytest.mark.parametrize("render", [
    dict(blur=10.0, noise=6.0), dict(blur=6.0, jpeg=75), dict(blur=12.0, noise=4.0, jpeg=80),
    dict(dark=0.1, light=0.26, noise=4.0)])
def test_heading_under_blur_noise_mjpg_and_low_contrast(render):
    rng = np.random.default_rng(4)
    headings = rng.uniform(-math.pi, math.pi, 6)
    errors, failures = decode_many(MODEL, headings, rng, **render)
    assert not failures
    assert np.sqrt(np.mean(errors**2)) < 0.06
    assert np.abs(errors).max() < 0.15


def test_general_mount_and_distorted_camera():
    """Head axis tilted and shifted in base_link, and a distorted lens: the geometry is
    taken from the model, not assumed."""
    model = MODEL.with_changes(
        head_mount=HeadMount(position=(0.05, -0.02, 0.1), roll=0.03, pitch=-0.02),
        encoder=EncoderDisk(height=1.027, inner_radius=0.035, outer_radius=0.05,
                            code=MODEL.encoder.code, zero_offset=0.4),
        camera=CameraIntrinsics(width=640, height=480, fx=1010.0, fy=1012.0, cx=322.0,
                                cy=238.0, distortion=(-0.15, 0.04, 0.0005, -0.001, 0.0)))
    rng = np.random.default_rng(5)
    headings = rng.uniform(-math.pi, math.pi, 5)
    errors, failures = decode_many(model, headings, rng)
    assert not failures
    assert np.abs(errors).max() < 0.1


def test_sector_is_the_one_under_the_head_x_axis():
    theta = math.radians(100.0)
    result = decode_heading(disk_frame(MODEL, theta, np.random.default_rng(6)), MODEL)
    assert result.ok
    assert result.sector == math.floor(theta / MODEL.encoder.sector_angle)


# ---------------------------------------------------------------- symmetric code


def test_symmetric_code_is_tracked_from_a_known_start():
    model = MODEL.with_changes(encoder=EncoderDisk(
        height=0.927, inner_radius=0.035, outer_radius=0.05, code="01" * 16))
    rng = np.random.default_rng(7)
    truth = 0.2 + np.arange(12) * math.radians(7.2)  # 25 frames/s, one turn in 2 s
    first = decode_heading(disk_frame(model, truth[0], rng), model)
    assert not first.ok and "previous heading" in first.reason
    previous, errors = truth[0], []
    for theta in truth[1:]:
        result = decode_heading(disk_frame(model, theta, rng), model, previous=previous)
        assert result.ok, result.reason
        errors.append(heading_error(result, theta))
        previous = result.heading
    assert np.abs(errors).max() < 0.1


# ---------------------------------------------------------------- hard cases


@pytest.mark.parametrize("fill", [0, 255, 128])
def test_uniform_frames_are_unreadable(fill):
    result = decode_heading(np.full((480, 640, 3), fill, np.uint8), MODEL)
    assert not result.ok and math.isnan(result.heading) and result.sector == -1


def test_noise_and_textured_scenes_never_give_a_confident_heading():
    rng = np.random.default_rng(8)
    for trial in range(12):
        if trial % 2:
            image = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
        else:  # a smooth random scene where the disk should be
            small = rng.uniform(0, 255, (480 // 24 + 1, 640 // 24 + 1, 1))
            image = cv2.resize(small, (640, 480), interpolation=cv2.INTER_CUBIC)
            image = np.repeat(np.clip(image, 0, 255)[:, :, None], 3, axis=2).astype(np.uint8)
        assert not decode_heading(image, MODEL).ok


def test_partly_covered_ring_is_right_or_unreadable():
    rng = np.random.default_rng(9)
    for theta in rng.uniform(-math.pi, math.pi, 4):
        image = disk_frame(MODEL, theta, rng)
        image[:, :300] = 90  # a cable hides the left part of the ring
        result = decode_heading(image, MODEL)
        if result.ok:
            assert abs(heading_error(result, theta)) < 0.1


@pytest.mark.parametrize(("image", "message"), [
    (np.zeros((640, 480, 3), np.uint8), "expected 640x480"),
    (np.zeros((480, 640, 3), np.float64), "dtype uint8"),
    (np.zeros((480, 640), np.uint8), "shape"),
])
def test_bad_frames_raise(image, message):
    with pytest.raises(ScanError, match=message):
        decode_heading(image, MODEL)


def test_disk_out_of_view_is_a_clear_error():
    model = MODEL.with_changes(encoder=EncoderDisk(
        height=1.5, inner_radius=0.035, outer_radius=0.05, code=MODEL.encoder.code))
    with pytest.raises(ScanError, match="not in the camera's view"):
        decode_heading(np.zeros((480, 640, 3), np.uint8), model)


def test_laser_line_range_avoids_the_ring():
    start, stop = laser_line_range(MODEL)
    assert (start, stop) == (0, 560)
    geo = ring_geometry(MODEL, EncoderConfig())
    assert np.all(geo.pixels % 640 >= stop)


# ---------------------------------------------------------------- heading sequences


def smooth_turn(n: int, rate: float, start: float) -> tuple[np.ndarray, np.ndarray]:
    times = np.arange(n) / 25.0
    truth = start + rate * times + 0.05 * np.sin(3.0 * times)
    return times, truth


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10**6), start=st.floats(-math.pi, math.pi))
def test_fill_unreadable_interpolates_smooth_motion_across_the_wrap(seed, start):
    rng = np.random.default_rng(seed)
    times, truth = smooth_turn(50, math.pi, start)
    ok = rng.random(50) > 0.3
    ok[[0, -1]] = True
    observed = np.where(ok, np.angle(np.exp(1j * truth)), np.nan)
    filled = fill_unreadable(observed, ok, times)
    err = np.angle(np.exp(1j * (filled - truth)))
    assert np.all(np.isfinite(filled))
    assert np.all(filled >= -math.pi) and np.all(filled < math.pi)
    assert np.abs(err[ok]).max() < 1e-12
    assert np.abs(err).max() < 0.01  # the wobble's curvature over the gaps


def test_fill_unreadable_ends_and_long_gaps():
    times, truth = smooth_turn(60, 3.0, 0.0)
    ok = np.ones(60, bool)
    ok[:3] = False  # start: extrapolated from frames 3 and 4
    ok[20:45] = False  # one second lost: not interpolated
    ok[50:53] = False  # 0.16 s lost: interpolated
    observed = np.where(ok, np.angle(np.exp(1j * truth)), np.nan)
    filled = fill_unreadable(observed, ok, times, max_gap=0.3)
    assert np.all(np.isnan(filled[20:45]))
    assert np.abs(np.angle(np.exp(1j * (filled[50:53] - truth[50:53])))).max() < 0.01
    assert np.abs(np.angle(np.exp(1j * (filled[:3] - truth[:3])))).max() < 0.02
    assert np.all(np.isfinite(filled[ok]))


def test_fill_unreadable_without_readable_frames_and_bad_input():
    assert np.all(np.isnan(fill_unreadable(np.full(4, np.nan), np.zeros(4, bool),
                                           np.arange(4.0))))
    with pytest.raises(ScanError, match="one length"):
        fill_unreadable(np.zeros(3), np.ones(4, bool), np.arange(4.0))
    with pytest.raises(ScanError, match="increasing"):
        fill_unreadable(np.zeros(3), np.ones(3, bool), np.array([0.0, 0.2, 0.1]))


def test_coverage_full_turn_and_gap():
    full = np.linspace(-math.pi, math.pi, 50, endpoint=False)
    result = coverage(full)
    assert result.complete and result.covered == pytest.approx(2 * math.pi)
    missing = full[(full < 0.5) | (full > 1.2)]  # 0.7 rad lost, not padded
    result = coverage(missing)
    assert not result.complete
    assert result.covered == pytest.approx(2 * math.pi - result.largest_gap)
    assert 0.7 < result.largest_gap < 0.9 and 0.3 < result.gap_start < 0.5
    assert coverage(np.array([np.nan, np.nan])).headings == 0
    assert not coverage(np.array([])).complete


@settings(max_examples=40, deadline=None)
@given(values=st.lists(st.floats(-10, 10), min_size=1, max_size=60),
       turn=st.floats(-math.pi, math.pi))
def test_coverage_is_rotation_invariant_and_sums_the_big_gaps(values, turn):
    values = np.array(values)
    a, b = coverage(values), coverage(values + turn)
    assert a.complete == b.complete
    assert a.covered == pytest.approx(b.covered, abs=1e-6)
    wrapped = np.sort(np.mod(values, 2 * math.pi))
    gaps = np.diff(np.append(wrapped, wrapped[0] + 2 * math.pi))
    assert a.covered == pytest.approx(2 * math.pi - gaps[gaps > math.radians(15)].sum())


def test_simulator_frames():
    """Frames of the simulator (motion blur, defocus pillbox, sRGB, MJPG): its true heading."""
    from scanmap_driver.sim import Renderer, builtin_scene, plan_scans

    scene = builtin_scene("office")
    plan = plan_scans(scene, MODEL, seed=1, count=1)[0]
    renderer = Renderer(scene, MODEL)
    rng = np.random.default_rng(11)
    for frame in (0, len(plan.frame_times) // 3, 2 * len(plan.frame_times) // 3):
        rendered = renderer.render(plan, frame, rng)
        result = decode_heading(rendered.image, MODEL)
        assert result.ok, result.reason
        assert abs(heading_error(result, rendered.truth.heading)) < 0.05
