"""Simulated recordings: the raw recording a real scanner would make in a scene, with
its ground truth, deterministic for a seed.

`simulate_recording` renders every frame of every scan (`render`), writes the MJPG videos
and sidecars in the recording format (`scanmap_driver.recording`) and the truth under
`ground_truth/`: per scan `truth`, the scene as simulated (`scene.json`), the truth
raster (`raster.npz`, 0.05 m, band 0.05-1.0 m) and the true pose at each scan's first frame
(`trajectory.txt`, TUM: `t x y z qx qy qz qw`). `simulate_ideal` writes ideal scans instead
(processed `scan_NNNN.npz` files, as `scanmap process` would) with the same truth files.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..files import atomic_path
from ..recording import GROUND_TRUTH, RecordingWriter, scan_name
from ..scanner_model import ScannerModel
from ..transforms import rotation_to_quaternion
from .camera_effects import SimCameraConfig
from .geometry import scene_planes
from .ideal import ideal_scans
from .plan import ScanPlan, plan_scans
from .raster import truth_raster
from .render import RenderedFrame, Renderer
from .scene import LIGHTING, Scene
from .truth import ScanTruth, truth_path

_FRAME_NOISE = 20  # random stream purpose


def lit_scene(scene: Scene, lighting: str | None) -> Scene:
    """The scene under a lighting preset ('dark', 'bright'), or as it is (None)."""
    if lighting is None:
        return scene
    if lighting not in LIGHTING:
        raise ValueError(f"lighting: expected one of {sorted(LIGHTING)}, got {lighting!r}")
    return scene.with_ambient(LIGHTING[lighting])


def simulate_recording(scene: Scene, out: str | os.PathLike[str], model: ScannerModel, *,
                       seed: int = 0, scans: int | None = None,
                       camera: SimCameraConfig | None = None, workers: int = 1,
                       progress: Callable[[str], None] | None = None) -> Path:
    """Render and write a raw recording with ground truth; returns its folder.

    Frames render in `workers` processes (Open3D holds the GIL while it casts rays, so
    threads would not run in parallel). The processes are spawned: a script calling this
    with workers > 1 needs the usual `if __name__ == "__main__":` guard. Every frame's
    noise has its own seed, so the files are the same for any number of workers.
    """
    camera = camera or SimCameraConfig()
    out = Path(out)
    plans = plan_scans(scene, model, seed, scans)
    writer = RecordingWriter(out, model, source="simulator", extra={
        "scene": scene.name, "seed": seed, "ambient": scene.ambient, "camera": asdict(camera)})
    _write_common_truth(out, scene, plans)
    with _frame_pool(scene, model, camera, workers) as render:
        for plan in plans:
            frames = render([(plan, i, seed) for i in range(plan.frame_times.shape[0])])
            with writer.scan(stamp=plan.stamp, exposure=camera.exposure) as scan:
                for frame in frames:
                    scan.add_jpeg(frame.jpeg, plan.stamp + frame.truth.time)
                for entry in plan.motion.log:
                    scan.log_motor(plan.stamp + entry["t"], entry["command"],
                                   duty=entry["duty"])
                scan.set_odometry(plan.odom_start, plan.odom_end)
            plane_object = scene_planes(scene.at_scan(plan.index)).plane_object
            ScanTruth.from_frames(plan, [f.truth for f in frames], plane_object
                                  ).save(truth_path(out, plan.index))
            if progress:
                progress(f"scan {plan.index + 1}/{len(plans)}: {len(frames)} frames")
    return out


_worker: dict[str, Renderer] = {}  # the renderer of a worker process


def _start_worker(scene: dict, model: dict, camera: SimCameraConfig) -> None:
    _worker["renderer"] = Renderer(Scene.from_dict(scene), ScannerModel.from_dict(model),
                                   camera)


def _render_task(task: tuple[ScanPlan, int, int]) -> RenderedFrame:
    plan, frame, seed = task
    rng = np.random.default_rng([seed, _FRAME_NOISE, plan.index, frame])
    return _worker["renderer"].render(plan, frame, rng)


@contextlib.contextmanager
def _frame_pool(scene: Scene, model: ScannerModel, camera: SimCameraConfig,
                workers: int) -> Iterator[Callable[[list], list[RenderedFrame]]]:
    """A function rendering a list of (plan, frame, seed) tasks, in worker processes."""
    init = (scene.to_dict(), model.to_dict(), camera)
    if workers <= 1:
        _start_worker(*init)
        yield lambda tasks: [_render_task(task) for task in tasks]
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                             initargs=init) as pool:
        yield lambda tasks: list(pool.map(_render_task, tasks, chunksize=4))


def simulate_ideal(scene: Scene, out: str | os.PathLike[str], model: ScannerModel, *,
                   seed: int = 0, scans: int | None = None,
                   progress: Callable[[str], None] | None = None) -> Path:
    """Write ideal scans (`scan_NNNN.npz`) with ground truth; returns the folder."""
    out = Path(out)
    _write_common_truth(out, scene, plan_scans(scene, model, seed, scans))
    for ideal in ideal_scans(scene, model, seed=seed, scans=scans):
        ideal.scan.save(out / f"{scan_name(ideal.scan.index)}.npz")
        if progress:
            progress(f"scan {ideal.scan.index + 1}: {len(ideal.scan)} points")
    return out


def _write_common_truth(out: Path, scene: Scene, plans: list[ScanPlan]) -> None:
    folder = out / GROUND_TRUTH
    scene.save(folder / "scene.json")
    truth_raster(scene).save(folder / "raster.npz")
    lines = ["# true pose of base_link in map at each scan's first frame: t x y z qx qy qz qw"]
    for plan in plans:
        pose = plan.base_poses_at(plan.frame_times[0])[0]
        q = rotation_to_quaternion(pose[:3, :3])
        values = [plan.stamp + plan.frame_times[0], *pose[:3, 3], *q]
        lines.append(" ".join(f"{v:.9f}" for v in values))
    with atomic_path(folder / "trajectory.txt") as tmp:
        tmp.write_text("\n".join(lines) + "\n")
