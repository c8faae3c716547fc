"""The paper's wall calibration: scan a flat vertical wall at a measured distance and adjust
the scanner's parameters until the wall is vertical, flat and at the right distance.

Observations are laser pixels (u, v) with their headings from scans of a room where the
robot faces a wall at a measured distance from the scanner axis (the wall's normal is
base_link x); each observation carries the distance of its scan. Floor points, when the
stripe reaches the floor, pin the height. One wall distance leaves the camera tilt and
height nearly interchangeable (both move the stripe alike at that range), so two scans,
near and far (e.g. 1.2 m and 3 m), are the reliable recipe.

Solved by robust nonlinear least squares (scipy) over corrections to a starting model:

| parameter            | what it moves                                              |
|----------------------|------------------------------------------------------------|
| laser_normal_1, _2   | the laser plane's normal, turned about two axes normal to it (rad) |
| vertical_separation  | the laser aperture along z relative to the camera (m)      |
| camera_tilt          | the camera's downward pitch b (rad)                         |
| camera_height        | the whole scanner (camera, laser, disk) along z (m)         |
| zero_offset          | the encoder disk's zero (rad)                               |
| wall_azimuth         | the wall's direction (rad), only with `facing=False`        |

Each parameter gets a standard deviation from a frame-clustered (sandwich) covariance:
errors along one frame's stripe are correlated, so treating every pixel as independent
would claim far too much. Parameters whose deviation exceeds a tolerance (about 1 cm at
4 m on its own) are reported as weakly determined; they may still trade off against
each other without moving any point. What decides is the point uncertainty the
covariance implies over the whole image at 1 m and at 4 m: `require_supported()`
refuses a calibration whose points are uncertain beyond POINT_LIMITS, or that leaves a
parameter with no information at all (deviation over 10 times its tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

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
MAX_ROUNDS = 8
# Largest acceptable p95 point uncertainty implied by the fit, per range band.
POINT_LIMITS = {"1 m": 0.01, "4 m": 0.02}  # the accuracy goals of the scanner
POINT_BANDS = {"1 m": (0.8, 1.2), "4 m": (3.5, 4.0)}
FINAL_BAND = 0.05  # m: points further than this from the wall or floor are not used


@dataclass(frozen=True)
class WallCalibration:
    """The calibrated model with what the data say about each parameter."""

    model: ScannerModel
    values: dict[str, float]  # fitted corrections to the starting model
    sigmas: dict[str, float]
    undetermined: tuple[str, ...]  # deviation above TOLERANCE: weakly determined
    point_sigma: dict[str, float]  # p95 point uncertainty (m) per range band, e.g. "1 m"
    rms: float  # m, wall and floor residuals
    wall_points: int
    floor_points: int
    notes: list[str] = field(default_factory=list)

    def require_supported(self) -> ScannerModel:
        """The model, or a CalibrationError naming what the data do not determine."""
        blind = [n for n in self.sigmas if self.sigmas[n] > 10.0 * TOLERANCE[n]]
        loose = [band for band, limit in POINT_LIMITS.items()
                 if not self.point_sigma.get(band, np.inf) <= limit]
        if blind or loose:
            detail = "; ".join(
                [f"{n} (sigma {self.sigmas[n]:.2g})" for n in blind]
                + [f"points at {b} (sigma {self.point_sigma.get(b, np.nan):.2g} m, limit "
                   f"{POINT_LIMITS[b]} m)" for b in loose])
            raise CalibrationError(
                f"the wall scans do not determine {detail}; scan the wall at two "
                "distances (near and far) with the floor in view, or fix these parameters")
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
        encoder=replace(model.encoder, height=model.encoder.height + lift,
                        zero_offset=model.encoder.zero_offset + get("zero_offset", 0.0)),
    )


def _rotate(vector: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of `vector` about the unit `axis`."""
    return (vector * np.cos(angle) + np.cross(axis, vector) * np.sin(angle)
            + axis * (axis @ vector) * (1.0 - np.cos(angle)))


def calibrate_wall(model: ScannerModel, u: np.ndarray, v: np.ndarray, heading: np.ndarray,
                   distance: float | np.ndarray, *, facing: bool = True,
                   fit: tuple[str, ...] | None = None,
                   floor_band: float = 0.15, wall_band: float = 0.3) -> WallCalibration:
    """Fit the scanner to a wall `distance` m in front of the robot (see module docstring).

    distance: one value, or one per observation (several scans at different distances).

    heading: the decoded heading of each observation; the encoder zero offset is solved as
    a shift of these headings. Points further than `wall_band` from the wall and
    `floor_band` from the floor under the starting model are ignored (other objects).
    """
    u, v, heading = (np.asarray(a, dtype=np.float64).ravel() for a in (u, v, heading))
    if not (u.shape == v.shape == heading.shape):
        raise CalibrationError("wall observations: u, v and heading differ in length")
    distance = np.broadcast_to(np.asarray(distance, dtype=np.float64), u.shape)
    if not np.all(np.isfinite(distance)) or np.any(distance <= model.min_range):
        raise CalibrationError(f"wall distance: expected ranges beyond {model.min_range} m, "
                               f"got {np.unique(distance)}")
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
        res_wall = along_wall[wall_mask] - distance[wall_mask]
        res_floor = points[floor_mask, 2]
        out = np.concatenate([res_wall, res_floor])
        return np.nan_to_num(out, nan=1.0)  # a point that left the valid range counts 1 m

    x = np.zeros(len(names))
    wall_mask = floor_mask = np.zeros(u.size, bool)
    # Continuation: classify points with the current estimate, solve with a robust scale
    # matched to the band, narrow the bands, repeat; wide bands first keep a poor start
    # from locking points into the wrong plane.
    for _ in range(MAX_ROUNDS):
        values = dict(zip(names, x, strict=True))
        points = triangulate(apply_corrections(model, values), u, v,
                             heading + values.get("zero_offset", 0.0)).points_base
        along = points @ rot_z(values.get("wall_azimuth", 0.0))[:, 0]
        ok = np.isfinite(points).all(axis=1)
        to_wall, to_floor = np.abs(along - distance), np.abs(points[:, 2])
        floor_mask = ok & (to_floor < floor_band) & (to_floor < to_wall)
        wall_mask = ok & ~floor_mask & (to_wall < wall_band)
        if wall_mask.sum() < 50:
            raise CalibrationError(
                f"wall calibration: only {wall_mask.sum()} points near a wall at "
                f"{np.unique(distance).tolist()} m; is the wall in front of the robot?")
        solution = least_squares(residuals_for, x, args=(wall_mask, floor_mask),
                                 loss="soft_l1", f_scale=max(0.005, wall_band / 10.0),
                                 x_scale=0.01, method="trf")
        step = np.abs(solution.x - x).max()
        x = solution.x
        if wall_band <= FINAL_BAND and step < 1e-7:
            break
        wall_band = max(FINAL_BAND, wall_band * 0.5)
        floor_band = max(FINAL_BAND, floor_band * 0.5)

    residual = residuals_for(x, wall_mask, floor_mask)
    jac = solution.jac
    frames = np.concatenate([heading[wall_mask], heading[floor_mask]])
    cov = clustered_covariance(jac, residual, frames)
    sigmas = dict(zip(names, np.sqrt(np.diag(cov)).tolist(), strict=True))
    undetermined = tuple(n for n in names if sigmas[n] > TOLERANCE[n])
    values = dict(zip(names, x.tolist(), strict=True))
    notes = []
    if not facing:
        notes.append("zero_offset is not solved: the wall's direction is free (facing=False)")
    return WallCalibration(
        model=apply_corrections(model, values), values=values, sigmas=sigmas,
        undetermined=undetermined, point_sigma=point_uncertainty(model, names, x, cov),
        rms=float(np.sqrt(np.mean(residual**2))), wall_points=int(wall_mask.sum()),
        floor_points=int(floor_mask.sum()), notes=notes)


def clustered_covariance(jac: np.ndarray, residual: np.ndarray, groups: np.ndarray
                         ) -> np.ndarray:
    """Sandwich covariance H^-1 (sum_g s_g s_g^T) H^-1 with s_g = J_g^T r_g per group.

    Robust to errors that are correlated within a group (one frame) and independent
    between groups. H is regularised so that a flat direction gets a huge variance.
    """
    n = jac.shape[1]
    hessian = jac.T @ jac
    hessian += REGULARISATION * np.trace(hessian) * np.eye(n) / n
    inverse = np.linalg.inv(hessian)
    _, label = np.unique(groups, return_inverse=True)
    scores = np.zeros((label.max() + 1, n))
    np.add.at(scores, label, jac * residual[:, None])
    meat = scores.T @ scores
    # A flat direction has no score either; give it the white-noise variance instead.
    white = inverse * float(residual @ residual) / max(1, residual.size - n)
    return np.maximum(inverse @ meat @ inverse, white)


def point_uncertainty(model: ScannerModel, names: tuple[str, ...], x: np.ndarray,
                      cov: np.ndarray) -> dict[str, float]:
    """p95 over the image of the point uncertainty (m) the covariance implies, per band."""
    u = np.repeat(np.arange(0.0, model.camera.width, 8.0), model.camera.height // 8)
    v = np.tile(np.arange(0.0, model.camera.height, 8.0), model.camera.width // 8)

    def points(values: np.ndarray) -> np.ndarray:
        corrected = apply_corrections(model, dict(zip(names, values, strict=True)))
        return triangulate(corrected, u, v, 0.0).points_head

    centre = points(x)
    step = 1e-6
    jac = np.stack([(points(x + step * e) - points(x - step * e)) / (2 * step)
                    for e in np.eye(len(names))], axis=-1)  # (N, 3, n)
    variance = np.einsum("pij,jk,pik->p", jac, cov, jac)
    rng = np.hypot(centre[:, 0], centre[:, 1])
    out = {}
    for band, (low, high) in POINT_BANDS.items():
        inside = np.isfinite(variance) & (rng >= low) & (rng < high)
        if inside.any():
            out[band] = float(np.sqrt(np.percentile(variance[inside], 95)))
    return out


def calibrate_wall_recordings(recordings, distances, start: ScannerModel,
                              rounds: int = 3) -> WallCalibration:
    """Wall calibration from the first scan of each recording (one distance each).

    Headings are decoded from the disk through the camera's geometry, which the fit
    changes: each round decodes the frames again with the latest model.
    """
    from ..assembly import ScanAssembler

    decoding, result = start, None
    for _ in range(rounds):
        parts = []
        for recording, distance in zip(recordings, distances, strict=True):
            assembler = ScanAssembler(decoding)
            for frame in recording.frames(recording.scans[0].index):
                assembler.add_frame(frame.image, frame.time)
            u, v, heading = assembler.observations()
            parts.append((u, v, heading, np.full(u.size, float(distance))))
        u, v, heading, distance = (np.concatenate(k) for k in zip(*parts, strict=True))
        # The decoding model's zero offset holds the last fit; keep the fit relative to start.
        heading = heading - (decoding.encoder.zero_offset - start.encoder.zero_offset)
        known = np.isfinite(heading)
        result = calibrate_wall(start, u[known], v[known], heading[known], distance[known])
        decoding = result.model
    return result
