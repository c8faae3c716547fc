"""An .npz whose array header is not a Python literal (a fuzzing find) is the reader's
own error, naming the file, not a SyntaxError or tokenize.TokenError from numpy."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from scanmap_driver.errors import MapError
from scanmap_driver.files import load_npz


@pytest.mark.parametrize("header", [b"{'descr': '<f4', 'fortran_order': Fa)))))))",
                                    b"{'descr': '<f4', 'fortran_order': (((((("])
def test_a_header_that_is_no_literal_is_the_readers_error(tmp_path, header):
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3, np.float32))
    good = buffer.getvalue()
    start = good.index(b"{")
    end = good.index(b"}") + 1
    bad = good[:start] + header.ljust(end - start) + good[end:]
    path = tmp_path / "bad.npz"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("points.npy", bad)
    with pytest.raises(MapError, match=r"bad\.npz"):
        load_npz(path, MapError)
