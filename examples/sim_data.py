"""The examples' data: simulated recordings, made once and kept under ./data/.

On a real robot these would be your own recordings (`scanmap record`); here the
simulator renders what the scanner's webcam would have recorded in a built-in scene,
with ground truth, so the examples also report their errors.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

from scanmap_driver import INDEX_NAME, Recording, reference_scanner
from scanmap_driver.sim import builtin_scene, simulate_recording

DATA = Path(__file__).resolve().parents[1] / "data"


def ensure_recording(path: Path, scene: str, scans: int, workers: int = 2) -> Path:
    """The recording at `path`, simulated first (`scans` scans of the built-in `scene`)
    unless it is already there. It is rendered into a side folder and renamed when
    complete, so an interrupted run leaves no half recording behind."""
    path = Path(path)
    if (path / INDEX_NAME).is_file():
        have = len(Recording.open(path).scans)
        print(f"using the recording {path} ({have} scans)")
        return path
    partial = path.with_name(path.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    print(f"simulating {scans} scans of the {scene} into {path} (once; it is kept)")
    start = time.perf_counter()
    simulate_recording(builtin_scene(scene), partial, reference_scanner(), scans=scans,
                       workers=workers, progress=lambda line: print("  " + line))
    partial.rename(path)
    print(f"simulated in {time.perf_counter() - start:.0f} s")
    return path
