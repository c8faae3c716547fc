"""The warm-up drops cached kernels compiled from other sources (Numba checks a kernel
against its own file only, not the modules whose kernels it calls)."""

from __future__ import annotations

from pathlib import Path

from scanmap.pipelines.warm_cache import drop_stale_caches


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
