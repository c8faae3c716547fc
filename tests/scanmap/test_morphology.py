"""OpenCV's morphology and components against scipy.ndimage (the peer) on random masks."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage

from scanmap.navigation import morphology
from scanmap.navigation.distance_field import distance_transform

SQUARE = np.ones((3, 3), bool)
masks = arrays(np.bool_, st.tuples(st.integers(1, 40), st.integers(1, 40)))


@settings(max_examples=60, deadline=None)
@given(mask=masks, iterations=st.integers(1, 4))
def test_dilate_matches_ndimage(mask, iterations):
    assert np.array_equal(morphology.dilate(mask, iterations),
                          ndimage.binary_dilation(mask, SQUARE, iterations=iterations))


@settings(max_examples=60, deadline=None)
@given(data=st.data(), iterations=st.integers(1, 12))
def test_geodesic_dilate_matches_ndimage_with_a_mask(data, iterations):
    mask = data.draw(masks)
    within = data.draw(arrays(np.bool_, mask.shape))
    assert np.array_equal(
        morphology.dilate(mask, iterations, within=within),
        ndimage.binary_dilation(mask, SQUARE, iterations=iterations, mask=within))


@settings(max_examples=60, deadline=None)
@given(mask=masks, size=st.sampled_from([3, 5]))
def test_max_filter_matches_ndimage(mask, size):
    assert np.array_equal(morphology.max_filter(mask, size),
                          ndimage.maximum_filter(mask, size=size))


@settings(max_examples=60, deadline=None)
@given(values=arrays(np.float32, st.tuples(st.integers(1, 30), st.integers(1, 30)),
                     elements=st.one_of(st.floats(-5, 5, width=32), st.just(np.inf))),
       size=st.sampled_from([3, 5]))
def test_min_filter_matches_ndimage(values, size):
    assert np.array_equal(morphology.min_filter(values, size),
                          ndimage.minimum_filter(values, size=size))


@settings(max_examples=60, deadline=None)
@given(values=arrays(np.float32, st.tuples(st.integers(1, 30), st.integers(1, 30)),
                     elements=st.one_of(st.floats(-5, 5, width=32), st.just(np.nan)),
                     fill=st.nothing()),
       size=st.sampled_from([3, 5, 7]))
def test_span_filter_matches_ndimage(values, size):
    highest = ndimage.maximum_filter(np.where(np.isnan(values), -np.inf, values), size=size)
    lowest = ndimage.minimum_filter(np.where(np.isnan(values), np.inf, values), size=size)
    assert np.array_equal(morphology.span_filter(values, size), highest - lowest)


def components(mask: np.ndarray) -> tuple[np.ndarray, int, list[tuple[slice, slice]]]:
    """`component_boxes` as ndimage gives it: labels, count, (rows, columns) slices."""
    labels, boxes = morphology.component_boxes(mask)
    return labels, len(boxes) - 1, [morphology.box_slices(box) for box in boxes[1:]]


@settings(max_examples=60, deadline=None)
@given(mask=masks)
def test_components_match_ndimage(mask):
    """The same components (as sets of cells) and bounding boxes, whatever the numbering."""
    labels, count, boxes = components(mask)
    expected, expected_count = ndimage.label(mask, SQUARE)
    assert count == expected_count and len(boxes) == count
    assert np.array_equal(labels > 0, mask)
    ours = {frozenset(zip(*np.nonzero(labels == k), strict=True)): boxes[k - 1]
            for k in range(1, count + 1)}
    theirs = {frozenset(zip(*np.nonzero(expected == k), strict=True)): box
              for k, box in enumerate(ndimage.find_objects(expected), start=1)}
    assert ours == theirs


@settings(max_examples=60, deadline=None)
@given(mask=masks, min_cells=st.integers(1, 6))
def test_large_components_match_ndimage(mask, min_cells):
    expected, _ = ndimage.label(mask, SQUARE)
    sizes = np.bincount(expected.ravel())
    assert np.array_equal(morphology.large_components(mask, min_cells),
                          mask & (sizes[expected] >= min_cells))


def test_empty_and_full_masks():
    empty, full = np.zeros((5, 7), bool), np.ones((5, 7), bool)
    assert not morphology.dilate(empty, 3).any() and morphology.dilate(full).all()
    assert components(empty)[1] == 0
    labels, count, boxes = components(full)
    assert count == 1 and (labels == 1).all() and boxes == [(slice(0, 5), slice(0, 7))]


@settings(max_examples=60, deadline=None)
@given(mask=masks, distance=st.sampled_from([0.0, 0.5, 1.0, 1.4, 1.5, 2.0, 2.3, 3.5, 5.0, 8,
                                              8.06, 9.9999999]))
def test_within_distance_is_the_distance_fields_comparison(mask, distance):
    assert np.array_equal(morphology.within_distance(mask, distance),
                          distance_transform(mask)[0] <= distance)


@settings(max_examples=60, deadline=None)
@given(mask=masks)
def test_neighbours_count_the_eight_around_each_cell(mask):
    expected = ndimage.convolve(mask.astype(int), np.ones((3, 3), int), mode="constant")
    assert np.array_equal(morphology.neighbours(mask), expected - mask)
