"""Random hazard rooms: scenes the hazard rules were not built on (`random_room(seed)`).

The built-in `hazards` and `workshop` scenes are where the rules were shaped; a rule that
holds only there is tuned to them. Each room here is drawn afresh from its seed: a walled
10 m x 5 m room with eight hazards on alternate sides of a weaving path (26 stop-and-scan
poses 0.3 m apart, the heading following the path within 3 deg): two holes 0.3-0.6 m wide
and 0.2-0.6 m deep, a step down of 6-20 cm, a pit 0.6-1.0 m across and 0.1-0.3 m deep, a
platform 8-30 cm high, a low step of 1-4 cm (traversable), a ramp of 4-11 deg
(traversable) and one of 20-30 deg (not), each turned by up to 46 deg (the ramps rise
along x), their order along the room shuffled. A hole's other side is 0.8-1.3 times the
first but never under `FloorConfig.max_hole` (0.3 m): a smaller hole, while nothing in it
or at its rim has been seen, is a patch the rules may take for a gap between samples.
"""

from __future__ import annotations

import math

import numpy as np

from scanmap_driver.sim.scene import Scene

HAZARDS = ("hole", "hole", "step down", "pit", "platform", "low step", "ramp", "steep ramp")
POSES = 26
POSE_STEP = 0.3  # m along x between poses


def _region(kind: str, x: float, y: float, rng: np.random.Generator) -> dict:
    """One hazard (a scene file's floor region) centred near (x, y)."""
    turned = rng.random() < 0.6 and "ramp" not in kind
    region = {"center": [round(x, 3), round(y, 3)], "name": kind, "color": [130, 130, 130],
              "yaw": round(float(rng.uniform(-0.8, 0.8)), 3) if turned else 0.0}
    if kind == "hole":
        side = rng.uniform(0.3, 0.6)  # the other side 0.8-1.3 times it, never under max_hole
        region |= {"size": [round(side, 3), round(max(side * rng.uniform(0.8, 1.3), 0.3), 3)],
                   "height": round(-rng.uniform(0.2, 0.6), 3)}
    elif kind == "pit":
        region |= {"size": [round(rng.uniform(0.6, 1.0), 3), round(rng.uniform(0.6, 1.0), 3)],
                   "height": round(-rng.uniform(0.1, 0.3), 3)}
    elif kind == "step down":
        region |= {"size": [0.9, 0.9], "height": round(-rng.uniform(0.06, 0.2), 3)}
    elif kind == "platform":
        region |= {"size": [0.7, 0.6], "height": round(rng.uniform(0.08, 0.3), 3)}
    elif kind == "low step":
        region |= {"size": [0.7, 0.7], "height": round(rng.uniform(0.01, 0.04), 3)}
    else:  # a ramp rising along x from the floor at its low edge
        degrees = rng.uniform(4.0, 11.0) if kind == "ramp" else rng.uniform(20.0, 30.0)
        gradient = math.tan(math.radians(degrees))
        region |= {"size": [1.0, 0.9], "gradient": [round(gradient, 4), 0.0],
                   "height": round(0.5 * gradient + 2e-4, 4)}  # rounded up: never below 0
    return region


def random_room(seed: int) -> Scene:
    """The room of the module docstring drawn from `seed` (the same seed, the same room)."""
    rng = np.random.default_rng(seed)
    wall = {"type": "box", "color": [200, 196, 190]}
    kinds = list(HAZARDS)
    rng.shuffle(kinds)
    regions = [_region(kind, 1.0 + k + rng.uniform(-0.2, 0.2),
                       (1.4 if k % 2 else -1.4) + rng.uniform(-0.1, 0.1), rng)
               for k, kind in enumerate(kinds)]
    phase, amplitude = rng.uniform(0.0, 2 * math.pi), rng.uniform(0.1, 0.35)
    poses = []
    for k in range(POSES):
        x = POSE_STEP * k
        slope = amplitude / 1.3 * math.cos(x / 1.3 + phase)
        poses.append([round(x, 3), round(amplitude * math.sin(x / 1.3 + phase), 4),
                      round(math.atan(slope) + rng.uniform(-0.05, 0.05), 4)])
    return Scene.from_dict({
        "format": "scanmap.scene/1", "name": f"random room {seed}",
        "description": f"random_room({seed}): {__doc__.splitlines()[0]}",
        "floor": {"color": [150, 140, 125]}, "ambient": 0.8, "texture": 0.25,
        "objects": [wall | {"center": [4.0, y, 0.65], "size": [10.2, 0.1, 1.7]}
                    for y in (-2.55, 2.55)]
        + [wall | {"center": [x, 0.0, 0.65], "size": [0.1, 5.0, 1.7]} for x in (-1.05, 9.05)],
        "floor_regions": regions, "scan_poses": poses}, source=f"random_room({seed})")
