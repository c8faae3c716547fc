"""Shared test helpers: the real data in ../shared/data/real, read in place."""

from __future__ import annotations

import os

# Small matrix products must not fan out over every core of a shared 2-core machine.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path

import pytest
from hypothesis import settings

# Timings belong to benchmarks/, not to pass/fail tests: on a shared machine the first
# example of a property (imports, Numba's cache) can take seconds, so no deadline. The
# examples are derived from each test's name, so every run (CI's too) draws the same ones
# and a result is reproducible.
settings.register_profile("scanmap", deadline=None, derandomize=True)
settings.load_profile("scanmap")

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def real_data(relative: str) -> Path:
    """Path of a file or folder under shared/data/real; skips the test when it is absent."""
    path = REAL_DATA / relative
    if not path.exists():
        pytest.skip(f"real data {path} is absent (it lives in ../shared beside the checkout)")
    return path


@pytest.fixture(scope="session")
def office_recording(tmp_path_factory) -> Path:
    """One rendered scan of the built-in office (seed 7) with ground truth, made once."""
    from scanmap_driver import reference_scanner
    from scanmap_driver.sim import builtin_scene
    from scanmap_driver.sim.simulate import simulate_recording

    out = tmp_path_factory.mktemp("office_recording")
    simulate_recording(builtin_scene("office"), out, reference_scanner(), seed=7, scans=1)
    return out
