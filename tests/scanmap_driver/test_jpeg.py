"""JPEG decoding against OpenCV's, which it replaces for speed: the same pixels."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.jpeg import jpeg_to_bgr
from scanmap_driver.sim.synthetic_frames import stripe_frame


def opencv(data: bytes) -> np.ndarray | None:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), quality=st.integers(50, 100))
def test_a_webcam_frame_decodes_to_opencvs_pixels(seed, quality):
    frame, _ = stripe_frame(np.random.default_rng(seed), red_objects=3)
    data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, quality])[1].tobytes()
    np.testing.assert_array_equal(jpeg_to_bgr(data), opencv(data))


@pytest.mark.parametrize("sampling", [cv2.IMWRITE_JPEG_SAMPLING_FACTOR_411,
                                      cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
                                      cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444])
def test_every_chroma_subsampling_decodes_to_opencvs_pixels(sampling):
    frame, _ = stripe_frame(np.random.default_rng(1), height=97, width=131)  # odd sizes
    data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling])[1]
    np.testing.assert_array_equal(jpeg_to_bgr(data.tobytes()), opencv(data.tobytes()))


def test_a_grey_jpeg_decodes_to_three_equal_channels_as_opencvs():
    grey = np.random.default_rng(2).integers(0, 256, (48, 64), dtype=np.uint8)
    data = cv2.imencode(".jpg", grey)[1].tobytes()
    np.testing.assert_array_equal(jpeg_to_bgr(data), opencv(data))


def test_damaged_entropy_data_decodes_what_it_can_as_opencv_does():
    frame, _ = stripe_frame(np.random.default_rng(3))
    data = bytearray(cv2.imencode(".jpg", frame)[1].tobytes())
    data[len(data) // 2: len(data) // 2 + 40] = bytes(40)  # zeros inside the scan data
    ours, theirs = jpeg_to_bgr(bytes(data)), opencv(bytes(data))
    assert ours is not None and theirs is not None
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("data", [b"", b"\xff\xd8\xff\xd9", b"not a jpeg at all" * 10])
def test_what_is_not_a_jpeg_gives_none(data):
    assert jpeg_to_bgr(data) is None  # (OpenCV raises its own error on empty data)
