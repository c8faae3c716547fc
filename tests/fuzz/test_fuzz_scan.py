"""Fuzzed scan files (`Scan.load`): refused with ScanError naming the file, or read with
every value exactly as stored (numpy's own reading of the mutated file is the truth)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import ScanError
from scanmap_driver.scan import Scan

from .mutations import FUZZ, mutated_npz, read_within

FIELDS = ("points", "colors", "time", "heading", "frame_index", "range_sigma")


def _original(tmp_path_factory) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    n = 40
    scan = Scan(points=rng.normal(size=(n, 3)), colors=rng.integers(0, 256, (n, 3)),
                time=np.linspace(5.0, 7.0, n), heading=np.linspace(0.0, 6.3, n),
                frame_index=np.repeat(np.arange(8), 5), range_sigma=np.full(n, 0.01),
                index=4, stamp=5.0, odom_start=np.eye(4), odom_end=np.eye(4))
    path = tmp_path_factory.mktemp("scan") / "scan.npz"
    scan.save(path)
    with np.load(path) as npz:
        return {key: npz[key] for key in npz.files}


@FUZZ
@given(data=st.data())
def test_fuzzed_scan_file_is_refused_or_read_as_stored(tmp_path_factory, data):
    arrays = _original(tmp_path_factory)
    path = tmp_path_factory.mktemp("fuzz") / "scan_0004.npz"
    path.write_bytes(data.draw(mutated_npz(arrays)))
    scan = read_within(lambda: Scan.load(path), ScanError, path)
    if scan is None:
        return
    with np.load(path) as npz:
        for name in FIELDS:
            stored = npz[name]
            assert stored.dtype.kind in "iuf" and stored.shape == getattr(scan, name).shape
            assert np.isfinite(stored).all()
            exact = stored.astype(np.float64)
            loaded = getattr(scan, name).astype(np.float64)
            if stored.dtype.kind in "iu":
                assert np.array_equal(loaded, exact)  # no wrapped integers
            else:
                assert np.allclose(loaded, exact, rtol=1e-6, atol=0.0)
