"""What a scanner sees of flat floor round it, from its geometry alone.

The laser's plane meets the floor z = 0 of `base_link` along a line at each heading. A
point of that line is measured where the camera sees it inside its image, unhidden by
the encoder disk (nor is the laser's light), and triangulation accepts it (within the
model's ranges from the head's axis, the camera's ray not too near the laser plane). The
nearest and farthest such points, over the headings, bound the floor the scanner ever
measures from where the robot stands: the reference scanner, its camera 1 m up and
tilted 18 deg, sees the floor 1.495-3.999 m off (its simulator's flat floor, 1.493-4.000
m). The floor segmentation's drop-off rules need these (`FloorConfig.for_scanner`), so
a scanner built to other dimensions needs no hand-set copy of them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .errors import CalibrationError
from .scanner_model import ScannerModel
from .triangulation import project_head_points, triangulate

HEADINGS = 8  # sampled over a turn: a tilted or offset head sees the floor unevenly
SAMPLE_STEP = 0.002  # m between the points sampled along the laser's floor line


@dataclass(frozen=True)
class FloorView:
    """The floor a scanner measures, from `base_link`'s z axis (where the robot stands).

    nearest, farthest: horizontal distances (m) of the nearest and farthest floor points
    it measures at any heading. emitter_height: the laser emitter's height (m) over the
    floor, averaged over a turn.
    """

    nearest: float
    farthest: float
    emitter_height: float


@functools.lru_cache(maxsize=16)
def floor_view(model: ScannerModel) -> FloorView:
    """The floor `model` measures round it (see the module); CalibrationError naming the
    model when its laser lights no floor that its camera sees."""
    reach = 3.0 * model.max_range + float(np.linalg.norm(model.head_mount.position))
    along = np.arange(-reach, reach, SAMPLE_STEP)
    nearest, farthest, emitter_heights = math.inf, 0.0, []
    for heading in np.arange(HEADINGS) * (2.0 * math.pi / HEADINGS):
        base_head = model.head_pose(heading)
        rotation, shift = base_head[:3, :3], base_head[:3, 3]
        emitter = rotation @ np.array(model.laser.origin) + shift
        emitter_heights.append(float(emitter[2]))
        floor = _laser_floor_line(emitter, rotation @ np.array(model.laser.normal), along)
        if floor is None:
            continue
        ranges = np.hypot(floor[:, 0], floor[:, 1])[_measured(model, heading, floor)]
        if ranges.size:
            nearest, farthest = min(nearest, float(ranges.min())), max(farthest,
                                                                       float(ranges.max()))
    if not farthest:
        raise CalibrationError(f"{model.name}: its laser lights no floor (z = 0 of "
                               "base_link) that its camera sees at any heading")
    return FloorView(nearest, farthest, float(np.mean(emitter_heights)))


def _laser_floor_line(origin: np.ndarray, normal: np.ndarray, along: np.ndarray
                      ) -> np.ndarray | None:
    """Points (N, 3) of the line where the plane through `origin` with `normal` meets
    z = 0, at signed distances `along` from its point nearest the z axis; None when the
    plane lies level (it never meets the floor, or lies in it)."""
    direction = np.cross(normal, (0.0, 0.0, 1.0))
    length = float(np.linalg.norm(direction))
    if length < 1e-9:
        return None
    level = normal[:2]
    foot = np.zeros(3)
    foot[:2] = level * float(normal @ origin) / float(level @ level)
    return foot + along[:, None] * (direction / length)


def _measured(model: ScannerModel, heading: float, floor: np.ndarray) -> np.ndarray:
    """Which floor points (N, 3, base_link) of the laser's plane at `heading` the scanner
    measures: in the image, triangulated, neither the camera's sight line nor the laser's
    light crossing the encoder disk."""
    base_head = model.head_pose(heading)
    rotation, shift = base_head[:3, :3], base_head[:3, 3]
    pixels = project_head_points(model, (floor - shift) @ rotation)
    seen = np.isfinite(pixels).all(axis=1)
    pixels = np.where(seen[:, None], pixels, -1.0)  # off the image: triangulation refuses
    seen &= triangulate(model, pixels[:, 0], pixels[:, 1], heading).valid
    for source in (np.array(model.camera_mount.position), np.array(model.laser.origin)):
        start = rotation @ source + shift
        seen &= ~(model.encoder.ray_distance(start, floor - start) < 1.0)  # before it
    return seen
