""".npz files (`files.save_npz`, `files.load_npz`): each array deflated where that pays and
stored where it does not, read back exactly by `load_npz` and by numpy, and a stored
member whose header claims more than it holds refused."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from scanmap_driver.errors import ScanmapError
from scanmap_driver.files import load_npz, save_npz


def member_types(path) -> dict[str, int]:
    with zipfile.ZipFile(path) as archive:
        return {info.filename: info.compress_type for info in archive.infolist()}


def test_arrays_are_deflated_where_it_pays_and_stored_where_it_does_not(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(0.0, 3.0, (100_000, 3)).astype(np.float32)  # 1.2 MB, like a scan
    grid = np.zeros((400, 400), np.float32)  # a sparse grid layer
    grid[::7, ::3] = 1.5
    small = rng.normal(size=20)  # small arrays: always deflated, it costs nothing
    path = tmp_path / "map.npz"
    save_npz(path, points=points, grid=grid, small=small)
    assert member_types(path) == {"points.npy": zipfile.ZIP_STORED,
                                  "grid.npy": zipfile.ZIP_DEFLATED,
                                  "small.npy": zipfile.ZIP_DEFLATED}
    assert path.stat().st_size < points.nbytes + 0.1 * grid.nbytes
    for arrays in (load_npz(path, ScanmapError), np.load(path)):
        np.testing.assert_array_equal(arrays["points"], points)
        np.testing.assert_array_equal(arrays["grid"], grid)
        np.testing.assert_array_equal(arrays["small"], small)


@settings(max_examples=40, deadline=None)
@given(hnp.arrays(st.sampled_from([np.float32, np.float64, np.int16, np.uint8, np.bool_]),
                  hnp.array_shapes(max_dims=3, max_side=70)),
       st.booleans())
def test_any_array_reads_back_exactly(tmp_path_factory, array, tiled):
    """Whatever the content (noise or repeats, NaN and inf included), bit for bit."""
    value = np.tile(array, (40,) + (1,) * (array.ndim - 1)) if tiled else array
    path = tmp_path_factory.mktemp("npz") / "a.npz"
    save_npz(path, value=value, text=np.array("scanmap"))
    loaded = load_npz(path, ScanmapError)
    assert loaded["value"].dtype == value.dtype and loaded["value"].shape == value.shape
    assert loaded["value"].tobytes() == value.tobytes()
    assert str(loaded["text"]) == "scanmap"


def test_a_stored_member_claiming_more_than_it_holds_is_refused(tmp_path):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                  "shape": (10**9,)})
    path = tmp_path / "liar.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as archive:
        archive.writestr("values.npy", header.getvalue() + bytes(400))
    with pytest.raises(ScanmapError, match=r"liar\.npz.*values\.npy"):
        load_npz(path, ScanmapError)
