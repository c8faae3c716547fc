"""A controller driving the corridor (issue 17 item 6): how often the path ahead is unknown,
so that it creeps, and how often no map could know that path yet.

    .venv/bin/python -m benchmarks.bench_controller

The corridor's first SCANS ideal scans (the main job's recording: 20 scans 0.4 m apart)
are mapped one by one as the live Mapper maps them (registration, fusion, the obstacle
snapshot after each scan). After each scan the robot, at that scan's registered pose,
asks `travel`: how far its disc can drive along its heading before it touches anything
not known free. Each scan's map serves until the next scan arrives, so the figures are
shares of the scans:

* unknown ahead: `travel` meets unknown space within REACH. `examples/controller.py`
  with its defaults creeps exactly then (its speed law gives under the creep speed below
  0.44 m from its centre: 0.19 m of travel for a 0.25 m radius) when nothing is nearer.
* unseeable ahead: the robot's disc swept REACH along its heading covers a cell that no
  scan so far could have seen: outside the floor annulus (FLOOR_BAND: the horizontal
  ranges at which the first scan's rays met the floor, camera 1 m up) of every earlier
  scan pose, and not under the robot where it stood at one. No map can know such a cell
  (short of assuming floor nobody saw), so this share is the least a controller that
  never enters unknown space at speed can creep on this drive.

The real-time replay (`examples/controller.py --summary`, the recording of the same
scene at 100 Hz) reports its share of fresh polls, which this measure tracks scan by scan
without the 2 minutes of the replay.
"""

from __future__ import annotations

import math

import numpy as np

from scanmap.grid.rays import scan_rays
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper
from scanmap.navigation.floor import RobotShape
from scanmap.navigation.obstacles import QueryStatus
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.ideal import IdealScan, ideal_scans
from scanmap_driver.sim.scene import builtin_scene

SCANS = 20  # the main job's recording of the corridor
REACH = 0.19  # m of travel below which the example controller creeps (its defaults)
FLOOR_BAND = 0.01  # m: rays ending within this of the floor met the floor
SWEEP_STEP = 0.01  # m between the discs that make up the swept path


def floor_annulus(first: IdealScan) -> tuple[float, float]:
    """The least and the greatest horizontal range at which the scan's rays met the floor
    (z within FLOOR_BAND of 0), from the scanner's axis."""
    points, _ = scan_rays(first.scan, reference_scanner(), first.frame_poses)
    floor = np.abs(points[:, 2]) < FLOOR_BAND
    ranges = np.hypot(points[floor, 0] - first.pose_start[0, 3],
                      points[floor, 1] - first.pose_start[1, 3])
    return float(ranges.min()), float(ranges.max())


def swept_cells(x: float, y: float, yaw: float, reach: float, radius: float,
                resolution: float) -> np.ndarray:
    """(K, 2) centres of the cells whose squares the disc of `radius` touches while its
    centre moves `reach` from (x, y) along `yaw`."""
    cells = set()
    for s in np.arange(0.0, reach + 1e-9, SWEEP_STEP):
        cx, cy = x + s * math.cos(yaw), y + s * math.sin(yaw)
        for i in range(math.floor((cx - radius) / resolution),
                       math.floor((cx + radius) / resolution) + 1):
            for j in range(math.floor((cy - radius) / resolution),
                           math.floor((cy + radius) / resolution) + 1):
                dx = max(i * resolution - cx, 0.0, cx - (i + 1) * resolution)
                dy = max(j * resolution - cy, 0.0, cy - (j + 1) * resolution)
                if dx * dx + dy * dy < radius * radius:
                    cells.add((i, j))
    return (np.array(sorted(cells), np.float64) + 0.5) * resolution


def unseeable(cells: np.ndarray, positions: np.ndarray, annulus: tuple[float, float],
              radius: float, resolution: float) -> int:
    """How many of `cells` (centres) no scan from `positions` (x, y) could have seen:
    outside every position's floor annulus and not under the robot's disc at any."""
    ranges = np.hypot(cells[:, None, 0] - positions[None, :, 0],
                      cells[:, None, 1] - positions[None, :, 1])
    half = 0.5 * resolution
    under = np.hypot(np.maximum(np.abs(cells[:, None, 0] - positions[None, :, 0]) - half, 0),
                     np.maximum(np.abs(cells[:, None, 1] - positions[None, :, 1]) - half, 0)
                     ) < radius
    seen = ((ranges >= annulus[0]) & (ranges <= annulus[1])) | under
    return int((~seen.any(axis=1)).sum())


def corridor_drive(scans: int = SCANS, seed: int = 0) -> dict:
    """The module docstring's measures on the corridor, and each scan's travel."""
    ideal = list(ideal_scans(builtin_scene("corridor"), seed=seed, scans=scans))
    annulus = floor_annulus(ideal[0])
    robot = RobotShape()
    mapper = Mapper(reference_scanner(), MapperConfig(max_age=1e9))  # never stale here
    resolution = mapper.config.grid.resolution
    travels, unknown, blind = [], [], []
    for k, scan in enumerate(ideal):
        mapper.add(scan.scan)
        pose = mapper.latest_pose
        x, y, yaw = pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])
        ahead = mapper.obstacles.travel((x, y, yaw), 1.0)
        travels.append(round(float(ahead.distance), 3))
        unknown.append(ahead.status == QueryStatus.UNKNOWN and ahead.distance < REACH)
        true = ideal[k].pose_start
        path = swept_cells(true[0, 3], true[1, 3], math.atan2(true[1, 0], true[0, 0]),
                           REACH, robot.radius, resolution)
        stood = np.array([s.pose_start[:2, 3] for s in ideal[:k + 1]])
        blind.append(unseeable(path, stood, annulus, robot.radius, resolution) > 0)
    return {"scans": len(ideal), "floor_annulus_m": [round(r, 3) for r in annulus],
            "unknown_ahead_share": float(np.mean(unknown)),
            "unseeable_ahead_share": float(np.mean(blind)),
            "unknown_ahead_scans": [k for k, u in enumerate(unknown) if u],
            "unseeable_ahead_scans": [k for k, b in enumerate(blind) if b],
            "travel_m": travels}


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see the module docstring) for `python -m benchmarks`."""
    drive = corridor_drive(8 if quick else SCANS)
    settings = (f"corridor, {drive['scans']} ideal scans mapped live, travel under "
                f"{REACH} m")
    return [{"stage": "controller", "method": "path ahead unknown (the controller creeps)",
             "settings": settings, "median_s": None, "error": drive["unknown_ahead_share"],
             "error_unit": "share of the scans (goal under 0.1)", **drive,
             "peers": {"unseeable: no scan could have seen the path yet":
                       {"error": drive["unseeable_ahead_share"]}}}]


if __name__ == "__main__":
    import json

    print(json.dumps(corridor_drive(), indent=1))
