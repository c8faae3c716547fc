"""The warm-up drops cached kernels compiled from other sources (Numba checks a kernel
against its own file only, not the modules whose kernels it calls), and a second run of
the main job compiles nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from scanmap.pipelines.warm_cache import drop_stale_caches
from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, simulate_recording


def _cached(package: Path, name: str) -> Path:
    cache = package / "__pycache__" / name
    cache.parent.mkdir(exist_ok=True)
    cache.write_bytes(b"machine code")
    return cache


def test_cached_kernels_go_when_any_source_changes_and_stay_otherwise(tmp_path):
    caller, callee = tmp_path / "caller", tmp_path / "callee"
    for package in (caller, callee):
        (package / "sub").mkdir(parents=True)
    (caller / "map.py").write_text("from callee.planes import fit\n")
    (callee / "sub" / "planes.py").write_text("def fit(): return 1\n")
    stale = [_cached(caller, "map.kernel-1.py311.nbi"), _cached(callee / "sub", "p.nbc")]
    assert drop_stale_caches((caller, callee)) == 2  # never stamped: compiled from unknown
    assert not any(f.exists() for f in stale)
    fresh = _cached(caller, "map.kernel-1.py311.nbi")
    assert drop_stale_caches((caller, callee)) == 0  # same sources: the cache stays
    assert fresh.exists()
    (callee / "sub" / "planes.py").write_text("def fit(): return 2\n")  # only the callee
    assert drop_stale_caches((caller, callee)) == 1
    assert not fresh.exists()


def test_a_read_only_install_is_left_alone(tmp_path, monkeypatch):
    """Where the package folder is not writable (Numba then caches in the user's folder)
    the warm-up goes on without a stamp instead of failing."""
    package = tmp_path / "installed"
    package.mkdir()
    (package / "a.py").write_text("x = 1\n")

    def refuse(*args, **kwargs):
        raise PermissionError("read-only")

    monkeypatch.setattr(Path, "mkdir", refuse)
    assert drop_stale_caches((package,)) == 0
    assert not (package / "__pycache__").exists()


def test_a_second_run_of_the_main_job_compiles_no_kernel(tmp_path):
    """Each kernel `scanmap map` runs loads from Numba's cache once compiled: one that
    cannot be cached (an omitted array argument did that) compiles on every run, 0.6 s."""
    recording = tmp_path / "corridor"
    simulate_recording(builtin_scene("corridor"), recording, reference_scanner(), scans=1)
    job = "import sys; from scanmap.pipelines.offline import map_to_folder; " \
          "map_to_folder(sys.argv[1], sys.argv[2])"
    logs = [subprocess.run([sys.executable, "-c", job, str(recording), str(tmp_path / f"m{k}")],
                           env=os.environ | {"NUMBA_DEBUG_CACHE": "1"}, capture_output=True,
                           text=True, check=True, timeout=600) for k in range(2)]
    loaded = [line for line in logs[1].stdout.splitlines() if "data loaded" in line]
    saved = [line for line in logs[1].stdout.splitlines() if "data saved" in line]
    assert len(loaded) > 20 and not saved, saved
