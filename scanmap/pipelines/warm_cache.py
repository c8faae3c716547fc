"""Compile every Numba kernel of the main job ahead of time, into Numba's on-disk cache.

Numba compiles a kernel on its first call for the argument types of that call and, with
`cache=True`, keeps the machine code beside the source. A newcomer's first run would
otherwise spend most of its time compiling (a segmentation step alone took 4 s). The
surest way to compile exactly the signatures a real run uses is a real run: simulate a
one-scan recording of the built-in corridor, map it as `scanmap map` does, and run the
mapper's own warm-up (live mapping, obstacle queries). `scripts/setup.sh` calls this
through `scanmap warm-up`; on a warm cache it only loads what is there.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from scanmap.mapping import Mapper
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, simulate_recording


def warm_kernels(scene: str = "corridor") -> float:
    """Run the main job's code paths once on a tiny recording; returns the seconds taken."""
    start = time.perf_counter()
    model = reference_scanner()
    with tempfile.TemporaryDirectory(prefix="scanmap-warm-") as tmp:
        recording = simulate_recording(builtin_scene(scene), Path(tmp) / "recording", model,
                                       scans=2, workers=1)
        map_to_folder(recording, Path(tmp) / "map", workers=1)
    Mapper(model).warm_up()
    return time.perf_counter() - start
