"""Scan assembly on rendered frames, checked against the simulator's ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from scanmap_driver.assembly import COLOUR_OFFSET_PX, ScanAssembler, colour_beside_stripe
from scanmap_driver.errors import ScanError
from scanmap_driver.recording import Recording
from scanmap_driver.transforms import wrap_angle


@pytest.fixture(scope="module")
def frames(office_recording):
    recording = Recording.open(office_recording)
    truth = np.load(recording.ground_truth / "scan_0000.npz")
    return recording, list(recording.frames(0)), truth


def assemble(recording, frames, mutate=None):
    assembler = ScanAssembler(recording.model)
    for frame in frames:
        image = frame.image if mutate is None else mutate(frame)
        assembler.add_frame(image, frame.time)
    record = recording.scans[0]
    return assembler, *assembler.finish(0, record.odom_start, record.odom_end)


def point_errors(scan, truth):
    """Distance of each point to the nearest true laser point of its frame (m)."""
    errors = np.empty(len(scan))
    for frame in np.unique(scan.frame_index):
        mine = scan.frame_index == frame
        tree = cKDTree(truth["laser_base"][truth["laser_frame"] == frame])
        errors[mine] = tree.query(scan.points[mine].astype(np.float64))[0]
    return errors


def test_scan_matches_ground_truth(frames):
    recording, images, truth = frames
    assembler, scan, summary = assemble(recording, images)
    heading_error = np.degrees(wrap_angle(assembler.headings - truth["frame_heading"]))
    assert np.sqrt(np.mean(heading_error**2)) < 0.2
    assert summary.complete and summary.unreadable_frames == 0
    assert summary.headings_covered_deg == pytest.approx(360.0)
    # Recall: the visible, unshadowed truth points within range on the lines left of the disk.
    from scanmap_driver.encoder import laser_line_range

    head = truth["laser_head"]
    visible = (truth["laser_primary"] & ~truth["laser_shadowed"]
               & (truth["laser_u"] < laser_line_range(recording.model)[1])
               & (np.hypot(head[:, 0], head[:, 1]) > 0.3)
               & (np.hypot(head[:, 0], head[:, 1]) < 4.0))
    assert len(scan) > 0.75 * visible.sum()  # faint grazing floor stripes beyond 2 m are lost
    errors = point_errors(scan, truth)
    assert np.percentile(errors, 95) < 0.02
    assert np.mean(errors > 0.10) < 0.005  # outliers
    assert np.all(np.isfinite(scan.range_sigma)) and scan.has_odometry
    np.testing.assert_array_equal(scan.time, np.array([f.time for f in images])[scan.frame_index])


def test_colours_come_from_beside_the_stripe(frames):
    recording, images, _ = frames
    _, scan, _ = assemble(recording, images[:5])
    excess = scan.colors[:, 0].astype(int) - np.maximum(scan.colors[:, 1], scan.colors[:, 2])
    assert np.median(excess) < 25  # scene colour, not the laser's red


def test_colour_sampler_prefers_the_side_without_red():
    image = np.full((40, 3, 3), 100, np.uint8)
    image[:20, :, 2] = 250  # a red object above the stripe (rows < 20), BGR
    colours = colour_beside_stripe(image, np.array([0.0, 1.0, 2.0]), np.array([20.0] * 3))
    np.testing.assert_array_equal(colours, np.full((3, 3), 100))


def plain_colour_beside(image, u, v):
    """colour_beside_stripe in numpy, as its docstring says it."""
    rows = np.clip(np.rint(v[:, None] + np.array([-1.0, 1.0]) * COLOUR_OFFSET_PX), 0,
                   image.shape[0] - 1).astype(int)
    sides = image[rows, u.astype(int)[:, None]].astype(int)  # (n, 2, 3) BGR
    excess = sides[:, :, 2] - np.maximum(sides[:, :, 0], sides[:, :, 1])
    pick = (excess[:, 1] < excess[:, 0]).astype(int)
    return sides[np.arange(len(u)), pick, ::-1].astype(np.uint8)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), lines=st.integers(0, 30))
def test_colour_sampler_matches_its_plain_definition(seed, lines):
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 256, (24, 30, 3), dtype=np.uint8)
    image[rng.random((24, 30)) < 0.3, 2] = 255  # red patches: the sides differ
    u = rng.integers(0, 30, lines).astype(float)
    v = rng.uniform(-10.0, 34.0, lines)  # near and past the image's ends: rows clipped
    np.testing.assert_array_equal(colour_beside_stripe(image, u, v),
                                  plain_colour_beside(image, u, v))


def test_unreadable_disk_frames_are_filled_and_counted(frames):
    recording, images, truth = frames
    blank = {5, 6, 20}

    def hide_disk(frame):
        if frame.index not in blank:
            return frame.image
        image = frame.image.copy()
        image[:, 560:] = 0
        return image

    assembler, _scan, summary = assemble(recording, images, hide_disk)
    assert summary.unreadable_frames == 3 and summary.complete
    filled = np.array(sorted(blank))
    from scanmap_driver.encoder import fill_unreadable

    times = np.array([f.time for f in images])
    ok = np.isfinite(assembler.headings)
    headings = fill_unreadable(assembler.headings, ok, times)
    error = np.degrees(wrap_angle(headings[filled] - truth["frame_heading"][filled]))
    assert np.abs(error).max() < 1.0


def test_a_short_scan_is_reported_not_padded(frames):
    recording, images, _ = frames
    _, _scan, summary = assemble(recording, images[: len(images) // 2])
    assert not summary.complete
    assert summary.headings_covered_deg < 300


def test_wrong_frame_size_and_all_unreadable(frames):
    recording, _images, _ = frames
    assembler = ScanAssembler(recording.model)
    with pytest.raises(ScanError, match="expected a 480x640x3"):
        assembler.add_frame(np.zeros((480, 600, 3), np.uint8), 0.0)
    for k in range(3):
        assembler.add_frame(np.zeros((480, 640, 3), np.uint8), float(k))
    with pytest.raises(ScanError, match="unreadable in all 3 frames"):
        assembler.finish(0)


def test_empty_scan():
    from scanmap_driver import reference_scanner

    scan, summary = ScanAssembler(reference_scanner()).finish(4)
    assert len(scan) == 0 and summary.frames == 0 and scan.index == 4
