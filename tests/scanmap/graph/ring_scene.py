"""A ring of two look-alike corridors for loop-closure tests (`scanmap.scene/1`).

Corridor A runs east along y = 0, corridor B west along y = 4; short connectors join
them at both ends. Every feature of A has a twin in B turned by 180 deg about (6, 2),
so that B driven westwards looks like A driven eastwards: a place recogniser alone would
merge them. The robot's path: A eastwards, up the east connector, B westwards, down the
west connector and back into A past its start, where the loop truly closes.
"""

from __future__ import annotations

import numpy as np

from scanmap_driver.sim import Scene

HEIGHT = 2.4
COLOUR = [200, 196, 186]


def _box(x0: float, y0: float, x1: float, y1: float, height: float = HEIGHT) -> dict:
    return {"type": "box", "center": [(x0 + x1) / 2, (y0 + y1) / 2, height / 2],
            "size": [x1 - x0, y1 - y0, height], "yaw": 0.0, "color": COLOUR}


def _twin(box: tuple[float, float, float, float, float]) -> tuple:
    """The box turned by 180 deg about (6, 2)."""
    x0, y0, x1, y1, h = box
    return (12.0 - x1, 4.0 - y1, 12.0 - x0, 4.0 - y0, h)


FEATURES = [(1.5, -0.85, 2.1, -0.45, 1.0), (4.0, 0.5, 4.4, 0.85, 0.6),
            (6.5, -0.85, 7.5, -0.6, 0.9), (9.0, 0.45, 9.3, 0.85, 1.2),
            (10.5, -0.85, 10.9, -0.35, 0.5)]


def ring_scene() -> Scene:
    """The two corridors, their connectors and features, and the path's scan poses."""
    walls = [(-2.7, -0.95, 14.7, -0.85), (-2.7, 4.85, 14.7, 4.95),  # outer long walls
             (-2.8, -0.95, -2.7, 4.95), (14.7, -0.95, 14.8, 4.95),  # outer ends
             (-1.0, 0.85, 13.0, 3.15)]                              # the block between
    objects = [_box(*w) for w in walls]
    objects += [_box(*f) for f in FEATURES] + [_box(*_twin(f)) for f in FEATURES]
    poses = [(x, 0.0, 0.0) for x in np.arange(0.0, 12.01, 0.6)]
    poses += [(13.85, 0.0, np.pi / 2), (13.85, 2.0, np.pi / 2), (13.85, 4.0, np.pi)]
    poses += [(x, 4.0, np.pi) for x in np.arange(12.0, -0.01, -0.6)]
    poses += [(-1.85, 4.0, -np.pi / 2), (-1.85, 2.0, -np.pi / 2), (-1.85, 0.0, 0.0)]
    poses += [(x, 0.0, 0.0) for x in np.arange(0.0, 4.21, 0.6)]
    return Scene.from_dict({"format": "scanmap.scene/1", "name": "look-alike ring",
                            "floor": {"color": [150, 140, 125]}, "ambient": 0.8,
                            "objects": objects,
                            "scan_poses": [[float(v) for v in p] for p in poses]})


def corridor_b_end() -> int:
    """Number of scan poses up to the end of corridor B (before the loop can close)."""
    return 21 + 3 + 21
