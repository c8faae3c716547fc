"""Simulator speed: one rendered frame, a whole recording (the issue's 20-scan corridor
under 60 s on 2 cores), the sampled ray casting against Open3D casting every ray (in a
process of its own with a time limit: a crash or hang is its failure), and ideal scans.

Times are wall-clock medians; CPU seconds (all threads and worker processes) are reported
beside them because on a shared machine the wall time says as much about the neighbours
as about the code. Run as `python -m benchmarks.bench_simulator` (the main guard lets the
recording's worker processes start).
"""

from __future__ import annotations

import math
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.isolation import PeerFailed, run_isolated
from benchmarks.timing import first_call_time, median_time
from scanmap_driver import reference_scanner
from scanmap_driver.recording import Recording
from scanmap_driver.sim import builtin_scene, ideal_scans, plan_scans
from scanmap_driver.sim.camera_effects import SimCameraConfig
from scanmap_driver.sim.geometry import NO_HIT, plane_distance
from scanmap_driver.sim.hitmap import hit_map
from scanmap_driver.sim.laser_stripe import head_poses
from scanmap_driver.sim.render import LaserAppearance, Renderer
from scanmap_driver.sim.scene import LIGHTING
from scanmap_driver.sim.simulate import lit_scene, simulate_recording


def _stripe_error(renderer: Renderer, plan, frame: int) -> float:
    """Median |centroid - truth| (px) of the still, speckle-free laser light per column."""
    light = renderer.light(plan, frame, np.random.default_rng(0))
    errors = []
    stripe = light.truth.stripe
    for u, v, lit in zip(stripe.u.astype(int), stripe.v, stripe.lit, strict=True):
        rows = np.arange(int(v) - 6, int(v) + 7)
        if lit and rows[0] >= 0 and rows[-1] < light.laser.shape[0]:
            profile = light.laser[rows, u]
            if profile.sum() > 0:
                errors.append(abs((profile * rows).sum() / profile.sum() - v))
    return float(np.median(errors))


def _cpu_and_wall(func) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    func()
    return time.process_time() - cpu, time.perf_counter() - wall


def _frame_rows(model, quick: bool) -> list[dict]:
    rows = []
    for name in ("corridor", "office"):
        for lighting in ("dark", "bright"):
            scene = lit_scene(builtin_scene(name), lighting)
            plan = plan_scans(scene, model, seed=1, count=2)[1]
            renderer = Renderer(scene, model)
            frames = range(5, plan.frame_times.size, 9 if quick else 3)
            rng = np.random.default_rng(0)
            first = first_call_time(lambda r=renderer, p=plan, g=rng: r.render(p, 0, g))
            walls, cpus = [], []
            for frame in frames:
                cpu, wall = _cpu_and_wall(lambda r=renderer, p=plan, f=frame, g=rng:
                                          r.render(p, f, g))
                cpus.append(cpu)
                walls.append(wall)
            still = Renderer(scene.with_ambient(0.0), model, SimCameraConfig(),
                             LaserAppearance(speckle=0.0))
            rows.append({
                "stage": "simulator", "method": "render one frame",
                "settings": f"{name}, {lighting}, 640x480, 1 thread",
                "median_s": float(np.median(walls)), "cpu_s": float(np.median(cpus)),
                "first_call_s": first,
                "error": _stripe_error(still, plan, 0), "error_unit": "px (laser centroid "
                "vs truth row, median)", "peers": {}})
    return rows


def _hit_map_row(model) -> dict:
    """Our sampled cast against Open3D's RaycastingScene casting every ray itself.

    Both are scored against the exact distance to the face each ray hits: the face's plane
    equation solved in float64 for the ray (the closed form of a ray-plane intersection).
    Open3D answers float32 distances; ours solves the plane equation for every pixel.
    """
    scene = builtin_scene("office")
    renderer = Renderer(scene, model)
    plan = plan_scans(scene, model, seed=1, count=1)[0]
    pose, _ = head_poses(model, plan.base_poses_at(plan.frame_times[20]),
                         plan.frame_headings[20:21])
    raycaster, rays = renderer.world.world, renderer.rays
    planes = raycaster.planes
    rotation, shift = pose[0][:3, :3], pose[0][:3, 3]
    origin = rotation @ rays.centre + shift
    directions = rays.directions.reshape(-1, 3) @ rotation.T
    origins = np.ascontiguousarray(np.broadcast_to(origin, directions.shape))
    peer = "Open3D RaycastingScene, every ray"
    unit = "m (mean |distance - exact plane distance| over all pixels)"
    try:
        open3d_s, open3d_t, primitive = run_isolated(
            open3d_cast, planes.vertices, planes.triangles, np.hstack([origins, directions]), 5)
        face = np.where(primitive >= 0, planes.triangle_plane[np.maximum(primitive, 0)],
                        NO_HIT)
    except PeerFailed as exc:  # a peer that fails is reported in its place
        peers = {peer: {"failed": str(exc)}}
        open3d_t = None
        face = hit_map(raycaster, rays.centre, rays.directions, pose[0], 1, 1).plane.ravel()
        unit += "; faces from our every-ray cast, Open3D failed"
    exact = plane_distance(planes.planes, face.astype(np.int32), origins,
                           np.ascontiguousarray(directions)).reshape(rays.directions.shape[:2])
    seen = np.isfinite(exact)

    def error(t: np.ndarray) -> float:
        return float(np.mean(np.abs(np.where(seen, t.reshape(exact.shape) - exact, 0.0))))

    sampled = hit_map(raycaster, rays.centre, rays.directions, pose[0], renderer.hit_step, 1)
    if open3d_t is not None:
        peers = {peer: {"median_s": open3d_s, "error": error(open3d_t.astype(np.float64))}}
    return {"stage": "simulator", "method": "sampled ray casting (rows every "
            f"{renderer.hit_step}, planes fill the rest)", "settings": "office, 307,200 rays",
            "median_s": median_time(lambda: hit_map(raycaster, rays.centre, rays.directions,
                                                    pose[0], renderer.hit_step, 1), repeats=10),
            "error": error(sampled.t), "error_unit": unit, "peers": peers}


def open3d_cast(vertices: np.ndarray, triangles: np.ndarray, rays: np.ndarray,
                repeats: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Open3D's RaycastingScene casting every ray (N, 6) on one thread: median wall time,
    float32 distances and the triangle hit (-1: none). Run in a process of its own."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),
                        o3d.core.Tensor(triangles.astype(np.uint32)))
    o3d_rays = o3d.core.Tensor(rays.astype(np.float32))
    seconds = median_time(lambda: scene.cast_rays(o3d_rays, nthreads=1), repeats=repeats)
    hits = scene.cast_rays(o3d_rays, nthreads=1)
    primitive = hits["primitive_ids"].numpy().astype(np.int64)
    primitive[primitive == o3d.t.geometry.RaycastingScene.INVALID_ID] = -1
    return seconds, hits["t_hit"].numpy(), primitive


def _recording_row(model, quick: bool, workers: int) -> dict:
    """The whole recording; CPU time counts the worker processes too."""
    scans = 1 if quick else 20
    scene = builtin_scene("corridor")
    folder = Path(tempfile.mkdtemp(prefix="bench_sim_"))
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        cpu, wall = _cpu_and_wall(lambda: simulate_recording(
            scene, folder / "rec", model, seed=1, scans=scans, workers=workers))
        frames = sum(r.frame_times.size for r in Recording.open(folder / "rec").scans)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu += (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime)
    return {"stage": "simulator", "method": "simulate recording (render + MJPG + truth)",
            "settings": f"corridor, {scans} scans, {frames} frames, {workers} worker(s)",
            "median_s": wall, "cpu_s": cpu, "frames": frames,
            "frames_per_s": frames / wall, "cpu_per_frame_s": cpu / frames,
            "wall_per_1000_frames_s": 1000 * wall / frames,
            "error": None, "peers": {}}


def _ideal_row(model, quick: bool) -> dict:
    scene = builtin_scene("corridor")
    scans = 5 if quick else 30
    list(ideal_scans(scene, model, seed=0, scans=1))  # compile and warm up
    out = []
    cpu, wall = _cpu_and_wall(lambda: out.extend(ideal_scans(scene, model, seed=0,
                                                             scans=scans)))
    error = np.concatenate([np.linalg.norm(s.scan.points - s.true_points, axis=1)
                            for s in out])
    return {"stage": "simulator", "method": "ideal scans (laser fan, no images)",
            "settings": f"corridor, {scans} scans, pixel_sigma 0.1 px",
            "median_s": wall / scans, "cpu_s": cpu / scans,
            "points_per_scan": float(np.mean([len(s.scan) for s in out])),
            "error": float(math.sqrt(np.mean(error ** 2))),
            "error_unit": "m (rms, noise added by the error model)", "peers": {}}


def run(quick: bool = False) -> list[dict]:
    """Rows: frame rendering per scene and light, ray casting, a recording, ideal scans."""
    model = reference_scanner()
    return [*_frame_rows(model, quick), _hit_map_row(model), _ideal_row(model, quick),
            _recording_row(model, quick, 1), _recording_row(model, quick, 2)]


if __name__ == "__main__":
    from benchmarks.report import markdown_table

    table = run()
    print(markdown_table(table))
    for row in table:
        extra = {k: row[k] for k in ("cpu_s", "frames_per_s", "cpu_per_frame_s",
                                     "wall_per_1000_frames_s") if k in row}
        print(f"{row['method']:48s} {row['settings']:40s} wall {row['median_s']:.3f} s",
              {k: round(v, 3) for k, v in extra.items()})
    print("lighting presets:", LIGHTING)
