"""The scanner model: camera intrinsics, camera and laser in the rotating head, encoder disk.

Frames (docs/architecture.md): `base_link` has its origin on the floor under the scanner axis;
`head` is `base_link` (through the optional `head_mount`) turned about z by the heading
theta; `camera` is OpenCV's optical frame (z forward, x right, y down), mounted on its
side so that the 640-pixel image side is vertical: image u grows toward the floor and
image v grows to the left. The laser plane and the camera are fixed in `head`; the
encoder disk is fixed in `base_link`.

The reference scanner (`reference_scanner()`) reproduces the paper's device in numbers:

* Camera: 640x480, 35 deg across the 640-pixel side, so f = 320 / tan(17.5 deg) =
  1014.9 px; 25 frames/s; no distortion (a calibrated model carries its own).
* Camera at 1.00 m above the floor, 0.07 m behind the axis, pitched down by b = 18 deg:
  the view spans 0.5 deg above to 35.5 deg below the horizon, so the floor enters the
  view 1.4 m out and 1 m height stays in view out to 4 m.
* Laser aperture 0.50 m straight below the lens (vertical baseline B = 0.5 m). The laser
  fan points forward, pitched 8 deg up, and its line is rolled 60 deg from horizontal
  (the paper's "angled laser line"): each frame's stripe runs across all 640 image lines
  while the head sweeps it round a volume from the floor to about 1 m.
* Accuracy: triangulating along an image line (fixed u, peak at v), one pixel of peak
  error costs |dP/dv| = 0.053 m at 4 m, 0.015 m at 2 m and 0.004 m at 1 m
  (Z^2 / (f B) scaled by the stripe's 60 deg roll): whole-pixel peaks (error up to
  0.5 px) stay within the paper's 0.05 m at 4 m, and a 0.1 px subpixel peak gives 5 mm.
* Coverage, checked numerically over the image: ranges 0.3-4 m; at 0.3-0.5 m the
  stripe is seen at 0.66-0.81 m height, from 1 m out it covers 0.3-1 m, and from 1.4 m
  out the whole band from the floor to 1 m.
* Encoder disk: 32 sectors carrying a de Bruijn B(2,5) code on a ring of radius
  0.035-0.050 m, 0.073 m below the lens (z = 0.927 m). Behind the axis, the camera sees
  the ring's front arc at the bottom of the view (u > ~560), about 0.13 m from the lens,
  spanning about +-30 deg of disk angle: more than the 5 sectors that fix the heading.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from .encoder_disk import EncoderDisk, de_bruijn
from .errors import CalibrationError
from .files import read_json, write_json
from .transforms import make_pose, rot_x, rot_y, rot_z
from .validate import check_keys, integer, number, vector

FORMAT = "scanmap.scanner/1"
MAX_IMAGE_SIDE = 16384  # pixels: larger is damage, and would allocate gigabytes per frame

# Columns: the optical x, y, z axes of a level, side-mounted camera, expressed in `head`.
# x (image u) points down, y (image v) points left, z (optical axis) points forward.
SIDE_MOUNT = np.column_stack([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics with OpenCV's (k1, k2, p1, p2, k3) distortion, in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    frame_rate: float = 25.0

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients as OpenCV expects them."""
        return np.array(self.distortion, dtype=np.float64)


@dataclass(frozen=True)
class CameraMount:
    """The camera's optical centre in `head` and its orientation.

    tilt: downward pitch of the optical axis (rad), the paper's angle b.
    yaw: turn of the optical axis about the head's z (rad).
    roll: turn about the optical axis (rad) beyond the 90 deg side mounting.
    """

    position: tuple[float, float, float]
    tilt: float
    yaw: float = 0.0
    roll: float = 0.0

    @property
    def rotation(self) -> np.ndarray:
        """R_head_camera: optical-frame directions into `head`."""
        return rot_z(self.yaw) @ rot_y(self.tilt) @ SIDE_MOUNT @ rot_z(self.roll)

    @property
    def pose(self) -> np.ndarray:
        """T_head_camera, 4x4."""
        return make_pose(self.rotation, np.array(self.position))


@dataclass(frozen=True)
class LaserPlane:
    """The laser plane in `head`: the laser aperture (a point of the plane) and unit normal."""

    origin: tuple[float, float, float]
    normal: tuple[float, float, float]

    def __post_init__(self) -> None:
        norm = float(np.linalg.norm(self.normal))
        if not abs(norm - 1.0) < 1e-9:
            raise CalibrationError(f"laser.normal: expected a unit vector, got norm {norm}")

    @classmethod
    def from_point_normal(cls, origin: Any, normal: Any) -> LaserPlane:
        """Plane through `origin` with the normalised `normal` (a normal already unit to
        1e-12 is kept bit for bit, so that a saved model loads back identical)."""
        normal = np.asarray(normal, dtype=np.float64)
        norm = np.linalg.norm(normal)
        if not np.isfinite(norm) or norm < 1e-12:
            raise CalibrationError(f"laser.normal: expected a non-zero vector, got {normal}")
        if abs(norm - 1.0) > 1e-12:
            normal = normal / norm
        return cls(tuple(map(float, origin)), tuple(map(float, normal)))

    @classmethod
    def from_angles(cls, origin: Any, pitch: float, roll: float) -> LaserPlane:
        """A fan pointing along head x, pitched up by `pitch`, its line rolled by `roll`."""
        forward = np.array([math.cos(pitch), 0.0, math.sin(pitch)])
        across = np.array([0.0, math.cos(roll), math.sin(roll)])
        across -= forward * (forward @ across)
        return cls.from_point_normal(origin, np.cross(forward, across))

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of `head` points from the plane."""
        return (np.asarray(points) - np.array(self.origin)) @ np.array(self.normal)


@dataclass(frozen=True)
class HeadMount:
    """Where the head's axis stands in `base_link`, and its tilt (0 for an upright mount)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roll: float = 0.0
    pitch: float = 0.0

    @property
    def pose(self) -> np.ndarray:
        """T_base_mount, 4x4: the head frame at heading 0."""
        return make_pose(rot_x(self.roll) @ rot_y(self.pitch), np.array(self.position))


@dataclass(frozen=True)
class ScannerModel:
    """Everything needed to turn a laser pixel and a heading into a point, and back.

    min_range, max_range: valid horizontal distance from the head axis (m).
    min_ray_plane_angle: rays closer than this to the laser plane are rejected (rad).
    pixel_sigma: standard deviation of the laser peak along the image line (px), used
        for the per-point range uncertainty.
    """

    camera: CameraIntrinsics
    camera_mount: CameraMount
    laser: LaserPlane
    encoder: EncoderDisk
    head_mount: HeadMount = field(default_factory=HeadMount)
    min_range: float = 0.3
    max_range: float = 4.0
    min_ray_plane_angle: float = math.radians(1.0)
    pixel_sigma: float = 0.1
    name: str = "scanner"

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_range < self.max_range:
            raise CalibrationError(
                f"limits: expected 0 <= min_range < max_range, got {self.min_range}, "
                f"{self.max_range}")
        plane_offset = self.laser.signed_distance(np.array(self.camera_mount.position))
        if abs(plane_offset) < 1e-3:
            raise CalibrationError(
                "laser: the camera centre lies on the laser plane (baseline "
                f"{plane_offset:.2e} m); triangulation is impossible")

    def head_pose(self, heading: float) -> np.ndarray:
        """T_base_head at a heading (rad)."""
        return self.head_mount.pose @ make_pose(rot_z(heading), np.zeros(3))

    def head_poses(self, headings: np.ndarray) -> np.ndarray:
        """(N, 4, 4) T_base_head at each of N headings (rad): `head_pose`, vectorised."""
        headings = np.asarray(headings, dtype=np.float64).reshape(-1)
        spin = np.zeros((headings.shape[0], 4, 4))
        c, s = np.cos(headings), np.sin(headings)
        spin[:, 0, 0], spin[:, 0, 1], spin[:, 1, 0], spin[:, 1, 1] = c, -s, s, c
        spin[:, 2, 2] = spin[:, 3, 3] = 1.0
        return self.head_mount.pose @ spin

    @property
    def baseline(self) -> float:
        """Distance (m) from the camera centre to the laser plane."""
        return float(abs(self.laser.signed_distance(np.array(self.camera_mount.position))))

    def with_changes(self, **changes: Any) -> ScannerModel:
        """A copy with some fields replaced (the model is frozen)."""
        return replace(self, **changes)

    # -- JSON -----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The `scanmap.scanner/1` JSON object."""
        cam = asdict(self.camera)
        cam["distortion"] = list(self.camera.distortion)
        return {
            "format": FORMAT,
            "name": self.name,
            "camera": cam,
            "camera_mount": {**asdict(self.camera_mount),
                             "position": list(self.camera_mount.position)},
            "laser": {"origin": list(self.laser.origin), "normal": list(self.laser.normal)},
            "encoder": asdict(self.encoder),
            "head_mount": {**asdict(self.head_mount),
                           "position": list(self.head_mount.position)},
            "limits": {"min_range": self.min_range, "max_range": self.max_range,
                       "min_ray_plane_angle": self.min_ray_plane_angle},
            "pixel_sigma": self.pixel_sigma,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model as `scanmap.scanner/1` JSON (atomically)."""
        write_json(path, self.to_dict())

    @classmethod
    def from_dict(cls, data: Any, source: str = "scanner") -> ScannerModel:
        """Validate and build a model; errors name `source` and the bad field."""
        err = CalibrationError

        def where(name: str) -> str:
            return f"{source}: {name}"

        top = check_keys(data, where("(top level)"), err,
                         ["format", "camera", "camera_mount", "laser", "encoder"],
                         ["name", "head_mount", "limits", "pixel_sigma"])
        if top["format"] != FORMAT:
            raise err(f"{where('format')}: expected {FORMAT!r}, got {top['format']!r}")

        c = check_keys(top["camera"], where("camera"), err,
                       ["width", "height", "fx", "fy", "cx", "cy"], ["distortion", "frame_rate"])
        dist = vector(c.get("distortion", [0.0] * 5), 5, where("camera.distortion"), err)
        for side in ("width", "height"):
            if integer(c[side], where(f"camera.{side}"), err, low=1) > MAX_IMAGE_SIDE:
                raise err(f"{where(f'camera.{side}')}: expected at most {MAX_IMAGE_SIDE} "
                          f"pixels, got {c[side]}")
        if not isinstance(top.get("name", ""), str):
            raise err(f"{where('name')}: expected a string, got {top['name']!r}")
        camera = CameraIntrinsics(
            width=c["width"], height=c["height"],
            fx=number(c["fx"], where("camera.fx"), err, low=0.0, low_open=True),
            fy=number(c["fy"], where("camera.fy"), err, low=0.0, low_open=True),
            cx=number(c["cx"], where("camera.cx"), err),
            cy=number(c["cy"], where("camera.cy"), err),
            distortion=tuple(map(float, dist)),
            frame_rate=number(c.get("frame_rate", 25.0), where("camera.frame_rate"), err,
                              low=0.0, low_open=True),
        )
        m = check_keys(top["camera_mount"], where("camera_mount"), err,
                       ["position", "tilt"], ["yaw", "roll"])
        mount = CameraMount(
            position=tuple(vector(m["position"], 3, where("camera_mount.position"), err)),
            tilt=number(m["tilt"], where("camera_mount.tilt"), err, low=-math.pi, high=math.pi),
            yaw=number(m.get("yaw", 0.0), where("camera_mount.yaw"), err),
            roll=number(m.get("roll", 0.0), where("camera_mount.roll"), err),
        )
        la = check_keys(top["laser"], where("laser"), err, ["origin", "normal"])
        try:
            laser = LaserPlane.from_point_normal(
                vector(la["origin"], 3, where("laser.origin"), err),
                vector(la["normal"], 3, where("laser.normal"), err))
        except CalibrationError as exc:
            raise err(f"{source}: {exc}") from None
        e = check_keys(top["encoder"], where("encoder"), err,
                       ["height", "inner_radius", "outer_radius", "code"], ["zero_offset"])
        if not isinstance(e["code"], str):
            raise err(f"{where('encoder.code')}: expected a string of '0'/'1'")
        try:
            encoder = EncoderDisk(
                height=number(e["height"], where("encoder.height"), err),
                inner_radius=number(e["inner_radius"], where("encoder.inner_radius"), err),
                outer_radius=number(e["outer_radius"], where("encoder.outer_radius"), err),
                code=e["code"],
                zero_offset=number(e.get("zero_offset", 0.0), where("encoder.zero_offset"), err),
            )
        except CalibrationError as exc:
            raise err(f"{source}: {exc}") from None
        h = check_keys(top.get("head_mount", {}), where("head_mount"), err, [],
                       ["position", "roll", "pitch"])
        head = HeadMount(
            position=tuple(vector(h.get("position", [0.0, 0.0, 0.0]), 3,
                                  where("head_mount.position"), err)),
            roll=number(h.get("roll", 0.0), where("head_mount.roll"), err),
            pitch=number(h.get("pitch", 0.0), where("head_mount.pitch"), err),
        )
        lim = check_keys(top.get("limits", {}), where("limits"), err, [],
                         ["min_range", "max_range", "min_ray_plane_angle"])
        try:
            return cls(
                camera=camera, camera_mount=mount, laser=laser, encoder=encoder,
                head_mount=head,
                min_range=number(lim.get("min_range", 0.3), where("limits.min_range"), err,
                                 low=0.0),
                max_range=number(lim.get("max_range", 4.0), where("limits.max_range"), err,
                                 low=0.0, low_open=True),
                min_ray_plane_angle=number(lim.get("min_ray_plane_angle", math.radians(1.0)),
                                           where("limits.min_ray_plane_angle"), err,
                                           low=0.0, high=math.pi / 2),
                pixel_sigma=number(top.get("pixel_sigma", 0.1), where("pixel_sigma"), err,
                                   low=0.0, low_open=True),
                name=top.get("name", "scanner"),
            )
        except CalibrationError as exc:
            if str(exc).startswith(source):
                raise
            raise err(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ScannerModel:
        """Read and validate a `scanmap.scanner/1` file."""
        return cls.from_dict(read_json(path, CalibrationError), source=str(path))


def reference_scanner() -> ScannerModel:
    """The paper's device in numbers; the reasoning is in this module's docstring."""
    f = 320.0 / math.tan(math.radians(17.5))
    camera_x, camera_z, laser_z = -0.07, 1.00, 0.50
    return ScannerModel(
        camera=CameraIntrinsics(width=640, height=480, fx=f, fy=f, cx=319.5, cy=239.5),
        camera_mount=CameraMount(position=(camera_x, 0.0, camera_z), tilt=math.radians(18.0)),
        laser=LaserPlane.from_angles((camera_x, 0.0, laser_z), pitch=math.radians(8.0),
                                     roll=math.radians(60.0)),
        encoder=EncoderDisk(height=0.927, inner_radius=0.035, outer_radius=0.050,
                            code=de_bruijn(5)),
        name="reference",
    )
