"""The fleet on a real Dask LocalCluster (two one-thread worker processes) against the serial
jobs on the same simulated recordings: same files, a killed worker's tasks re-run, a
re-run resumes, a corrupt recording fails alone."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from scanmap.cli import main
from scanmap.pipelines.fleet import (
    MANIFEST,
    SUMMARY,
    connect,
    file_record,
    fleet_inputs,
    run_fleet,
)
from scanmap.pipelines.offline import map_to_folder
from scanmap_driver import ScanmapError, reference_scanner
from scanmap_driver.processing import process_recording
from scanmap_driver.sim import builtin_scene
from scanmap_driver.sim.simulate import simulate_recording

pytest.importorskip("distributed")

NAMES = ("a", "b")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> list[Path]:
    """Two small office recordings (2 scans each, different seeds)."""
    folder = tmp_path_factory.mktemp("recordings")
    for seed, name in enumerate(NAMES, start=1):
        simulate_recording(builtin_scene("office"), folder / name, reference_scanner(),
                           seed=seed, scans=2)
    return [folder / name for name in NAMES]


@pytest.fixture(scope="module")
def serial(recordings, tmp_path_factory) -> Path:
    """The serial jobs' outputs: serial/process/NAME and serial/map/NAME."""
    out = tmp_path_factory.mktemp("serial")
    for path in recordings:
        process_recording(path, out / "process" / path.name)
        map_to_folder(path, out / "map" / path.name)
    return out


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two one-thread worker processes, closed after the module."""
    with connect("local:2") as client:
        yield client


def assert_same_npz(serial: Path, fleet: Path) -> None:
    """The same arrays, bit for bit (NaN equal to NaN)."""
    with np.load(serial) as a, np.load(fleet) as b:
        assert a.files == b.files
        for key in a.files:
            nan = a[key].dtype.kind in "fc"
            assert np.array_equal(a[key], b[key], equal_nan=nan), (serial.name, key)


def assert_same_processed(serial: Path, fleet: Path) -> None:
    """Every scan array bit-identical, the .ply bytes and the per-scan summaries equal."""
    files = sorted(p.name for p in serial.iterdir())
    assert sorted(p.name for p in fleet.iterdir()) == sorted([*files, MANIFEST])
    for name in files:
        if name.endswith(".npz"):
            assert_same_npz(serial / name, fleet / name)
        elif name.endswith(".ply"):
            assert (serial / name).read_bytes() == (fleet / name).read_bytes(), name
    scans = [json.loads((f / "summary.json").read_text())["scans"] for f in (serial, fleet)]
    assert scans[0] == scans[1]


def assert_same_map(serial: Path, fleet: Path) -> None:
    """Every map.npz array equal (the same scans fused in the same order by the same code
    are the same floating-point operations, so no tolerance is needed there); the
    trajectory within 1e-9 m / rad, as its text rounds."""
    assert_same_npz(serial / "map.npz", fleet / "map.npz")
    tum = [np.loadtxt(f / "trajectory.tum") for f in (serial, fleet)]
    np.testing.assert_allclose(tum[1], tum[0], rtol=0, atol=1e-9)


def test_processed_scans_equal_the_serial_ones(client, recordings, serial, tmp_path):
    summary = run_fleet(client, "process", recordings, tmp_path, options={"chunk_scans": 1})
    assert summary["done"] == list(NAMES) and not summary["failed"]
    for name in NAMES:
        assert_same_processed(serial / "process" / name, tmp_path / name)
        manifest = json.loads((tmp_path / name / MANIFEST).read_text())
        assert all(file_record(tmp_path / name / f) == record
                   for f, record in manifest["files"].items())
    assert json.loads((tmp_path / SUMMARY).read_text()) == summary
    assert not (tmp_path / ".staging").exists()


def test_maps_equal_the_serial_ones(client, recordings, serial, tmp_path):
    summary = run_fleet(client, "map", recordings, tmp_path)
    assert summary["done"] == list(NAMES) and not summary["failed"]
    for name in NAMES:
        assert_same_map(serial / "map" / name, tmp_path / name)


def test_a_rerun_resumes_redoes_damage_and_a_corrupt_recording_fails_alone(
        client, recordings, serial, tmp_path):
    options = {"chunk_scans": 2}
    run_fleet(client, "process", recordings, tmp_path / "out", options=options)
    damaged = tmp_path / "out" / "a" / "scan_0001.npz"
    data = bytearray(damaged.read_bytes())
    data[len(data) // 2] ^= 0xFF
    damaged.write_bytes(bytes(data))
    corrupt = tmp_path / "bad"
    corrupt.mkdir()
    (corrupt / "recording.json").write_text('{"format": ')
    seen = []
    summary = run_fleet(client, "process", [*recordings, corrupt], tmp_path / "out",
                        options=options, progress=lambda outcome, _: seen.append(outcome))
    assert summary["done"] == ["a"] and summary["resumed"] == ["b"]
    assert "scan_0001.npz: size or sha256 differs" in summary["inputs"][0]["reason"]
    assert list(summary["failed"]) == ["bad"]
    assert "recording.json: not valid JSON" in summary["failed"]["bad"]
    assert sorted(o["name"] for o in seen) == ["a", "b", "bad"]
    for name in NAMES:
        assert_same_processed(serial / "process" / name, tmp_path / "out" / name)
    assert not (tmp_path / "out" / "bad").exists()


def _executing(dask_worker) -> list[str]:
    """The keys a worker is running now (run on the worker by `client.run`)."""
    return [str(task.key) for task in dask_worker.state.executing]


def _kill_a_busy_worker(client, stop: threading.Event, killed: list[int]) -> None:
    """SIGKILL the process of the first worker seen running a chunk of scans."""
    pids = client.run(os.getpid)
    while not stop.is_set():
        for address, keys in client.run(_executing).items():
            if any(key.startswith("process_chunk") for key in keys):
                os.kill(pids[address], signal.SIGKILL)
                killed.append(pids[address])
                return
        time.sleep(0.05)


def test_a_worker_killed_mid_task_loses_nothing(client, recordings, serial, tmp_path):
    stop, killed = threading.Event(), []
    killer = threading.Thread(target=_kill_a_busy_worker, args=(client, stop, killed))
    killer.start()
    try:
        summary = run_fleet(client, "process", recordings, tmp_path,
                            options={"chunk_scans": 1})
    finally:
        stop.set()
        killer.join()
    assert killed, "no worker was seen running a chunk"
    assert killed[0] not in client.run(os.getpid).values()
    assert summary["done"] == list(NAMES) and not summary["failed"]
    for name in NAMES:
        assert_same_processed(serial / "process" / name, tmp_path / name)


def test_inputs_are_a_folder_or_a_list_and_names_are_unique(tmp_path):
    for name in ("r1", "r2", ".hidden"):
        (tmp_path / "fleet" / name).mkdir(parents=True)
    assert fleet_inputs(tmp_path / "fleet") == [tmp_path / "fleet" / n for n in ("r1", "r2")]
    listing = tmp_path / "list.txt"
    listing.write_text("# tonight\nfleet/r2\n\nfleet/r1\n")
    assert fleet_inputs(listing) == [tmp_path / "fleet" / n for n in ("r2", "r1")]
    listing.write_text("fleet/r1\nother/r1\n")
    with pytest.raises(ScanmapError, match=r"names used twice: \['r1'\]"):
        fleet_inputs(listing)


def test_an_unknown_cluster_is_a_clear_error(tmp_path, capsys):
    (tmp_path / "fleet" / "r1").mkdir(parents=True)
    assert main(["fleet", "process", str(tmp_path / "fleet"), "--out", str(tmp_path / "out"),
                 "--cluster", "yarn"]) == 1
    assert "--cluster 'yarn': expected local, local:N" in capsys.readouterr().err
