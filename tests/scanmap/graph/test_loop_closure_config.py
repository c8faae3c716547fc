"""LoopClosureConfig as a MapperConfig part: TOML in and out, bad values named."""

from __future__ import annotations

import pytest

from scanmap.graph import LoopClosureConfig
from scanmap.mapping import MapperConfig
from scanmap_driver.errors import MapError


def test_off_by_default_and_a_toml_table_switches_it_on(tmp_path):
    assert not MapperConfig().loop_closure.enabled
    path = tmp_path / "mapper.toml"
    path.write_text("[loop_closure]\nenabled = true\ngate_radius = 2.5\n")
    config = MapperConfig.load(path)
    assert config.loop_closure == LoopClosureConfig(enabled=True, gate_radius=2.5)
    path.write_text(config.to_toml())
    assert MapperConfig.load(path) == config


def test_unknown_keys_and_negative_values_are_refused(tmp_path):
    path = tmp_path / "mapper.toml"
    path.write_text("[loop_closure]\ngate = 2.5\n")
    with pytest.raises(MapError, match=r"loop_closure.*gate"):
        MapperConfig.load(path)
    with pytest.raises(MapError, match="min_fitness"):
        LoopClosureConfig(min_fitness=-1.0)
