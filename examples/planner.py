"""A navigation planner on scanmap's costmap: A* through the mapped office, drawn on the map.

    .venv/bin/python examples/planner.py [--start X Y] [--goal X Y]

It maps the office recording (./data/office_recording, simulated once when missing:
24 scans on a loop round a table) or loads a saved map (--map map.npz from `scanmap
map`), inflates the obstacles as Nav2 does (lethal, inscribed radius, exponential
decay), and plans with A* over 8-connected cells: a cell is entered only if its cost is
below INSCRIBED (the robot's centre there keeps its footprint off every obstacle) and
never if it is unknown; each step costs its length times (1 + cost_weight * cost / 252),
so the path keeps away from obstacles where it can. Like Nav2's footprint clearing, the
cells under the robot's footprint at the start are taken as free: the robot stands
there, though the scanner cannot see under itself.

Coordinates are in the map frame (m; the map starts where the robot started). Without
--goal it plans to the trajectory's pose farthest from the start, or, for a one-scan map,
to the reachable cell farthest from it. Writes plan.png and plan.json to --out.
"""

from __future__ import annotations

import argparse
import heapq
import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage
from sim_data import DATA, ensure_recording

from scanmap import (
    FREE,
    INSCRIBED,
    OBSTACLE,
    UNKNOWN,
    Mapper,
    MapperConfig,
    ScanSource,
    Segmentation,
    distance_transform,
    inflate,
    occupancy_grid,
    occupancy_image,
    write_png,
)
from scanmap_driver import write_json

STEPS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]


def astar(costs: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
          cost_weight: float = 3.0) -> list[tuple[int, int]] | None:
    """Cheapest 8-connected path of (row, col) cells from start to goal through cells of
    cost below INSCRIBED, or None. The octile-distance heuristic never overestimates
    (every step costs at least its length), so the path is optimal."""
    passable = costs < INSCRIBED
    if not (passable[start] and passable[goal]):
        return None

    def heuristic(cell: tuple[int, int]) -> float:
        dy, dx = abs(cell[0] - goal[0]), abs(cell[1] - goal[1])
        return max(dy, dx) + (math.sqrt(2.0) - 1.0) * min(dy, dx)

    best = {start: 0.0}
    came_from: dict[tuple[int, int], tuple[int, int]] = {}
    frontier = [(heuristic(start), 0.0, start)]
    while frontier:
        _, so_far, cell = heapq.heappop(frontier)
        if cell == goal:
            path = [cell]
            while path[-1] != start:
                path.append(came_from[path[-1]])
            return path[::-1]
        if so_far > best[cell]:
            continue
        for dy, dx in STEPS:
            nxt = (cell[0] + dy, cell[1] + dx)
            if not (0 <= nxt[0] < costs.shape[0] and 0 <= nxt[1] < costs.shape[1]) \
                    or not passable[nxt]:
                continue
            step = math.hypot(dy, dx) * (1.0 + cost_weight * costs[nxt] / (INSCRIBED - 1))
            if so_far + step < best.get(nxt, math.inf):
                best[nxt] = so_far + step
                came_from[nxt] = cell
                heapq.heappush(frontier, (so_far + step + heuristic(nxt), so_far + step, nxt))
    return None


def cell_of(seg: Segmentation, xy: np.ndarray) -> tuple[int, int]:
    """(row, col) of the map point (x, y)."""
    col = math.floor((xy[0] - seg.origin[0]) / seg.resolution)
    row = math.floor((xy[1] - seg.origin[1]) / seg.resolution)
    if not (0 <= row < seg.shape[0] and 0 <= col < seg.shape[1]):
        raise SystemExit(f"({xy[0]:.2f}, {xy[1]:.2f}) is outside the map")
    return row, col


def centre_of(seg: Segmentation, cells: np.ndarray) -> np.ndarray:
    """(N, 2) map coordinates of the centres of (row, col) cells."""
    cells = np.asarray(cells, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([seg.origin[0] + (cells[:, 1] + 0.5) * seg.resolution,
                            seg.origin[1] + (cells[:, 0] + 0.5) * seg.resolution])


def clear_footprint(seg: Segmentation, xy: np.ndarray) -> Segmentation:
    """The segmentation with the unknown cells under the robot's footprint at xy free."""
    rows, cols = np.mgrid[0:seg.shape[0], 0:seg.shape[1]]
    centres = centre_of(seg, np.column_stack([rows.ravel(), cols.ravel()]))
    under = (np.hypot(*(centres - xy).T) <= seg.robot.radius).reshape(seg.shape)
    state = seg.state.copy()
    state[under & (state == UNKNOWN)] = FREE
    return replace(seg, state=state)


def default_goal(seg: Segmentation, costs: np.ndarray, start: tuple[int, int],
                 trajectory: np.ndarray) -> tuple[int, int]:
    """The trajectory pose farthest from the start that A* can reach, else the farthest
    reachable cell."""
    labels, _ = ndimage.label(costs < INSCRIBED, np.ones((3, 3), bool))
    reachable = labels == labels[start]
    candidates = [cell_of(seg, xy) for xy in trajectory]
    candidates = [c for c in candidates if reachable[c]]
    if len(candidates) < 2:
        candidates = list(zip(*np.nonzero(reachable), strict=True))
    far = np.argmax([math.hypot(c[0] - start[0], c[1] - start[1]) for c in candidates])
    return tuple(int(v) for v in candidates[far])


def load_or_map(args: argparse.Namespace) -> Mapper:
    """The mapper of --map, or of the office recording mapped now."""
    if args.map:
        print(f"loading {args.map}")
        return Mapper.load(args.map, offline=True)
    recording = ensure_recording(args.recording, "office", args.scans, args.workers)
    source = ScanSource.open(recording, workers=args.workers)
    mapper = Mapper(source.model, MapperConfig(update_obstacles=False), offline=True)
    print(f"mapping {recording} ({source.count} scans)")
    mapper.map_scans(source)
    args.out.mkdir(parents=True, exist_ok=True)
    mapper.save(args.out / "map.npz")
    return mapper


def draw(seg: Segmentation, costs: np.ndarray, path: list[tuple[int, int]] | None,
         start: tuple[int, int], goal: tuple[int, int]) -> np.ndarray:
    """The map tinted by cost (the inflation zone), the path, start (green), goal (red)."""
    picture = occupancy_image(occupancy_grid(seg), seg.origin, seg.resolution, scale=4)
    inflated = (costs < 255) & (seg.state != OBSTACLE)
    weight = np.where(inflated, 0.6 * costs / INSCRIBED, 0.0)[::-1, :, None]
    weight = np.repeat(np.repeat(weight, picture.scale, 0), picture.scale, 1)
    image = ((1 - weight) * picture.image + weight * np.array([60, 90, 255])).astype(np.uint8)
    if path:
        pixels = picture.pixel(centre_of(seg, path)) + picture.scale // 2
        cv2.polylines(image, [pixels.reshape(-1, 1, 2)], False, (200, 80, 0), 2, cv2.LINE_AA)
    for cell, colour in ((start, (0, 160, 0)), (goal, (0, 0, 220))):
        pixel = picture.pixel(centre_of(seg, [cell]))[0] + picture.scale // 2
        cv2.circle(image, (int(pixel[0]), int(pixel[1])), 6, colour, -1, cv2.LINE_AA)
    return image


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", type=Path, default=None, help="a saved map.npz to plan on")
    parser.add_argument("--recording", type=Path, default=DATA / "office_recording")
    parser.add_argument("--scans", type=int, default=24,
                        help="scans to simulate when the recording is missing (default 24)")
    parser.add_argument("--out", type=Path, default=DATA / "office_plan")
    parser.add_argument("--start", type=float, nargs=2, metavar=("X", "Y"), default=None,
                        help="start in map (default: where the robot started)")
    parser.add_argument("--goal", type=float, nargs=2, metavar=("X", "Y"), default=None)
    parser.add_argument("--inflation-radius", type=float, default=0.55)
    parser.add_argument("--cost-scaling", type=float, default=3.0)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)

    mapper = load_or_map(args)
    trajectory = mapper.trajectory().positions[:, :2]
    start_xy = np.array(args.start) if args.start else trajectory[0]
    seg = clear_footprint(mapper.segment(), start_xy)
    costs = inflate(seg, inflation_radius=args.inflation_radius,
                    cost_scaling_factor=args.cost_scaling)
    start = cell_of(seg, start_xy)
    goal = cell_of(seg, np.array(args.goal)) if args.goal else \
        default_goal(seg, costs, start, trajectory)
    path = astar(costs, start, goal)
    args.out.mkdir(parents=True, exist_ok=True)
    write_png(args.out / "plan.png", draw(seg, costs, path, start, goal))
    result = {"start": centre_of(seg, [start])[0].tolist(),
              "goal": centre_of(seg, [goal])[0].tolist(), "found": path is not None}
    if path is None:
        print(f"no path from {result['start']} to {result['goal']} through known free space")
    else:
        distance, _ = distance_transform(seg.state == OBSTACLE)
        rows, cols = np.array(path).T
        xy = centre_of(seg, path)
        result |= {"path": xy.tolist(), "cells": [list(map(int, c)) for c in path],
                   "length_m": float(np.sum(np.hypot(*np.diff(xy, axis=0).T))),
                   "max_cost": int(costs[rows, cols].max()),
                   "min_obstacle_distance_m": float(distance[rows, cols].min()
                                                    * seg.resolution)}
        print(f"path of {result['length_m']:.2f} m from ({result['start'][0]:.2f}, "
              f"{result['start'][1]:.2f}) to ({result['goal'][0]:.2f}, "
              f"{result['goal'][1]:.2f}): {len(path)} cells, highest cost "
              f"{result['max_cost']}, nearest obstacle "
              f"{result['min_obstacle_distance_m']:.2f} m")
    write_json(args.out / "plan.json", result)
    print(f"wrote {args.out / 'plan.png'} and {args.out / 'plan.json'}")
    return 0 if path is not None else 1


if __name__ == "__main__":
    raise SystemExit(main())
