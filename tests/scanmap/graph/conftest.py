"""The ring scene's ideal scans, simulated once for every loop-closure test."""

from __future__ import annotations

import pytest

from scanmap_driver.sim import ideal_scans
from tests.scanmap.graph.ring_scene import ring_scene


@pytest.fixture(scope="session")
def ring_ideal() -> list:
    """Ideal scans (with their truth) of the whole path round the ring."""
    return list(ideal_scans(ring_scene(), seed=3))
