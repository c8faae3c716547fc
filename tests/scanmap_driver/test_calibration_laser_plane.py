"""The laser plane from the aperture and two wall points: closed forms, properties, refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from scanmap_driver import CalibrationError, reference_scanner
from scanmap_driver.calibration import laser_plane_from_points
from scanmap_driver.scanner_model import LaserPlane

coordinate = st.floats(-5.0, 5.0, allow_nan=False)
point = st.tuples(coordinate, coordinate, coordinate)


def test_horizontal_plane_closed_form():
    plane = laser_plane_from_points((0.0, 0.0, 0.5), (2.0, -1.0, 0.5), (2.0, 1.0, 0.5))
    assert plane.origin == (0.0, 0.0, 0.5)
    np.testing.assert_allclose(plane.normal, (0.0, 0.0, 1.0), atol=1e-15)


def test_vertical_plane_normal_points_along_x():
    # A plane containing z: z gives no orientation, so +x does.
    plane = laser_plane_from_points((0.0, 0.0, 0.0), (-1.0, 1.0, 0.0), (-1.0, 1.0, 2.0))
    np.testing.assert_allclose(plane.normal, np.array([1.0, 1.0, 0.0]) / math.sqrt(2),
                               atol=1e-15)


def test_paper_procedure_recovers_the_reference_laser():
    # The reference laser (pitched 8 deg, rolled 60 deg) lights a wall 3 m ahead; two lit
    # points on that wall plus the aperture give back the plane exactly.
    laser = reference_scanner().laser
    origin, normal = np.array(laser.origin), np.array(laser.normal)
    wall_x = origin[0] + 3.0
    wall_points = []
    for y in (-0.4, 0.6):  # on the wall x = wall_x, solve the plane equation for z
        z = origin[2] - (normal[0] * (wall_x - origin[0]) + normal[1] * (y - origin[1])) \
            / normal[2]
        wall_points.append((wall_x, y, z))
    plane = laser_plane_from_points(laser.origin, *wall_points)
    np.testing.assert_allclose(plane.normal, laser.normal, atol=1e-12)
    assert plane.origin == laser.origin


@settings(max_examples=200, deadline=None)
@given(point, point, point)
def test_points_lie_on_the_plane_whatever_their_order(a, b, c):
    pts = np.array([a, b, c])
    sides = [np.linalg.norm(pts[i] - pts[j]) for i, j in ((0, 1), (0, 2), (1, 2))]
    longest = max(sides)
    assume(longest > 1e-3 and min(sides) > 1e-2 * longest)
    assume(np.linalg.norm(np.cross(pts[1] - pts[0], pts[2] - pts[0])) > 1e-2 * longest**2)
    plane = laser_plane_from_points(a, b, c)
    assert isinstance(plane, LaserPlane)
    assert np.linalg.norm(plane.normal) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(plane.signed_distance(pts), 0.0, atol=1e-9 * max(longest, 1))
    # Swapping the wall points gives the very same plane (the normal is oriented).
    swapped = laser_plane_from_points(a, c, b)
    np.testing.assert_allclose(swapped.normal, plane.normal, atol=1e-12)
    # Independent closed form: the normal is perpendicular to both triangle sides.
    n = np.array(plane.normal)
    assert abs(n @ (pts[1] - pts[0])) < 1e-9 * longest
    assert abs(n @ (pts[2] - pts[0])) < 1e-9 * longest


@settings(max_examples=100, deadline=None)
@given(point, st.tuples(coordinate, coordinate, coordinate).filter(
    lambda d: np.linalg.norm(d) > 0.1), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))
def test_collinear_points_are_refused(a, direction, s, t):
    gaps = (abs(s), abs(t), abs(s - t))  # distances along the line, in units of |d|
    assume(min(gaps) > 0.01 * max(gaps))
    a, d = np.array(a), np.array(direction)
    # points a nanometre apart are one point (and 1e-214 m squared underflows to 0): the
    # coincident-points error, tested on its own, answers those
    assume(min(gaps) * np.linalg.norm(d) > 1e-9)
    with pytest.raises(CalibrationError, match="collinear"):
        laser_plane_from_points(a, a + s * d, a + t * d)


def test_nearly_collinear_within_tolerance_is_refused_and_can_be_allowed():
    # A wall point 1 mm off the line through points 2 m apart: flatness 2.5e-4.
    points = ((0.0, 0.0, 0.5), (2.0, 0.0, 0.5), (1.0, 0.0, 0.501))
    with pytest.raises(CalibrationError, match="collinear"):
        laser_plane_from_points(*points)
    plane = laser_plane_from_points(*points, tolerance=1e-4)
    np.testing.assert_allclose(plane.normal, (0.0, 1.0, 0.0), atol=1e-12)


@pytest.mark.parametrize(("points", "pair"), [
    (((0, 0, 0.5), (0, 0, 0.5), (2, 1, 0.5)), "aperture and wall_a"),
    (((0, 0, 0.5), (2, 1, 0.5), (0, 0, 0.5)), "aperture and wall_b"),
    (((0, 0, 0.5), (2, 1, 0.5), (2, 1, 0.5 + 1e-6)), "wall_a and wall_b"),
    (((1, 1, 1), (1, 1, 1), (1, 1, 1)), "aperture and wall_a"),
])
def test_coincident_points_are_named(points, pair):
    with pytest.raises(CalibrationError, match=f"{pair} coincide"):
        laser_plane_from_points(*points)


@pytest.mark.parametrize(("points", "name"), [
    (((0, 0, math.nan), (2, 1, 0.5), (2, -1, 0.5)), "aperture"),
    (((0, 0, 0), (2, math.inf, 0.5), (2, -1, 0.5)), "wall_a"),
    (((0, 0, 0), (2, 1, 0.5), (2, -1)), "wall_b"),
    (((0, 0, 0), (2, 1, 0.5), "wall"), "wall_b"),
])
def test_non_finite_or_malformed_points_are_named(points, name):
    with pytest.raises(CalibrationError, match=f"laser plane: {name}: expected 3 finite"):
        laser_plane_from_points(*points)


def test_scale_invariance_of_the_tolerance():
    # The same shape in millimetres-sized or kilometre-sized units passes or fails alike.
    shape = np.array([(0.0, 0.0, 0.0), (2.0, 0.0, 0.0), (1.0, 0.0, 0.01)])
    for scale in (1e-3, 1.0, 1e3):
        plane = laser_plane_from_points(*(shape * scale))
        np.testing.assert_allclose(plane.normal, (0.0, 1.0, 0.0), atol=1e-12)
