"""Pinholes (issue 17 item 6): an UNKNOWN patch without any hit, at most `max_pinhole` each
side, whose every neighbour is FREE, is FREE; anything else round it keeps it UNKNOWN."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from scanmap.navigation.floor import DROP_OFF, FREE, OBSTACLE, UNKNOWN
from scanmap.navigation.floor._states import _pinholes


@given(h=st.integers(1, 5), w=st.integers(1, 5), y=st.integers(1, 12), x=st.integers(1, 12),
       neighbour=st.sampled_from([None, UNKNOWN, OBSTACLE, DROP_OFF]),
       hit=st.booleans(), at=st.integers(0, 100))
def test_a_pinhole_is_filled_only_when_small_hitless_and_enclosed_by_free(h, w, y, x,
                                                                         neighbour, hit, at):
    state = np.full((20, 20), FREE, np.uint8)
    nlev = np.zeros((20, 20), np.int32)
    state[y:y + h, x:x + w] = UNKNOWN
    if hit:  # a hit inside the patch (a hole's far wall, a low object)
        nlev[y + at % h, x + (at // h) % w] = 1
    if neighbour is not None:  # a neighbour not FREE on the patch's ring
        state[y - 1, x + at % w] = neighbour
        nlev[y - 1, x + at % w] = 1 if neighbour != UNKNOWN else 0
    filled = _pinholes(state, nlev, 3)
    touches_edge = y + h >= 20 or x + w >= 20
    small = h <= 3 and w <= 3
    expect = small and not hit and not touches_edge \
        and neighbour in (None, UNKNOWN) and not (neighbour == UNKNOWN and h + 1 > 3)
    assert filled[y:y + h, x:x + w].all() == expect
    assert not filled[state != UNKNOWN].any()
    assert filled.sum() in (0, h * w + (neighbour == UNKNOWN))
