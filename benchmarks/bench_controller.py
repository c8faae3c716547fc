"""A controller driving the corridor (issue 17 item 6): how often the path ahead is unknown,
so that it creeps, and how often no map could know that path yet.

The corridor's first SCANS scans (the main job's recording: 20 scans 0.4 m apart)
are mapped one by one as the live Mapper maps them (registration, fusion, the obstacle
snapshot after each scan). After each scan the robot, at that scan's registered pose,
asks `travel`: how far its disc can drive along its heading before it touches anything
not known free. Each scan's map serves until the next scan arrives, so the figures are
shares of the scans:

* unknown ahead: `travel` meets unknown space within REACH. `examples/controller.py`
  with its defaults creeps exactly then (its speed law gives under the creep speed below
  0.44 m from its centre: 0.19 m of travel for a 0.25 m radius) when nothing is nearer.
* blocked ahead: the robot's disc swept REACH along its heading, from its true pose,
  covers a cell the scene's truth holds as an obstacle or a drop-off (`blocked`): every
  controller slows there, whatever the map knows, so creeping there is no fault of the
  map's (on the corridor drive, its bin).
* unseeable ahead: the robot's disc swept REACH along its heading covers a cell that no
  scan so far could have seen: outside the floor annulus (FLOOR_BAND: the horizontal
  ranges at which the first scan's rays met the floor, camera 1 m up) of every earlier
  scan pose, and not under the robot where it stood at one. No map can know such a cell
  (short of assuming floor nobody saw), so this share is the least a controller that
  never enters unknown space at speed can creep on this drive.
* avoidable: the scans with the path ahead unknown that are neither blocked nor
  unseeable, where a map could have let the controller drive on.

The same drive is measured twice: on ideal scans (the simulator's geometry, every ray
that meets the floor up to the 4 m range limit) and on the corridor recording the replay
plays (`examples/controller.py --summary`, 100 Hz polls), rendered and extracted as a
camera sees it: there the floor shows only from about 1.6 to 2.2 m and its laser lines
lie farther apart, so the gaps between them are what the map must bridge. The recording
row tracks the replay's share of fresh polls scan by scan without its 2 minutes (full
mode only: rendering 20 scans takes a minute when ./data has none).

    .venv/bin/python -m benchmarks.bench_controller [--recording DIR]
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks.bench_mapping import RECORDING, corridor_recording
from scanmap.datasets.recordings import ScanSource
from scanmap.grid.rays import scan_rays
from scanmap.io.trajectory import read_tum
from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper
from scanmap.navigation.floor import RobotShape
from scanmap.navigation.obstacles import QueryStatus
from scanmap_driver.recording import INDEX_NAME
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel, reference_scanner
from scanmap_driver.sim.ideal import IdealScan, ideal_scans
from scanmap_driver.sim.raster import DROP_OFF, OBSTACLE, TruthRaster, truth_raster
from scanmap_driver.sim.scene import builtin_scene

SCANS = 20  # the main job's recording of the corridor
REACH = 0.19  # m of travel below which the example controller creeps (its defaults)
FLOOR_BAND = 0.01  # m: rays ending within this of the floor met the floor
SWEEP_STEP = 0.01  # m between the discs that make up the swept path


def floor_annulus(first: IdealScan) -> tuple[float, float]:
    """The least and the greatest horizontal range at which the scan's rays met the floor
    (z within FLOOR_BAND of 0), from the scanner's axis."""
    points, _ = scan_rays(first.scan, reference_scanner(), first.frame_poses)
    return _annulus(points, first.pose_start)


def _annulus(points: np.ndarray, pose: np.ndarray) -> tuple[float, float]:
    floor = np.abs(points[:, 2]) < FLOOR_BAND
    ranges = np.hypot(points[floor, 0] - pose[0, 3], points[floor, 1] - pose[1, 3])
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


def blocked(cells: np.ndarray, raster: TruthRaster) -> int:
    """How many of `cells` (centres) the truth raster holds as obstacle or drop-off."""
    return int(np.isin(raster.class_at(cells), (OBSTACLE, DROP_OFF)).sum())


def corridor_drive(scans: int = SCANS, seed: int = 0) -> dict:
    """The module docstring's measures on the corridor's ideal scans, and each scan's
    travel."""
    scene = builtin_scene("corridor")
    ideal = list(ideal_scans(scene, seed=seed, scans=scans))
    return _drive([s.scan for s in ideal], [s.pose_start for s in ideal],
                  floor_annulus(ideal[0]), reference_scanner(), truth_raster(scene))


def recording_drive(path: Path = RECORDING) -> dict:
    """The same measures on a simulated recording: its scans as the camera saw them, the
    true poses of its ground truth (`trajectory.txt`, as `scanmap map` reads them), the
    floor annulus of its first scan's points placed at its true pose."""
    source = ScanSource.open(path)
    scans = [item.scan for item in source]
    truth = read_tum(source.ground_truth / "trajectory.txt").poses
    starts = [truth[scan.index] for scan in scans]
    points, _ = scan_rays(scans[0], source.model, starts[0])
    return _drive(scans, starts, _annulus(points, starts[0]), source.model,
                  TruthRaster.load(source.ground_truth / "raster.npz"))


def _drive(scans: Sequence[Scan], starts: Sequence[np.ndarray],
           annulus: tuple[float, float], model: ScannerModel, raster: TruthRaster) -> dict:
    robot = RobotShape()
    mapper = Mapper(model, MapperConfig(max_age=1e9))  # never stale here
    resolution = mapper.config.grid.resolution
    travels, unknown, blind, stopped = [], [], [], []
    for k, scan in enumerate(scans):
        mapper.add(scan)
        pose = mapper.latest_pose
        x, y, yaw = pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])
        ahead = mapper.obstacles.travel((x, y, yaw), 1.0)
        travels.append(round(float(ahead.distance), 3))
        unknown.append(ahead.status == QueryStatus.UNKNOWN and ahead.distance < REACH)
        true = starts[k]
        path = swept_cells(true[0, 3], true[1, 3], math.atan2(true[1, 0], true[0, 0]),
                           REACH, robot.radius, resolution)
        stood = np.array([s[:2, 3] for s in starts[:k + 1]])
        blind.append(unseeable(path, stood, annulus, robot.radius, resolution) > 0)
        stopped.append(blocked(path, raster) > 0)
    avoidable = [u and not b and not s for u, b, s in zip(unknown, blind, stopped, strict=True)]
    return {"scans": len(scans), "floor_annulus_m": [round(r, 3) for r in annulus],
            "unknown_ahead_share": float(np.mean(unknown)),
            "unseeable_ahead_share": float(np.mean(blind)),
            "blocked_ahead_share": float(np.mean(stopped)),
            "avoidable_unknown_share": float(np.mean(avoidable)),
            "unknown_ahead_scans": [k for k, u in enumerate(unknown) if u],
            "unseeable_ahead_scans": [k for k, b in enumerate(blind) if b],
            "blocked_ahead_scans": [k for k, b in enumerate(stopped) if b],
            "avoidable_unknown_scans": [k for k, a in enumerate(avoidable) if a],
            "travel_m": travels}


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see the module docstring) for `python -m benchmarks`: ideal scans,
    and in full mode the recording."""
    drives = [("ideal scans", corridor_drive(8 if quick else SCANS))]
    if not quick:
        with tempfile.TemporaryDirectory() as folder:
            drives.append(("rendered scans (the replay's recording)",
                           recording_drive(corridor_recording(Path(folder), SCANS))))
    rows = []
    for name, drive in drives:
        settings = (f"corridor, {drive['scans']} {name} mapped live, travel under "
                    f"{REACH} m")
        rows.append({"stage": "controller",
                     "method": "path ahead unknown (the controller creeps)",
                     "settings": settings, "median_s": None,
                     "error": drive["unknown_ahead_share"],
                     "error_unit": "share of the scans (goal under 0.1)", **drive,
                     "peers": {"unseeable: no scan could have seen the path yet":
                               {"error": drive["unseeable_ahead_share"]},
                               "blocked: a true obstacle on the path":
                               {"error": drive["blocked_ahead_share"]},
                               "avoidable: unknown, neither unseeable nor blocked":
                               {"error": drive["avoidable_unknown_share"]}}})
    return rows


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--recording", type=Path, default=RECORDING,
                        help="a simulated recording to drive too (default: the examples' "
                        "corridor, when there)")
    args = parser.parse_args(argv)
    drives = {"ideal": corridor_drive()}
    if (args.recording / INDEX_NAME).is_file():
        drives["recording"] = recording_drive(args.recording)
    print(json.dumps(drives, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
