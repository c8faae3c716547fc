"""Scan files: npz round trip, PLY through Open3D, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from scanmap_driver.errors import ScanError
from scanmap_driver.scan import Scan


def make_scan(n=100, seed=0):
    rng = np.random.default_rng(seed)
    return Scan(points=rng.normal(size=(n, 3)), colors=rng.integers(0, 256, (n, 3)),
                time=np.linspace(10.0, 12.0, n), heading=np.linspace(0, 2 * np.pi, n),
                frame_index=np.arange(n) // 10, range_sigma=np.full(n, 0.01), index=7,
                stamp=10.0, odom_start=np.eye(4), odom_end=np.eye(4))


def test_npz_round_trip(tmp_path):
    scan = make_scan()
    scan.save(tmp_path / "scan.npz")
    loaded = Scan.load(tmp_path / "scan.npz")
    for name in ("points", "colors", "time", "heading", "frame_index", "range_sigma",
                 "odom_start", "odom_end"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(scan, name))
    assert (loaded.index, loaded.stamp, loaded.has_odometry) == (7, 10.0, True)
    assert loaded.points.dtype == np.float32


def test_ply_is_readable_by_open3d(tmp_path):
    import open3d as o3d

    scan = make_scan()
    scan.save_ply(tmp_path / "scan.ply")
    cloud = o3d.io.read_point_cloud(str(tmp_path / "scan.ply"))
    np.testing.assert_allclose(np.asarray(cloud.points), scan.points, atol=1e-6)
    np.testing.assert_allclose(np.asarray(cloud.colors) * 255, scan.colors, atol=0.6)


def test_empty_scan_round_trip(tmp_path):
    Scan.empty(index=3).save(tmp_path / "e.npz")
    loaded = Scan.load(tmp_path / "e.npz")
    assert len(loaded) == 0 and loaded.index == 3 and not loaded.has_odometry


def test_shape_mismatch_names_the_field():
    with pytest.raises(ScanError, match=r"Scan\.time"):
        Scan(points=np.zeros((3, 3)), colors=np.zeros((3, 3)), time=np.zeros(2),
             heading=np.zeros(3), frame_index=np.zeros(3), range_sigma=np.zeros(3))


def test_corrupt_and_truncated_files(tmp_path):
    path = tmp_path / "scan.npz"
    make_scan().save(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ScanError, match=r"scan\.npz"):
        Scan.load(path)
    np.savez(tmp_path / "other.npz", points=np.zeros((2, 3)))
    with pytest.raises(ScanError, match="missing arrays"):
        Scan.load(tmp_path / "other.npz")


def test_select_keeps_metadata():
    scan = make_scan()
    sub = scan.select(scan.frame_index == 2)
    assert len(sub) == 10 and sub.index == 7


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    umask = os.umask(0)
    os.umask(umask)
    make_scan().save(tmp_path / "s.npz")
    assert (tmp_path / "s.npz").stat().st_mode & 0o777 == 0o666 & ~umask
