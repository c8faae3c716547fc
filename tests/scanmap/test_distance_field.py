"""The exact distance transform against scipy.ndimage.distance_transform_edt."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage

from scanmap.navigation.distance_field import distance_transform


def check_against_scipy(mask: np.ndarray, pad: int = 0) -> None:
    distance, nearest = distance_transform(mask, pad)
    reference = ndimage.distance_transform_edt(~mask)
    np.testing.assert_allclose(distance, reference, rtol=1e-6, atol=1e-5)
    rows, cols = np.unravel_index(nearest, (mask.shape[0] + 2 * pad, mask.shape[1] + 2 * pad))
    rows, cols = rows - pad, cols - pad  # the index counts the padded array's cells
    assert mask[rows, cols].all()  # the index names a feature ...
    yy, xx = np.indices(mask.shape)
    np.testing.assert_allclose(np.hypot(rows - yy, cols - xx), reference, rtol=1e-6, atol=1e-5)


@settings(max_examples=60, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 40), st.integers(1, 40)),
              elements=st.booleans()).filter(lambda m: m.any()), st.integers(0, 2))
def test_matches_scipy_on_random_masks(mask, pad):
    check_against_scipy(mask, pad)


def test_matches_scipy_on_a_sparse_large_mask():
    rng = np.random.default_rng(0)
    check_against_scipy(rng.random((300, 420)) < 0.002)


def test_without_features_every_distance_is_infinite():
    distance, nearest = distance_transform(np.zeros((5, 7), bool))
    assert np.isinf(distance).all() and (nearest == -1).all()


def test_all_features_and_empty_shapes():
    distance, nearest = distance_transform(np.ones((3, 4), bool))
    assert (distance == 0).all()
    np.testing.assert_array_equal(nearest, np.arange(12).reshape(3, 4))
    assert distance_transform(np.zeros((0, 5), bool))[0].shape == (0, 5)
