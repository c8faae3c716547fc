"""Compile every Numba kernel of the main job ahead of time, into Numba's on-disk cache.

Numba compiles a kernel on its first call for the argument types of that call and, with
`cache=True`, keeps the machine code beside the source. A newcomer's first run would
otherwise spend most of its time compiling (a segmentation step alone took 4 s). The
surest way to compile exactly the signatures a real run uses is a real run: simulate a
one-scan recording of the built-in corridor, map it as `scanmap map` does, and run the
mapper's own warm-up (live mapping, obstacle queries). `scripts/setup.sh` calls this
through `scanmap warm-up`; on a warm cache it only loads what is there.

Numba checks a cached kernel against its own source file only: a kernel that calls one
from another module keeps the old callee's machine code when only that module changed
(after a `git pull`, say). So the warm-up first compares a digest of every source with
the one it compiled last time, and drops all cached kernels when they differ.
"""

from __future__ import annotations

import hashlib
import tempfile
import time
from pathlib import Path

import scanmap_driver
from scanmap.mapping import Mapper
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, simulate_recording

PACKAGES = (Path(__file__).resolve().parents[1], Path(scanmap_driver.__file__).parent)
STAMP = "kernel-sources.sha256"


def drop_stale_caches(packages: tuple[Path, ...] = PACKAGES) -> int:
    """Remove every cached Numba kernel under `packages` if any source changed since the
    last call (digest kept in the first package's __pycache__); returns the files removed."""
    digest = hashlib.sha256()
    for package in packages:
        for source in sorted(package.rglob("*.py")):
            digest.update(str(source.relative_to(package)).encode())
            digest.update(source.read_bytes())
    stamp = packages[0] / "__pycache__" / STAMP
    if stamp.is_file() and stamp.read_text() == digest.hexdigest():
        return 0
    stale = [f for package in packages for pattern in ("*.nbi", "*.nbc")
             for f in package.rglob(pattern)]
    try:
        for f in stale:
            f.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except PermissionError:  # a read-only install: Numba caches in the user's folder
        return 0
    return len(stale)


def warm_kernels(scene: str = "corridor") -> float:
    """Run the main job's code paths once on a tiny recording, after dropping cached
    kernels compiled from other sources; returns the seconds taken."""
    start = time.perf_counter()
    drop_stale_caches()
    model = reference_scanner()
    with tempfile.TemporaryDirectory(prefix="scanmap-warm-") as tmp:
        recording = simulate_recording(builtin_scene(scene), Path(tmp) / "recording", model,
                                       scans=2, workers=1)
        map_to_folder(recording, Path(tmp) / "map", workers=1)
    Mapper(model).warm_up()
    return time.perf_counter() - start
