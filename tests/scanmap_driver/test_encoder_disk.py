"""Encoder disk code: de Bruijn property, sector lookup."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.encoder_disk import EncoderDisk, de_bruijn, window_is_unique
from scanmap_driver.errors import CalibrationError


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
def test_de_bruijn_contains_every_word_once(order):
    code = de_bruijn(order)
    assert len(code) == 2**order
    doubled = code + code[: order - 1]
    words = {doubled[i:i + order] for i in range(len(code))}
    assert words == {format(k, f"0{order}b") for k in range(2**order)}


def test_any_five_sectors_fix_the_position_but_four_do_not():
    code = de_bruijn(5)
    assert window_is_unique(code, 5)
    assert not window_is_unique(code, 4)


@given(st.floats(-20.0, 20.0), st.floats(-1.0, 1.0))
def test_value_at_follows_sectors(angle, offset):
    disk = EncoderDisk(height=0.9, inner_radius=0.03, outer_radius=0.05, code=de_bruijn(5),
                       zero_offset=offset)
    sector = int(np.floor((angle - offset) / disk.sector_angle)) % 32
    assert disk.value_at(np.array(angle)) == int(disk.code[sector])


def test_invalid_disks():
    with pytest.raises(CalibrationError, match="inner_radius"):
        EncoderDisk(height=0.9, inner_radius=0.05, outer_radius=0.03, code="0101")
    with pytest.raises(CalibrationError, match="code"):
        EncoderDisk(height=0.9, inner_radius=0.03, outer_radius=0.05, code="01x1")
