"""Occupancy maps of 2-D laser logs: a synthetic room, and the real Intel lab log."""

from __future__ import annotations

import numpy as np

from scanmap.cli import main
from scanmap.datasets.carmen import read_carmen
from scanmap.io.map_files import load_ros_map
from scanmap.navigation.floor import FREE, OBSTACLE
from scanmap.pipelines.carmen_map import carmen_segmentation, fuse_carmen
from scanmap_driver.transforms import se2_to_pose, transform_points

from ..conftest import real_data


class RoomLog:
    """A CarmenLog-like log: 180 beams of a laser in a 6 m x 4 m box room (walls a quarter
    cell inside cells)."""

    def __init__(self, poses: np.ndarray) -> None:
        self.poses = poses
        self.times = np.arange(len(poses), dtype=float)
        self.max_range = 40.0
        angles = np.deg2rad(-90.0 + np.arange(180))
        self.ranges = np.array([self._cast(p, angles) for p in poses])

    @staticmethod
    def _cast(pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Range to the walls x = +-3, y = +-2 along each beam (nearest positive hit)."""
        d = np.stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])], axis=1)
        best = np.full(len(angles), np.inf)
        for axis, wall in ((0, 3.0125), (0, -3.0125), (1, 2.0125), (1, -2.0125)):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wall - pose[axis]) / d[:, axis]
            best = np.where((t > 0) & (t < best), t, best)
        return best

    def __len__(self) -> int:
        return len(self.poses)

    def scan_points(self, index: int, height: float = 0.3) -> np.ndarray:
        a = np.deg2rad(-90.0 + np.arange(180))
        r = self.ranges[index]
        return np.column_stack([r * np.cos(a), r * np.sin(a), np.full(180, height)])


def test_a_laser_room_is_walls_around_free_floor():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 3.1], [-1.0, -0.5, 1.5], [0.5, -1.0, -1.6]])
    log = RoomLog(poses)
    seg = carmen_segmentation(fuse_carmen(log))
    xs = seg.origin[0] + (np.arange(seg.shape[1]) + 0.5) * seg.resolution
    ys = seg.origin[1] + (np.arange(seg.shape[0]) + 0.5) * seg.resolution
    x, y = np.meshgrid(xs, ys)
    inside = (np.abs(x) < 2.8) & (np.abs(y) < 1.8)
    assert (seg.state[inside] == FREE).mean() > 0.99
    assert not (seg.state[inside] == OBSTACLE).any()
    ends, _ = endpoints(log, range(len(log)))
    rows = np.floor((ends[:, 1] - seg.origin[1]) / seg.resolution).astype(int)
    cols = np.floor((ends[:, 0] - seg.origin[0]) / seg.resolution).astype(int)
    assert (seg.state[rows, cols] == OBSTACLE).mean() > 0.99


def endpoints(log, indices) -> tuple[np.ndarray, np.ndarray]:
    """Map endpoints and laser positions of the given scans."""
    ends, origins = [], []
    for i in indices:
        pts = transform_points(se2_to_pose(*log.poses[i]), log.scan_points(i))
        ends.append(pts[:, :2])
        origins.append(np.repeat(log.poses[i][None, :2], len(pts), axis=0))
    return np.vstack(ends), np.vstack(origins)


def test_the_intel_map_predicts_held_out_scans():
    """Map the even scans of the Intel log; the odd scans (not fused) must end on mapped
    obstacles and cross mapped free space, as in the published map."""
    log = read_carmen(real_data("carmen/intel-corrected.log.gz"))

    class Even:
        poses, times, max_range = log.poses[::2], log.times[::2], log.max_range

        def __len__(self) -> int:
            return len(self.poses)

        def scan_points(self, index: int, height: float = 0.3) -> np.ndarray:
            return log.scan_points(2 * index, height=height)

    seg = carmen_segmentation(fuse_carmen(Even()))
    ends, origins = endpoints(log, range(1, len(log), 2))
    res = seg.resolution

    def cells(xy):
        return (np.floor((xy[:, 1] - seg.origin[1]) / res).astype(int),
                np.floor((xy[:, 0] - seg.origin[0]) / res).astype(int))

    state = np.pad(seg.state, 1)  # a 1-cell tolerance: is an obstacle within one cell?
    near_obstacle = np.zeros_like(state, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near_obstacle |= np.roll(np.roll(state == OBSTACLE, dy, 0), dx, 1)
    r, c = cells(ends)
    assert near_obstacle[r + 1, c + 1].mean() > 0.9
    midway = origins + 0.5 * (ends - origins)  # halfway along each held-out beam
    r, c = cells(midway)
    assert (seg.state[r, c] == FREE).mean() > 0.9


def test_carmen_map_command_writes_a_ros_map(tmp_path, capsys):
    log = real_data("carmen/intel-corrected.log.gz")
    assert main(["carmen-map", str(log), "--out", str(tmp_path)]) == 0
    loaded = load_ros_map(tmp_path / "intel-corrected.yaml")
    assert (loaded.data == 100).sum() > 10_000 and (loaded.data == 0).sum() > 100_000
    assert (tmp_path / "intel-corrected.png").stat().st_size < 300_000
    out = capsys.readouterr().out
    assert "910 scans" in out and "beam layout: 180 beams from -90.00 deg" in out


def test_a_log_fuses_into_one_level_per_cell_as_three_levels_would_at_half_the_memory():
    """Every hit and ray of a 2-D log lies at one height, so the one-level grid
    `fuse_carmen` keeps maps exactly what the default three levels map, scan by scan,
    in under half the memory (the first 150 scans of the ACES log: 181 beams, 50 m)."""
    from scanmap.grid.height_grid import GridConfig, HeightGrid

    log = read_carmen(real_data("carmen/aces-corrected.log.gz")).subset(range(150))
    fused = fuse_carmen(log)
    plain = HeightGrid(GridConfig(max_range=log.max_range))
    for i in range(len(log)):
        points = transform_points(se2_to_pose(*log.poses[i]), log.scan_points(i))
        plain.insert(points, np.array([*log.poses[i, :2], 0.3]), float(log.times[i]))
    assert fused.config.levels == 1 and plain.layers().nlev.max() == 1
    a, b = carmen_segmentation(fused), carmen_segmentation(plain)
    assert a.origin == b.origin and (a.state == OBSTACLE).sum() > 1000
    np.testing.assert_array_equal(a.state, b.state)
    np.testing.assert_array_equal(fused.layers().levels, plain.layers().levels[:, :, :1])
    assert fused.memory_bytes < 0.5 * plain.memory_bytes
