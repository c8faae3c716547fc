"""The paper's wall calibration: scan a flat vertical wall at a measured distance and adjust
the scanner's parameters until the wall is vertical, flat and at the right distance.

Observations are laser pixels (u, v) with their headings from one scan of a room where
the robot faces a wall at `distance` metres from the scanner axis (the wall's normal is
base_link x). Floor points, when the stripe reaches the floor, pin the height.

Solved by robust nonlinear least squares (scipy) over corrections to a starting model:

| parameter            | what it moves                                              |
|----------------------|------------------------------------------------------------|
| laser_normal_1, _2   | the laser plane's normal, turned about two axes normal to it (rad) |
| vertical_separation  | the laser aperture along z relative to the camera (m)      |
| camera_tilt          | the camera's downward pitch b (rad)                         |
| camera_height        | camera and laser together along z (m)                       |
| zero_offset          | the encoder disk's zero (rad)                               |
| wall_azimuth         | the wall's direction (rad), only with `facing=False`        |

Each parameter gets a standard deviation from the Gauss-Newton covariance. A parameter
the data cannot pin (its deviation above a tolerance that would cost about 1 cm at 4 m,
or a direction of the problem with no curvature) is reported as undetermined, and
`WallCalibration.require_supported()` refuses such a calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..errors import CalibrationError
from ..scanner_model import CameraMount, LaserPlane, ScannerModel
from ..transforms import rot_z
from ..triangulation import triangulate

PARAMETERS = ("laser_normal_1", "laser_normal_2", "vertical_separation", "camera_tilt",
              "camera_height", "zero_offset", "wall_azimuth")
# Largest acceptable standard deviation per parameter: about 1 cm of range at 4 m.
TOLERANCE = {"laser_normal_1": 2e-4, "laser_normal_2": 2e-4, "vertical_separation": 2e-3,
             "camera_tilt": 2e-4, "camera_height": 5e-3, "zero_offset": 1e-3,
             "wall_azimuth": 1e-3}
REGULARISATION = 1e-10  # keeps the covariance finite in flat directions (and huge there)


@dataclass(frozen=True)
class WallCalibration:
    """The calibrated model with what the data say about each parameter."""

    model: ScannerModel
    values: dict[str, float]  # fitted corrections to the starting model
    sigmas: dict[str, float]
    undetermined: tuple[str, ...]
    rms: float  # m, wall and floor residuals
    wall_points: int
    floor_points: int
    notes: list[str] = field(default_factory=list)

    def require_supported(self) -> ScannerModel:
        """The model, or a CalibrationError naming what the data do not determine."""
        if self.undetermined:
            detail = ", ".join(f"{name} (sigma {self.sigmas[name]:.2g})"
                               for name in self.undetermined)
            raise CalibrationError(
                f"the wall scan does not determine {detail}; add headings that see the wall "
                "at more angles, floor points, or fix these parameters")
        return self.model


def apply_corrections(model: ScannerModel, values: dict[str, float]) -> ScannerModel:
    """The model with the named corrections applied (missing names count as zero)."""
    get = values.get
    normal = np.array(model.laser.normal)
    axis_1 = np.cross(normal, [0.0, 0.0, 1.0])
    axis_1 /= np.linalg.norm(axis_1)
    axis_2 = np.cross(normal, axis_1)
    turned = _rotate(_rotate(normal, axis_1, get("laser_normal_1", 0.0)), axis_2,
                     get("laser_normal_2", 0.0))
    lift = get("camera_height", 0.0)
    origin = np.array(model.laser.origin) + [0.0, 0.0, lift - get("vertical_separation", 0.0)]
    mount = model.camera_mount
    position = np.array(mount.position) + [0.0, 0.0, lift]
    return model.with_changes(
        laser=LaserPlane.from_point_normal(origin, turned),
        camera_mount=CameraMount(position=tuple(position),
                                 tilt=mount.tilt + get("camera_tilt", 0.0), yaw=mount.yaw,
                                 roll=mount.roll),
        encoder=_with_zero_offset(model, get("zero_offset", 0.0)),
    )


def _with_zero_offset(model: ScannerModel, delta: float):
    from dataclasses import replace

    return replace(model.encoder, zero_offset=model.encoder.zero_offset + delta)


def _rotate(vector: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of `vector` about the unit `axis`."""
    return (vector * np.cos(angle) + np.cross(axis, vector) * np.sin(angle)
            + axis * (axis @ vector) * (1.0 - np.cos(angle)))


def calibrate_wall(model: ScannerModel, u: np.ndarray, v: np.ndarray, heading: np.ndarray,
                   distance: float, *, facing: bool = True,
                   fit: tuple[str, ...] | None = None,
                   floor_band: float = 0.15, wall_band: float = 0.3) -> WallCalibration:
    """Fit the scanner to a wall `distance` m in front of the robot (see module docstring).

    heading: the decoded heading of each observation; the encoder zero offset is solved as
    a shift of these headings. Points further than `wall_band` from the wall and
    `floor_band` from the floor under the starting model are ignored (other objects).
    """
    if not np.isfinite(distance) or distance <= model.min_range:
        raise CalibrationError(f"wall distance: expected a range beyond {model.min_range} m, "
                               f"got {distance}")
    u, v, heading = (np.asarray(a, dtype=np.float64).ravel() for a in (u, v, heading))
    if not (u.shape == v.shape == heading.shape):
        raise CalibrationError("wall observations: u, v and heading differ in length")
    names = tuple(fit) if fit is not None else tuple(
        p for p in PARAMETERS if facing or p != "zero_offset")
    if not facing and "wall_azimuth" not in names:
        names += ("wall_azimuth",)
    if facing:
        names = tuple(n for n in names if n != "wall_azimuth")
    unknown = set(names) - set(PARAMETERS)
    if unknown:
        raise CalibrationError(f"wall calibration: unknown parameters {sorted(unknown)}")

    def residuals_for(x: np.ndarray, wall_mask: np.ndarray, floor_mask: np.ndarray):
        values = dict(zip(names, x, strict=True))
        current = apply_corrections(model, values)
        shifted = heading + values.get("zero_offset", 0.0)
        points = triangulate(current, u, v, shifted).points_base
        along_wall = points @ (rot_z(values.get("wall_azimuth", 0.0))[:, 0])
        res_wall = along_wall[wall_mask] - distance
        res_floor = points[floor_mask, 2]
        out = np.concatenate([res_wall, res_floor])
        return np.nan_to_num(out, nan=1.0)  # a point that left the valid range counts 1 m

    x = np.zeros(len(names))
    wall_mask = floor_mask = np.zeros(u.size, bool)
    for _ in range(3):  # classify points with the current estimate, then solve
        values = dict(zip(names, x, strict=True))
        points = triangulate(apply_corrections(model, values), u, v,
                             heading + values.get("zero_offset", 0.0)).points_base
        along = points @ rot_z(values.get("wall_azimuth", 0.0))[:, 0]
        ok = np.isfinite(points).all(axis=1)
        floor_mask = ok & (np.abs(points[:, 2]) < floor_band)
        wall_mask = ok & ~floor_mask & (np.abs(along - distance) < wall_band)
        if wall_mask.sum() < 50:
            raise CalibrationError(f"wall calibration: only {wall_mask.sum()} points near a "
                                   f"wall at {distance} m; is the wall in front of the robot?")
        solution = least_squares(residuals_for, x, args=(wall_mask, floor_mask),
                                 loss="soft_l1", f_scale=0.01, x_scale=0.01, method="trf")
        x = solution.x
        wall_band = max(0.05, wall_band / 3.0)
        floor_band = max(0.05, floor_band / 2.0)

    residual = residuals_for(x, wall_mask, floor_mask)
    jac = solution.jac
    dof = max(1, residual.size - len(names))
    scale = float(residual @ residual) / dof
    normal_matrix = jac.T @ jac
    normal_matrix += REGULARISATION * np.trace(normal_matrix) * np.eye(len(names)) / len(names)
    cov = np.linalg.inv(normal_matrix) * scale
    sigmas = dict(zip(names, np.sqrt(np.diag(cov)).tolist(), strict=True))
    undetermined = tuple(n for n in names if sigmas[n] > TOLERANCE[n])
    values = dict(zip(names, x.tolist(), strict=True))
    notes = []
    if not facing:
        notes.append("zero_offset is not solved: the wall's direction is free (facing=False)")
    return WallCalibration(
        model=apply_corrections(model, values), values=values, sigmas=sigmas,
        undetermined=undetermined, rms=float(np.sqrt(np.mean(residual**2))),
        wall_points=int(wall_mask.sum()), floor_points=int(floor_mask.sum()), notes=notes)
