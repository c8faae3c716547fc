"""Render the frames the scanner's webcam would deliver, with the truth behind every pixel.

One frame: the scene seen at the heading of mid-exposure (`hitmap`), shaded (`shading`)
and blurred by the head's rotation during the exposure (`motion_blur`); the encoder disk
below the lens, fixed in `base_link`, also blurred by the rotation and then defocused (the
lens is focused near 4 m); the laser stripe (`laser_stripe` for where, `laser_light` for
how), which co-rotates with the camera and is only swept where the geometry moves it; and
the camera (`camera_effects`): exposure, noise, mosaic, gamma and MJPG.

Photometry: radiance 1.0 fills a pixel at the reference exposure. A white surface in a
bright room (ambient 1) gives `SCENE_GAIN`; the laser on a white surface at 1 m and normal
incidence gives `LaserAppearance.power` in red.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..scanner_model import ScannerModel
from .camera_effects import SimCameraConfig, encode_mjpg, expose
from .geometry import World, rotate
from .hitmap import HitMap, hit_map
from .laser_light import defocus_diameter, draw_stripes, speckle, stripe_sigma
from .laser_stripe import (
    StripePoints,
    camera_rays,
    head_poses,
    points_from_hit_map,
    rows_at,
    stripe_points,
)
from .motion_blur import blur_along_flow, rotation_flow
from .plan import ScanPlan
from .scene import Scene
from .shading import LIGHT_DIRECTION, disk_albedo, shade_scene

SCENE_GAIN = 0.35
DISK_LIGHT = 0.5  # radiance of a white disk sector under its LED
EXPOSURE_PARTS = 1  # sub-intervals of the exposure for motion blur (the path's drift in u)
ROLLING_ITERATIONS = 3
DISK_MARGIN = 24  # columns beside the disk's footprint that its blur may reach


@dataclass(frozen=True)
class LaserAppearance:
    """The laser's brightness and look; see `laser_light`.

    power: red radiance on a white surface at 1 m, normal incidence.
    crosstalk: the camera's (R, G, B) response to the laser's red light.
    mask_threshold: laser signal (full-scale fraction) that counts as a laser pixel.
    """

    power: float = 2.7
    crosstalk: tuple[float, float, float] = (1.0, 0.08, 0.02)
    sigma: float = 1.5
    speckle: float = 0.3
    mask_threshold: float = 0.005


@dataclass(frozen=True)
class FrameTruth:
    """What is true behind one frame.

    time: local mid-exposure time (s); heading: true heading then (rad);
    base_pose: true T_map_base; stripe: every stripe point the camera sees (lit or in the
    laser's shadow), each with its own heading (different from `heading` only under a
    rolling shutter); primary: the strongest lit point of each column;
    laser_mask: (H, W) pixels where the laser adds at least `mask_threshold`.
    """

    time: float
    heading: float
    base_pose: np.ndarray
    stripe: StripePoints
    primary: np.ndarray
    laser_mask: np.ndarray


@dataclass(frozen=True)
class FrameLight:
    """The light of one frame before the camera: RGB radiance (H, W, 3), the laser's own
    red radiance (H, W), the disk's coverage (H, W, 0..1), and the truth."""

    radiance: np.ndarray
    laser: np.ndarray
    disk: np.ndarray
    truth: FrameTruth


@dataclass(frozen=True)
class RenderedFrame:
    """A frame as the webcam delivers it (MJPG: JPEG bytes) and its truth."""

    jpeg: bytes
    truth: FrameTruth

    @functools.cached_property
    def image(self) -> np.ndarray:
        """The frame decoded to BGR, as OpenCV hands it over (decoded on first use)."""
        return cv2.imdecode(np.frombuffer(self.jpeg, dtype=np.uint8), cv2.IMREAD_COLOR)


@dataclass
class Renderer:
    """Renders frames of one scene for one scanner model.

    hit_step: rows between directly cast rows (`hitmap`); scene_step: the scene (not the
    laser, the disk or the truth) is shaded on every scene_step-th image row and
    interpolated between them, which the motion blur along the rows hides.
    """

    scene: Scene
    model: ScannerModel
    camera: SimCameraConfig = field(default_factory=SimCameraConfig)
    laser: LaserAppearance = field(default_factory=LaserAppearance)
    hit_step: int = 4
    scene_step: int = 2
    threads: int = 1

    def __post_init__(self) -> None:
        self.world = World(self.scene, self.model.encoder)
        self._scan_world: tuple[int, World] | None = None  # people placed for one scan
        self.rays = camera_rays(self.model)
        self._disk_columns = self._find_disk_columns()
        self._scene_rows = np.arange(0, self.model.camera.height, self.scene_step)
        self._scene_directions = np.ascontiguousarray(self.rays.directions[self._scene_rows])
        self._disk_directions = np.ascontiguousarray(
            self.rays.directions[:, self._disk_columns:])

    def world_at(self, index: int) -> World:
        """The world scan `index` sees: the scene with its people where their tracks put
        them then (`Scene.at_scan`); built once per scan, kept while its frames render."""
        if not self.scene.people:
            return self.world
        if self._scan_world is None or self._scan_world[0] != index:
            self._scan_world = (index, World(self.scene.at_scan(index), self.model.encoder))
        return self._scan_world[1]

    def _find_disk_columns(self) -> int:
        """First image column where the disk (or its blur) can appear at any heading."""
        height, width = self.rays.laser_t.shape
        first = width
        directions = self.rays.directions.reshape(-1, 3)
        for heading in np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False):
            _, base_head = head_poses(self.model, np.eye(4)[None], np.array([heading]))
            rotation, shift = base_head[0, :3, :3], base_head[0, :3, 3]
            t = self.model.encoder.ray_distance(rotation @ self.rays.centre + shift,
                                                rotate(directions, rotation)
                                                ).reshape(height, width)
            cols = np.flatnonzero(np.isfinite(t).any(axis=0))
            if cols.size:
                first = min(first, int(cols[0]))
        return max(first - DISK_MARGIN, 0)

    def _offsets(self, plan: ScanPlan, time: float) -> tuple[np.ndarray, np.ndarray]:
        """Row read-out times (H,) and heading offsets (H, parts + 1) over the exposure."""
        height = self.model.camera.height
        rows = (np.arange(height) - 0.5 * (height - 1)) / max(height - 1, 1)
        row_time = time + self.camera.rolling_shutter * rows
        parts = np.linspace(-0.5, 0.5, EXPOSURE_PARTS + 1) * self.camera.exposure
        offsets = plan.motion.heading_at(row_time[:, None] + parts[None, :]) \
            - plan.motion.heading_at(time)
        return row_time, offsets

    def render(self, plan: ScanPlan, frame: int, rng: np.random.Generator) -> RenderedFrame:
        """Frame `frame` of scan `plan` as the webcam delivers it, noise drawn from `rng`."""
        light = self.light(plan, frame, rng)
        image = expose(light.radiance, self.camera, rng)
        return RenderedFrame(encode_mjpg(image, self.camera), light.truth)

    def light(self, plan: ScanPlan, frame: int, rng: np.random.Generator) -> FrameLight:
        """The light reaching the sensor during frame `frame` of scan `plan`."""
        model, rays = self.model, self.rays
        time = float(plan.frame_times[frame])
        heading = float(plan.motion.heading_at(time))
        base = plan.base_poses_at(time)[0]
        map_head, base_head = head_poses(model, base[None], np.array([heading]))
        map_head, base_head = map_head[0], base_head[0]
        row_time, offsets = self._offsets(plan, time)
        rows, directions = self._scene_rows, self._scene_directions
        world = self.world_at(plan.index)
        hits = hit_map(world.world, rays.centre, directions, map_head, self.hit_step,
                       self.threads)
        radiance = shade_scene(hits.plane, hits.t, directions, rays.centre,
                               map_head[:3, :3], map_head[:3, 3],
                               world.world.planes.planes[:, :3], world.plane_axes,
                               world.plane_albedo,
                               LIGHT_DIRECTION, self.scene.ambient * SCENE_GAIN,
                               self.scene.texture)
        flow = self._flow(hits.t, directions)
        flow[:, :, 1] /= self.scene_step  # in rows of the coarse grid
        radiance = between_rows(blur_along_flow(radiance, flow, offsets[rows]), rows,
                                model.camera.height)
        stripe = self._stripe(world, plan, hits, rows, base, heading, row_time)
        laser = self._laser_layer(world, plan, stripe, base, row_time, rng)
        for channel, share in enumerate(self.laser.crosstalk):
            radiance[:, :, channel] += np.float32(share) * laser
        scene_t = np.repeat(hits.t, self.scene_step, axis=0)[:model.camera.height]
        covered = self._add_disk(radiance, scene_t, base_head, offsets)
        mask = (laser * self.camera.scale >= self.laser.mask_threshold) & (covered < 0.5)
        truth = FrameTruth(time, heading, base, stripe, stripe.strongest_per_column(), mask)
        return FrameLight(radiance, laser, covered, truth)

    def _flow(self, t: np.ndarray, directions: np.ndarray) -> np.ndarray:
        cam = self.model.camera
        return rotation_flow(t, directions, self.rays.centre,
                             self.model.camera_mount.rotation, cam.fx, cam.fy)

    def _stripe(self, world: World, plan: ScanPlan, hits: HitMap, rows: np.ndarray,
                base: np.ndarray, heading: float, row_time: np.ndarray) -> StripePoints:
        """Every visible stripe point; under a rolling shutter, each at its row's heading."""
        points = points_from_hit_map(world, self.model, hits.plane, hits.t, rows, base,
                                     heading, self.threads)
        if self.camera.rolling_shutter == 0.0 or len(points) == 0:
            return points
        bases = np.repeat(base[None], len(points), axis=0)
        v = points.v
        for _ in range(ROLLING_ITERATIONS):
            headings = plan.motion.heading_at(np.interp(v, np.arange(row_time.size), row_time))
            v = rows_at(world, self.model, points, bases, headings)
        return stripe_points(world, self.model, np.arange(len(points)), points.u, v,
                             points.plane, bases, headings, self.threads)

    def _laser_layer(self, world: World, plan: ScanPlan, stripe: StripePoints,
                     base: np.ndarray, row_time: np.ndarray, rng: np.random.Generator
                     ) -> np.ndarray:
        """(H, W) red laser radiance of the lit stripe points, swept over the exposure."""
        cam = self.model.camera
        layer = np.zeros((cam.height, cam.width), dtype=np.float32)
        lit = stripe.select(stripe.lit)
        if len(lit) == 0:
            return layer
        bases = np.repeat(base[None], len(lit), axis=0)
        when = np.interp(lit.v, np.arange(row_time.size), row_time)
        half = 0.5 * self.camera.exposure
        v_open = rows_at(world, self.model, lit, bases, plan.motion.heading_at(when - half))
        v_close = rows_at(world, self.model, lit, bases, plan.motion.heading_at(when + half))
        v_open = np.where(np.isfinite(v_open), v_open, lit.v)
        v_close = np.where(np.isfinite(v_close), v_close, lit.v)
        depth = (lit.head - self.rays.centre) @ self.model.camera_mount.rotation[:, 2]
        sigma = stripe_sigma(self.laser.sigma, defocus_diameter(
            depth, cam.fx, self.camera.aperture, self.camera.focus_distance))
        peak = self.laser.power * lit.strength * self.laser.sigma / sigma
        draw_stripes(layer, lit.u.astype(np.int64), v_open, v_close, peak, sigma,
                     speckle(rng, len(lit), self.laser.speckle))
        return layer

    def _add_disk(self, radiance: np.ndarray, scene_t: np.ndarray, base_head: np.ndarray,
                  offsets: np.ndarray) -> np.ndarray:
        """Composite the blurred, defocused disk over `radiance` (in place); its coverage."""
        first = self._disk_columns
        height, width = scene_t.shape
        coverage = np.zeros((height, width), dtype=np.float32)
        if first >= width:
            return coverage
        rotation, shift = base_head[:3, :3], base_head[:3, 3]
        directions = rotate(self._disk_directions.reshape(-1, 3), rotation)
        origin = rotation @ self.rays.centre + shift
        t = self.model.encoder.ray_distance(origin, directions).reshape(height, -1)
        on_disk = t < scene_t[:, first:]
        if not on_disk.any():
            return coverage
        points = origin + t[on_disk][:, None] * directions.reshape(height, -1, 3)[on_disk]
        layer = np.zeros((height, width - first, 2), dtype=np.float32)
        layer[on_disk, 0] = DISK_LIGHT * disk_albedo(self.model.encoder, points)
        layer[on_disk, 1] = 1.0
        depth_t = np.where(on_disk, t, scene_t[:, first:])
        layer = blur_along_flow(layer, self._flow(depth_t, self._disk_directions), offsets)
        depth = float(np.median(t[on_disk]))
        diameter = float(defocus_diameter(depth, self.model.camera.fx, self.camera.aperture,
                                          self.camera.focus_distance))
        layer = cv2.filter2D(layer, -1, pillbox(diameter), borderType=cv2.BORDER_REPLICATE)
        alpha = layer[:, :, 1:2]
        region = radiance[:, first:]
        region *= 1.0 - alpha
        region += layer[:, :, 0:1]
        coverage[:, first:] = alpha[:, :, 0]
        return coverage


def between_rows(image: np.ndarray, rows: np.ndarray, height: int) -> np.ndarray:
    """(height, W, C) image from its rows `rows` (increasing), linear in between and
    constant beyond the last."""
    if rows.size == height:
        return image
    full = np.empty((height, *image.shape[1:]), dtype=image.dtype)
    below = np.clip(np.searchsorted(rows, np.arange(height), side="right") - 1, 0,
                    rows.size - 1)
    above = np.minimum(below + 1, rows.size - 1)
    span = np.maximum(rows[above] - rows[below], 1)
    weight = (np.clip(np.arange(height) - rows[below], 0, None) / span).astype(image.dtype)
    weight = weight[:, None, None]
    np.multiply(image[below], 1 - weight, out=full)
    full += image[above] * weight
    return full


def pillbox(diameter: float) -> np.ndarray:
    """Normalised uniform-disc kernel of the given diameter (px), antialiased at its rim."""
    radius = max(0.5 * diameter, 0.5)
    size = math.ceil(radius) * 2 + 1
    c = size // 2
    y, x = np.mgrid[0:size, 0:size] - c
    kernel = np.clip(radius + 0.5 - np.hypot(x, y), 0.0, 1.0).astype(np.float32)
    return kernel / kernel.sum()
