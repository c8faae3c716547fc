"""What a scanner sees of flat floor (`floor_view`), against the simulator's scans of an
empty floor, and the floor rules taking it from the scanner (`FloorConfig.for_scanner`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scanmap import Mapper
from scanmap.navigation.floor import FloorConfig
from scanmap_driver.errors import CalibrationError, MapError
from scanmap_driver.floor_view import floor_view
from scanmap_driver.scanner_model import CameraMount, HeadMount, LaserPlane, reference_scanner
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.scene import Scene

REFERENCE = reference_scanner()
LOW = REFERENCE.with_changes(  # a camera 0.6 m up, tilted more; the emitter 0.3 m up
    camera_mount=CameraMount(position=(-0.05, 0.0, 0.6), tilt=0.45),
    laser=LaserPlane((-0.05, 0.0, 0.3), REFERENCE.laser.normal), name="low")
RAISED = REFERENCE.with_changes(  # the head 0.2 m up, off the robot's centre
    head_mount=HeadMount(position=(0.1, 0.05, 0.2)), name="raised")


def empty_floor_ranges(model) -> np.ndarray:
    """Horizontal ranges (m, from base_link's z axis) of one ideal scan's points of an
    empty floor, without peak noise."""
    scene = Scene.from_dict({"format": "scanmap.scene/1", "name": "empty", "ambient": 0.8,
                             "floor": {"color": [150, 140, 125]}, "objects": [],
                             "scan_poses": [[0.0, 0.0, 0.0]]})
    scan = next(iter(ideal_scans(scene, model, scans=1, pixel_sigma=0.0))).scan
    return np.hypot(scan.points[:, 0], scan.points[:, 1])


@pytest.mark.parametrize(("model", "emitter_height"), [(REFERENCE, 0.5), (LOW, 0.3),
                                                       (RAISED, 0.7)])
def test_the_floor_view_is_the_floor_the_simulated_scanner_measures(model, emitter_height):
    """The nearest and farthest floor points of a simulated turn over empty floor, to the
    sampling of its image columns (a column spans 1-2 cm of range at the far end, where
    the floor's line runs nearly along the camera's axis)."""
    ranges = empty_floor_ranges(model)
    view = floor_view(model)
    assert view.nearest == pytest.approx(ranges.min(), abs=0.01)
    assert view.farthest == pytest.approx(ranges.max(), abs=0.02)
    assert view.emitter_height == pytest.approx(emitter_height)


def test_a_lower_camera_sees_the_floor_nearer():
    assert floor_view(LOW).nearest < 0.6 * floor_view(REFERENCE).nearest


def test_a_scanner_whose_laser_never_lights_the_floor_in_view_is_a_clear_error():
    """A level laser plane (a planar scanner) meets no floor: nothing to derive, so the
    floor rules ask for the fields by name, unless they are set."""
    level = REFERENCE.with_changes(laser=LaserPlane((0.0, 0.0, 0.5), (0.0, 0.0, 1.0)),
                                   name="level")
    with pytest.raises(CalibrationError, match="level: its laser lights no floor"):
        floor_view(level)
    with pytest.raises(MapError, match="set blind_range, view_range, emitter_height"):
        FloorConfig().for_scanner(level)
    given = FloorConfig(blind_range=1.0, view_range=3.0, emitter_height=0.4)
    assert given.for_scanner(level) is given


def test_the_floor_rules_take_only_the_unset_fields_from_the_scanner():
    config = FloorConfig(view_range=2.5).for_scanner(LOW)
    assert config.view_range == 2.5
    assert config.blind_range == floor_view(LOW).nearest
    assert config.emitter_height == pytest.approx(0.3)


@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf, "1.5"])
def test_a_bad_scanner_field_is_a_clear_error(value):
    with pytest.raises(MapError, match=r"FloorConfig\.blind_range"):
        FloorConfig(blind_range=value)


def test_the_mapper_segments_with_its_scanners_floor_view():
    """A scanner built lower sees the floor from 0.83 m, not the reference's 1.5 m: the
    drop-off rules must know where it could have seen a drop-off from."""
    floor = Mapper(LOW).config.floor
    assert floor.blind_range == pytest.approx(0.83, abs=0.01)
    assert floor.emitter_height == pytest.approx(0.3)
    assert Mapper().config.floor.blind_range == pytest.approx(1.495, abs=0.005)
