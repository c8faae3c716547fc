"""Shared test helpers: the real data in ../shared/data/real, read in place."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def real_data(relative: str) -> Path:
    """Path of a file or folder under shared/data/real; skips the test when it is absent."""
    path = REAL_DATA / relative
    if not path.exists():
        pytest.skip(f"real data {path} is absent (it lives in ../shared beside the checkout)")
    return path
