"""Synthetic camera frames with known truth, for the laser and encoder tests and benchmarks.

Laser stripes are rendered as pixel-integrated Gaussians (the exact subpixel centre is
known) over a dark or bright scene with red objects, then clipped, noised, quantised and
optionally passed through MJPG (4:2:0 chroma subsampling, as webcams deliver).

Encoder frames are rendered forward, independently of the decoder's inverse mapping
(rays intersected with the disk plane): points sampled densely on the disk's printed
face are projected forward by OpenCV's camera model (`triangulation.project_head_points`,
checked against cv2.projectPoints in the tests), averaged per pixel, then
defocus-blurred with a Gaussian.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np
from scipy.special import ndtr

from ..scanner_model import ScannerModel
from ..transforms import invert_pose
from ..triangulation import project_head_points

LASER_BGR = np.array([0.05, 0.12, 1.0])  # red laser with a little crosstalk into G and B
RED_LIT = np.array([0.12, 0.18, 1.0])  # BGR scale of a scene lit by red light (a dark room)


def mjpg(image: np.ndarray, quality: int = 85) -> np.ndarray:
    """The image after a JPEG round trip with 4:2:0 chroma subsampling."""
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality,
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


def scene(rng: np.random.Generator, height: int, width: int, level: float,
          red_objects: int = 0, colourful: float = 0.1) -> np.ndarray:
    """A smooth textured scene (float BGR) around `level`, with red rectangles.

    Brightness varies by +-40 % over ~16 px cells; each channel varies independently by
    +-`colourful` on top (0.1: a mildly coloured room; 0.4: strongly coloured texture).
    """
    cells = (height // 16 + 1, width // 16 + 1)
    shade = rng.uniform(0.6, 1.4, (*cells, 1)) * rng.uniform(1 - colourful, 1 + colourful,
                                                             (*cells, 3))
    img = level * cv2.resize(shade, (width, height), interpolation=cv2.INTER_CUBIC)
    for _ in range(red_objects):
        h, w = rng.integers(20, 90, 2)
        v, u = rng.integers(0, height - h), rng.integers(0, width - w)
        img[v:v + h, u:u + w] = (0.25 * level, 0.25 * level, min(250.0, 1.6 * level + 60))
    return img


def stripe_path(rng: np.random.Generator, n_lines: int, n_pos: int) -> np.ndarray:
    """A smooth stripe position per line, far from the line ends, with every subpixel phase
    (the wave sweeps over a quarter of the line length). Smooth as on a surface: neighbouring
    lines' centres lie on a curve, not a sawtooth of subpixel phases, which no surface
    draws and which the fit's blend across lines would rightly blur."""
    u = np.arange(n_lines)
    centre = n_pos / 2 + rng.uniform(-0.1, 0.1) * n_pos
    wave = 0.25 * n_pos * np.sin(2 * np.pi * u / n_lines * rng.uniform(0.7, 1.6)
                                 + rng.uniform(0, 2 * np.pi))
    return centre + wave


def stripe_profile(pos: np.ndarray, centre: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian of unit peak integrated over each pixel [p - 0.5, p + 0.5]."""
    hi = ndtr((pos + 0.5 - centre) / sigma)
    lo = ndtr((pos - 0.5 - centre) / sigma)
    return (hi - lo) * math.sqrt(2 * math.pi) * sigma


def stripe_frame(rng: np.random.Generator, *, height: int = 480, width: int = 640,
                 sigma: float = 1.5, amplitude: float = 180.0, level: float = 20.0,
                 noise: float = 2.0, red_objects: int = 0, colourful: float = 0.1,
                 colour: np.ndarray = LASER_BGR, tint: np.ndarray | None = None,
                 jpeg: int | None = None, by_rows: bool = False,
                 truth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(BGR uint8 frame, true stripe position per line). Lines are columns unless by_rows.

    amplitude above 255 clips the red core (saturation); the scene is at `level`, its
    BGR channels scaled by `tint` (e.g. a red-lit object).
    """
    n_lines, n_pos = (height, width) if by_rows else (width, height)
    if truth is None:
        truth = stripe_path(rng, n_lines, n_pos)
    pos = np.arange(n_pos)[:, None]
    profile = stripe_profile(pos, truth[None, :], sigma)  # (n_pos, n_lines)
    if by_rows:
        profile = profile.T
    img = scene(rng, height, width, level, red_objects, colourful)
    if tint is not None:
        img *= np.asarray(tint)[None, None, :]
    img += amplitude * profile[:, :, None] * np.asarray(colour)[None, None, :]
    img += rng.normal(0.0, noise, img.shape)
    frame = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg is not None:
        frame = mjpg(frame, jpeg)
    return frame, truth


def saturated_core_frame(rng: np.random.Generator, *, core_width: float = 8.0,
                         sigma: float = 3.0, level: float = 150.0,
                         red_tint: np.ndarray = RED_LIT, **kwargs
                         ) -> tuple[np.ndarray, np.ndarray]:
    """A dark-room frame of a red-lit object crossed by a laser so strong that its core is
    clipped white over `core_width` px (green and blue saturated too) and its red over a
    wider band; (frame, true centre per line). kwargs go to `stripe_frame`."""
    colour = np.asarray(kwargs.pop("colour", LASER_BGR))
    scene_gb = level * np.asarray(red_tint)[:2].max()
    reach = math.exp(-0.5 * (0.5 * core_width / sigma) ** 2)  # profile at the core's edge
    amplitude = (255.0 - scene_gb) / (colour[:2].min() * reach)
    return stripe_frame(rng, sigma=sigma, amplitude=amplitude, level=level, tint=red_tint,
                        colour=colour, **kwargs)


def disk_points(model: ScannerModel, heading: float, step: float = 6e-5,
                arc: float = math.radians(55.0),
                texture: Callable[[np.ndarray], np.ndarray] | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) on the printed ring in `base_link`, and their printed value (0..1).

    The disk is centred on the head's axis, perpendicular to it, with its face at
    `base_link` height `encoder.height` on the axis; its angles are measured in the
    mount frame. Only base angles within `arc` of the heading are sampled: the camera
    sees the front arc of the ring. texture: value at disk-frame (N, 2) x, y (m), by
    default the model's code (`value_at`).
    """
    enc = model.encoder
    radii = np.arange(enc.inner_radius + step / 2, enc.outer_radius, step)
    n_ang = int(2 * arc * enc.outer_radius / step)
    angles = heading + (np.arange(n_ang) + 0.5) / n_ang * 2 * arc - arc
    rr, aa = np.meshgrid(radii, angles)
    mount = model.head_mount.pose
    lift = (enc.height - mount[2, 3]) / mount[2, 2]
    local = np.column_stack([rr.ravel() * np.cos(aa.ravel()), rr.ravel() * np.sin(aa.ravel()),
                             np.full(rr.size, lift)])
    base = np.einsum("ij,nj->ni", mount[:3, :3], local) + mount[:3, 3]
    values = enc.value_at(aa.ravel()) if texture is None else texture(local[:, :2])
    return base, np.asarray(values, dtype=np.float64)


def srgb(linear: np.ndarray) -> np.ndarray:
    """sRGB encoding (0..1) of linear light (0..1), as a webcam delivers it."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def disk_frame(model: ScannerModel, heading: float, rng: np.random.Generator, *,
               blur: float = 4.0, noise: float = 2.0, dark: float = 0.03, light: float = 0.6,
               background: float = 0.1, jpeg: int | None = None,
               texture: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """A BGR frame showing the encoder disk at `heading`, rendered forward (see module doc).

    dark, light, background: linear radiance (0..1) of the black and white print and of
    what lies beyond the ring; blurred in linear light, then sRGB-encoded, noised (grey
    levels) and quantised. texture: see disk_points.
    """
    cam = model.camera
    base, values = disk_points(model, heading, texture=texture)
    pose = invert_pose(model.head_pose(heading))
    head = np.einsum("ij,nj->ni", pose[:3, :3], base) + pose[:3, 3]
    pix = project_head_points(model, head)
    u, v = np.rint(pix[:, 0]), np.rint(pix[:, 1])
    inside = np.isfinite(u) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    idx = (v[inside] * cam.width + u[inside]).astype(np.int64)
    total = np.bincount(idx, weights=values[inside], minlength=cam.width * cam.height)
    hits = np.bincount(idx, minlength=cam.width * cam.height)
    seen = hits > 0
    img = np.full(cam.width * cam.height, background)
    img[seen] = dark + (light - dark) * total[seen] / hits[seen]
    img = img.reshape(cam.height, cam.width)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = 255.0 * srgb(img[:, :, None] * np.array([0.95, 1.0, 1.05])[None, None, :])
    img += rng.normal(0.0, noise, img.shape)
    frame = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg is not None:
        frame = mjpg(frame, jpeg)
    return frame
