"""Online mapping: a background thread maps while another thread queries."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from scanmap import DeviceError, MapError, Mapper
from scanmap.grid.height_grid import GridConfig
from scanmap.mapping.config import MapperConfig
from scanmap.navigation.obstacles import QueryStatus
from scanmap_driver import reference_scanner
from scanmap_driver.continuous_scanning import ContinuousScanning
from scanmap_driver.scan import Scan
from scanmap_driver.scanner import ScanConfig
from scanmap_driver.sim import builtin_scene, ideal_scans
from scanmap_driver.sim.motor_model import MotorModelConfig
from scanmap_driver.transforms import se2_to_pose

from ..scanmap_driver.polling import wait_until
from ..scanmap_driver.sim_rig import WallAssembler, rig

FAST = MotorModelConfig(full_speed=2.0 * np.pi * 1.6)  # about 0.9 s per revolution


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
            assert nearest.status in (QueryStatus.OK, QueryStatus.UNKNOWN)
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
    assert answer.status == QueryStatus.FAULTED and answer.clearance == 0.0
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


class RoomAssembler(WallAssembler):
    """Frames of the sim rig become points of a square room (4 m wide, walls to 1 m, floor
    from 0.8 m), swept over the headings since the previous frame: a live scanner's
    scans of a room, fast enough to run the real loop."""

    HALF_SIDE = 2.0

    def finish(self, index: int = 0, odom_start=None, odom_end=None) -> tuple[Scan, int]:
        if len(self.headings) < 2:  # a scan cancelled at its start
            return Scan.empty(index, self.times[0] if self.times else 0.0), len(self.times)
        headings = np.unwrap(self.headings)
        parts = []
        for k in range(1, len(headings)):
            angle = np.linspace(headings[k - 1], headings[k], 40, endpoint=False)
            c, s = np.cos(angle), np.sin(angle)
            wall = self.HALF_SIDE / np.maximum(np.abs(c), np.abs(s))
            ranges = np.concatenate([np.repeat(wall, 12), np.repeat(wall * 0.4, 3),
                                     np.repeat(wall * 0.6, 3)])
            heights = np.concatenate([np.tile(np.linspace(0.05, 1.0, 12), len(angle)),
                                      np.zeros(6 * len(angle))])
            turn = np.concatenate([np.repeat(angle, 12), np.repeat(angle, 3),
                                   np.repeat(angle, 3)])
            parts.append((k, np.column_stack([ranges * np.cos(turn), ranges * np.sin(turn),
                                              heights])))
        frame = np.concatenate([np.full(len(p), k) for k, p in parts])
        points = np.vstack([p for _, p in parts])
        scan = Scan(points=points, colors=np.zeros((len(points), 3), np.uint8),
                    time=np.array(self.times)[frame], heading=headings[frame],
                    frame_index=frame, range_sigma=np.full(len(points), 0.005), index=index,
                    stamp=self.times[0])
        return scan, len(self.times)


def test_live_scans_from_the_scanner_are_mapped_while_queries_are_served():
    """The real Scanner on the simulated firmware, scanning continuously; the mapper maps
    in the background on the monotonic clock; when scanning stops the data go stale."""
    with rig(ScanConfig(continuous=True), FAST) as r:
        r.scanner.new_assembler = RoomAssembler
        mapper = Mapper(reference_scanner(), MapperConfig(max_age=2.0))
        mapper.warm_up()
        with ContinuousScanning(r.scanner, capacity=2) as scanning:
            mapping = mapper.start(scanning)
            assert wait_until(lambda: mapping.mapped >= 3, 60.0)
            answer = mapper.obstacles.nearest(0.0, 0.0)
        assert mapping.join(timeout=10.0) and mapping.error is None
    assert mapper.statuses[0] == "initialised" and "ok" in mapper.statuses[1:]
    assert answer.status in (QueryStatus.OK, QueryStatus.UNKNOWN) and answer.age < 2.0
    assert abs(answer.distance - RoomAssembler.HALF_SIDE) < 0.1  # the nearest wall
    assert wait_until(lambda: mapper.obstacles.nearest(0.0, 0.0).status == QueryStatus.STALE, 5.0)
