"""The floor a scanner measures (`floor_seen`), against the simulator's scans of an empty
floor, and the floor rules taking their scanner geometry from it (`FloorConfig.for_scanner`,
the Mapper)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scanmap import Mapper
from scanmap.navigation.floor import FloorConfig
from scanmap.navigation.floor.config import floor_seen
from scanmap_driver.errors import MapError
from scanmap_driver.scanner_model import HeadMount, LaserPlane, reference_scanner

from .test_unlit import LOW_CAMERA as LOW
from .test_unlit import empty_floor_scan

REFERENCE = reference_scanner()
RAISED = REFERENCE.with_changes(  # the head 0.2 m up, off the robot's centre
    head_mount=HeadMount(position=(0.1, 0.05, 0.2)), name="raised")


def empty_floor_ranges(model) -> np.ndarray:
    """Horizontal ranges (m, from base_link's z axis) of the points of one ideal scan of
    an empty floor, without peak noise."""
    scan = empty_floor_scan(model)
    return np.hypot(scan.points[:, 0], scan.points[:, 1])


@pytest.mark.parametrize(("model", "emitter_height"), [(REFERENCE, 0.5), (LOW, 0.3),
                                                       (RAISED, 0.7)])
def test_the_floor_seen_is_the_floor_the_simulated_scanner_measures(model, emitter_height):
    """The nearest and farthest floor points of a simulated turn over empty floor, to the
    sampling of the image (half a row at the near end, which the simulator measures to
    the image's edge, a line at the far end: 1-1.5 cm)."""
    ranges = empty_floor_ranges(model)
    seen = floor_seen(model)
    assert seen["blind_range"] == pytest.approx(ranges.min(), abs=0.015)
    assert seen["view_range"] == pytest.approx(ranges.max(), abs=0.015)
    assert seen["emitter_height"] == pytest.approx(emitter_height)


def test_a_scanner_that_measures_no_floor_is_a_clear_error():
    """A level laser plane (a planar scanner) meets no floor: nothing to derive, so the
    floor rules ask for the fields by name, unless they are set."""
    level = REFERENCE.with_changes(laser=LaserPlane((0.0, 0.0, 0.5), (0.0, 0.0, 1.0)),
                                   name="level")
    assert floor_seen(level) is None
    with pytest.raises(MapError, match=r"'level' measures no floor.*set blind_range, "
                                       r"view_range, emitter_height"):
        FloorConfig().for_scanner(level)
    given = FloorConfig(blind_range=1.0, view_range=3.0, emitter_height=0.4)
    assert given.for_scanner(level) is given


def test_the_floor_rules_take_only_the_unset_fields_from_the_scanner():
    config = FloorConfig(view_range=2.5).for_scanner(LOW)
    assert config.view_range == 2.5
    assert config.blind_range == floor_seen(LOW)["blind_range"]
    assert config.emitter_height == pytest.approx(0.3)


@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf, "1.5"])
def test_a_bad_scanner_field_is_a_clear_error(value):
    with pytest.raises(MapError, match=r"FloorConfig\.blind_range"):
        FloorConfig(blind_range=value)


def test_the_mapper_segments_with_its_scanners_floor():
    """A scanner built lower sees the floor from 0.84 m, not the reference's 1.5 m: the
    drop-off rules must know where it could have seen a drop-off from."""
    floor = Mapper(LOW).config.floor
    assert floor.blind_range == pytest.approx(0.83, abs=0.01)
    assert floor.emitter_height == pytest.approx(0.3)
    assert Mapper().config.floor.blind_range == pytest.approx(1.495, abs=0.005)
