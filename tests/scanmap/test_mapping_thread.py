"""Online mapping: a background thread maps while another thread queries."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from scanmap import DeviceError, MapError, Mapper
from scanmap.grid import GridConfig
from scanmap.mapper_config import MapperConfig
from scanmap.obstacles import Status
from scanmap_driver import reference_scanner
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.transforms import se2_to_pose


@pytest.fixture(scope="module")
def scans():
    return [ideal.scan for ideal in ideal_scans(builtin_scene("office"), seed=4, scans=4)]


def test_queries_are_served_while_scans_are_mapped(scans, tmp_path):
    mapper = Mapper(reference_scanner(), offline=True)
    mapping = mapper.start()
    answers, done = [], threading.Event()

    def controller() -> None:
        while not done.is_set():
            answers.append((mapper.obstacles.snapshot, mapper.obstacles.nearest(0.5, 0.0)))

    poller = threading.Thread(target=controller)
    poller.start()
    for scan in scans:
        mapping.submit(scan, timeout=60)
    mapper.save(tmp_path / "during.npz")  # saved while mapping: the file is whole
    mapping.close()
    assert mapping.join(timeout=120)
    done.set()
    poller.join()
    assert mapping.mapped == len(scans) and mapping.error is None and not mapping.errors
    assert mapper.statuses == ["initialised", "ok", "ok", "ok"]
    seen = [snap for snap, _ in answers if snap is not None]
    stamps = [snap.stamp for snap in seen]
    assert len(set(map(id, seen))) >= 2 and stamps == sorted(stamps)  # each a whole scan newer
    for snap, nearest in answers:
        if snap is not None:
            assert nearest.status in (Status.OK, Status.UNKNOWN)
            assert np.isfinite(nearest.clearance)
    assert len(Mapper.load(tmp_path / "during.npz", offline=True)) <= len(scans)


def test_a_source_fault_marks_the_obstacle_map_faulted(scans):
    def scanner():
        yield from scans[:2]
        raise DeviceError("camera: no frame for 2 s")

    mapper = Mapper(reference_scanner(), offline=True)
    mapping = mapper.start(scanner())
    assert mapping.join(timeout=120)
    assert isinstance(mapping.error, DeviceError) and mapping.mapped == 2
    answer = mapper.obstacles.nearest(0.0, 0.0)
    assert answer.status == Status.FAULTED and answer.clearance == 0.0
    assert "camera" in mapper.obstacles.fault


def test_a_scan_the_map_cannot_hold_is_skipped_and_mapping_goes_on(scans):
    """A scan beyond the grid's extent raises MapError in the mapper: it is kept in
    `errors`, the thread maps the next scans."""
    config = MapperConfig(grid=GridConfig(extent=20.0))
    mapper = Mapper(reference_scanner(), config, offline=True,
                    initial_pose=se2_to_pose(30.0, 0.0, 0.0))
    mapping = mapper.start(scans[:2])
    assert mapping.join(timeout=120)
    assert mapping.error is None and len(mapping.errors) >= 1
    assert all(isinstance(e, MapError) for e in mapping.errors)
    assert "extent" in str(mapping.errors[0])


def test_stop_ends_a_waiting_thread_and_submit_says_why_it_cannot(scans):
    mapper = Mapper(reference_scanner(), offline=True)
    mapping = mapper.start(capacity=1)
    assert mapping.running
    assert mapping.stop(timeout=10)
    assert not mapping.running and mapping.mapped == 0
    with pytest.raises(MapError, match="not running"):
        mapping.submit(scans[0])
    own = mapper.start(iter(()))
    with pytest.raises(MapError, match="own source"):
        own.submit(scans[0])
    assert own.join(timeout=10)
