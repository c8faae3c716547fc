"""The scanning loop against the simulated firmware on a pseudo-terminal and a camera that
renders the head's true angle (tests/scanmap_driver/sim_rig.py), and its recordings.

Truth is the motor model's own head angle over time. Each fault has a test showing the
motor stopped (the firmware's state, and the head's true speed), the partial data kept,
and an error that says what happened.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from scanmap_driver import reference_scanner
from scanmap_driver.camera import RenderedCamera
from scanmap_driver.continuous_scanning import ContinuousScanning
from scanmap_driver.errors import DeviceError
from scanmap_driver.heading_tracker import HeadingTracker
from scanmap_driver.live_recording import write_scan
from scanmap_driver.recording import Recording, RecordingWriter, read_avi_frames
from scanmap_driver.scan import Scan
from scanmap_driver.scanner import ScanConfig, ScanFailed, ScanResult
from scanmap_driver.sim.motor_model import MotorModelConfig

from .polling import wait_until
from .sim_rig import WALL_HEIGHTS, WALL_RADIUS, rig

FAST = MotorModelConfig(full_speed=2.0 * math.pi * 1.6)  # about 0.9 s per revolution
TURN = 2.0 * math.pi + math.radians(10.0)


def wrapped(a):
    return (np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi


def later(delay: float, action) -> threading.Timer:
    timer = threading.Timer(delay, action)
    timer.start()
    return timer


def brake_time(firmware) -> float:
    return next(t for t, body in firmware.requests if body == "BRAKE")


def assert_motor_stopped(firmware, caught: float) -> None:
    """Braked by the host before the error reached the caller, and the head at rest."""
    assert firmware.state == "BRAKE" and not firmware.driven
    assert brake_time(firmware) <= caught
    assert wait_until(lambda: abs(firmware.angular_velocity) < 1e-3, 1.0)


def assert_partial_data(result, fault: str) -> None:
    assert result.fault == fault
    assert len(result.frame_times) >= 5 and len(result.scan) > 0
    assert len(result.scan) == WALL_HEIGHTS.size * np.isfinite(result.headings).sum()
    assert 0.0 < result.coverage < TURN


# -- one scan --------------------------------------------------------------------------------

def test_one_scan_covers_a_turn_with_true_headings_and_returns_the_head():
    progress = []
    with rig(start_angle=0.3, on_progress=progress.append) as r:
        result = r.scanner.scan()
        fw = r.firmware
        truth = np.array([fw.angle_at(t) for t in result.frame_times])
        # the sweep: a full turn plus the overlap by the headings, and by the truth
        assert TURN <= result.coverage < TURN + math.radians(25)
        assert TURN <= truth[-1] - truth[0] < TURN + math.radians(25)
        assert np.abs(wrapped(result.headings - truth)).max() < 1e-3
        # the points: one wall column per frame, at that frame's true heading and time
        scan = result.scan
        assert len(scan) == WALL_HEIGHTS.size * len(result.frame_times)
        point_truth = np.array([fw.angle_at(t) for t in scan.time])
        assert np.abs(wrapped(np.arctan2(scan.points[:, 1], scan.points[:, 0])
                              - point_truth)).max() < 1e-3
        assert np.allclose(np.hypot(scan.points[:, 0], scan.points[:, 1]), WALL_RADIUS)
        assert result.fault is None and result.overflow_frames == 0
        log = result.motor_log
        assert log[0]["command"] == "status" and log[0]["state"] == "STOP"
        assert {"command": "run", "duty": 0.72} == {k: log[1][k] for k in ("command", "duty")}
        assert any(e["command"] == "status" and e["state"] == "RUN" and e["target"] == 720
                   for e in log)
        # the return: braked and back at the start (reciprocating motion)
        assert wait_until(lambda: abs(fw.angular_velocity) < 1e-3, 2.0)
        assert fw.state == "BRAKE"
        assert abs(wrapped(fw.angle - 0.3)) < math.radians(4.0)
        assert {"RUN CCW 720", "RUN CW 800"} <= {body for _, body in fw.requests}
    sweep = [p.coverage for p in progress if p.phase == "sweep"]
    assert np.all(np.diff(sweep) >= -1e-9) and sweep[-1] == pytest.approx(result.coverage)
    assert any(p.phase == "return" for p in progress)


def test_continuous_clockwise_scan_leaves_the_head_where_the_sweep_ended():
    settings = ScanConfig(direction="CW", continuous=True)
    with rig(settings, FAST, start_angle=1.0) as r:
        result = r.scanner.scan()
        truth = np.array([r.firmware.angle_at(t) for t in result.frame_times])
        assert TURN <= result.coverage and TURN <= truth[0] - truth[-1]
        assert wait_until(lambda: abs(r.firmware.angular_velocity) < 1e-3, 2.0)
        assert r.firmware.angle < 1.0 - TURN  # not returned
        assert not any(body.startswith("RUN CCW") for _, body in r.firmware.requests)


def test_frames_are_kept_for_a_recording_when_asked():
    with rig(ScanConfig(keep_frames=True, continuous=True), FAST) as r:
        result = r.scanner.scan()
        assert [f.timestamp for f in result.frames] == list(result.frame_times)
        assert np.all(np.diff([f.index for f in result.frames]) >= 1)


# -- faults ----------------------------------------------------------------------------------

def test_stall_stops_the_motor_and_keeps_the_partial_scan():
    with rig(None, FAST) as r:
        later(0.6, lambda: setattr(r.firmware, "stalled", True))
        with pytest.raises(ScanFailed) as err:
            r.scanner.scan()
        caught = time.monotonic()
        assert err.value.reason == "stall"
        assert "stall: the heading advanced only" in str(err.value)
        assert "motor braked" in str(err.value)
        assert_motor_stopped(r.firmware, caught)
        assert_partial_data(err.value.result, "stall")
        assert r.scanner.last_result is err.value.result


class FreezingCamera(RenderedCamera):
    """A webcam that stops delivering after 20 frames (its read blocks until closed)."""

    def read(self):
        if self._delivered >= 20:
            self._closed.wait(30.0)
            raise DeviceError("closed")
        return super().read()


class UnpluggedCamera(RenderedCamera):
    """A webcam whose driver reports an error after 20 frames."""

    def read(self):
        if self._delivered >= 20:
            raise DeviceError("camera /dev/video0: no frame (unplugged)")
        return super().read()


@pytest.mark.parametrize(("camera_type", "message"), [
    (FreezingCamera, "the camera delivered no frame for 1.0 s"),
    (UnpluggedCamera, "camera failed: camera /dev/video0: no frame (unplugged)"),
])
def test_camera_that_stops_delivering_stops_the_motor(camera_type, message):
    with rig(None, FAST, camera_type=camera_type) as r:
        with pytest.raises(ScanFailed) as err:
            r.scanner.scan()
        caught = time.monotonic()
        assert err.value.reason == "camera" and message in str(err.value)
        assert_motor_stopped(r.firmware, caught)
        assert_partial_data(err.value.result, "camera")
        assert 15 <= len(err.value.result.frame_times) <= 20  # all the scan had


def test_vanished_serial_port_is_reported_and_the_watchdog_stops_the_motor():
    with rig(None, FAST) as r:
        later(0.6, r.firmware.disappear)
        with pytest.raises(ScanFailed) as err:
            r.scanner.scan()
        text = str(err.value)
        assert err.value.reason == "motor" and "vanished" in text
        assert "braking failed too" in text
        assert wait_until(lambda: r.firmware.state == "BRAKE", 2.0)
        assert "WATCHDOG" in r.firmware.faults
        assert wait_until(lambda: abs(r.firmware.angular_velocity) < 1e-3, 1.0)
        assert_partial_data(err.value.result, "motor")


def test_controller_fault_mid_scan_stops_the_scan():
    with rig(None, FAST) as r:
        later(0.6, r.firmware.driver_fault)
        with pytest.raises(ScanFailed, match=r"reports fault\(s\) DRIVER") as err:
            r.scanner.scan()
        assert err.value.reason == "motor" and not r.firmware.driven
        assert_partial_data(err.value.result, "motor")


def test_scan_over_its_time_limit_is_stopped():
    with rig(ScanConfig(time_limit=0.5), FAST) as r:
        with pytest.raises(ScanFailed, match=r"exceeded its 0\.5 s time limit") as err:
            r.scanner.scan()
        caught = time.monotonic()
        assert err.value.reason == "time_limit"
        assert_motor_stopped(r.firmware, caught)
        assert_partial_data(err.value.result, "time_limit")


def test_ctrl_c_stops_the_motor_and_keeps_the_data():
    # Ctrl-C once the sweep is a third of a turn along: KeyboardInterrupt raised there, in
    # the scanning thread, as Python's SIGINT handler raises it (a timer thread's
    # _thread.interrupt_main got lost in the whole test suite, not alone)
    def press_mid_sweep(progress) -> None:
        if progress.phase == "sweep" and progress.coverage > 2.0:
            raise KeyboardInterrupt

    with rig(None, FAST, on_progress=press_mid_sweep) as r:
        with pytest.raises(KeyboardInterrupt):
            r.scanner.scan()
        caught = time.monotonic()
        assert_motor_stopped(r.firmware, caught)
        assert_partial_data(r.scanner.last_result, "interrupted")


def test_unreadable_encoder_never_starts_the_motor():
    with rig(ScanConfig(stall_time=0.4), FAST) as r:
        r.scanner.new_assembler = None
        r.scanner.decode_heading = lambda frame: None
        with pytest.raises(ScanFailed, match=r"no heading decoded in 0\.4 s before the motor"):
            r.scanner.scan()
        assert not any(body.startswith("RUN") for _, body in r.firmware.requests)


# -- continuous scanning -----------------------------------------------------------------------

def test_continuous_scanning_drops_the_oldest_scans_for_a_slow_consumer():
    with rig(ScanConfig(continuous=True), FAST) as r:
        with ContinuousScanning(r.scanner, capacity=1) as scanning:
            assert wait_until(lambda: scanning.scans_taken >= 3, 20.0)
            latest = scanning.get(timeout=5.0)
            assert scanning.dropped_scans >= 2
            assert latest.scan.index >= 2 and latest.fault is None  # the newest was kept
            assert latest.overflow_frames == 0  # the loop kept up with the camera
            following = scanning.get(timeout=5.0)
            # back to back: the next scan starts with the next frames of the camera
            gap = following.frame_times[0] - latest.frame_times[-1]
            assert 0 < gap < 3.0 / r.camera.frame_rate
            assert following.scan.index == latest.scan.index + 1
        assert r.firmware.state == "BRAKE"


def test_continuous_scanning_hands_the_fault_to_the_consumer():
    with rig(ScanConfig(continuous=True), FAST) as r:
        scanning = ContinuousScanning(r.scanner, capacity=4)
        scanning.start()
        first = scanning.get(timeout=10.0)
        assert first is not None and first.fault is None
        r.firmware.stalled = True
        with pytest.raises(ScanFailed) as err:
            while scanning.get(timeout=10.0) is not None:
                pass
        assert err.value.reason == "stall"
        assert r.firmware.state == "BRAKE" and not r.firmware.driven
        scanning.stop()


def test_stopping_continuous_scanning_brakes_at_once_and_keeps_the_partial_scan():
    with rig(ScanConfig(continuous=True), FAST) as r:
        scanning = ContinuousScanning(r.scanner)
        scanning.start()
        assert wait_until(lambda: r.firmware.driven, 5.0)
        time.sleep(0.3)
        start = time.monotonic()
        scanning.stop()  # what Ctrl-C does in `scanmap scan --continuous`
        assert time.monotonic() - start < 1.0
        assert r.firmware.state == "BRAKE" and brake_time(r.firmware) < start + 0.5
        assert r.scanner.last_result.fault == "cancelled" and len(r.scanner.last_result.scan)
        assert scanning.get(timeout=0.1) is None  # a cancel is not an error


# -- heading tracking --------------------------------------------------------------------------

def test_tracker_unwraps_through_gaps_and_skips_a_lone_outlier():
    tracker = HeadingTracker(sign=1.0)
    speed = 3.0  # rad/s
    times = np.arange(0, 2.5, 0.04)
    keep = np.ones(times.size, bool)
    keep[20:27] = False  # 7 undecoded frames: 0.84 rad unseen
    for t in times[keep]:
        assert tracker.update(t, (0.5 + speed * t) % (2 * math.pi))
    assert tracker.progress == pytest.approx(speed * times[-1], abs=1e-9)
    assert not tracker.update(times[-1] + 0.04, 0.5 + speed * times[-1] + math.pi)
    assert tracker.outliers == 1
    assert tracker.update(times[-1] + 0.08, (0.5 + speed * (times[-1] + 0.08)) % (2 * math.pi))
    assert tracker.progress == pytest.approx(speed * (times[-1] + 0.08), abs=1e-9)


def test_tracker_accepts_a_real_jump_after_three_agreeing_headings():
    tracker = HeadingTracker(sign=-1.0)
    for k in range(5):
        tracker.update(k * 0.04, -0.1 * k)
    results = [tracker.update(0.2 + k * 0.04, 2.0 - 0.1 * k) for k in range(3)]
    assert results == [False, False, True]
    assert wrapped(tracker.heading_now() - 1.8) == pytest.approx(0.0, abs=1e-12)


# -- recording ----------------------------------------------------------------------

def recorded_result(fault=None, frames=6):
    """A ScanResult as the loop makes it, with full-size MJPG frames of a rendered camera."""
    camera = RenderedCamera(lambda t: np.full((480, 640, 3), int(t * 500) % 256, np.uint8),
                            frame_rate=100.0, jpeg_quality=90)
    taken = [camera.read() for _ in range(frames)]
    t0 = taken[0].timestamp
    log = [{"t": t0 - 0.01, "command": "status", "state": "STOP", "faults": []},
           {"t": t0 - 0.005, "command": "run", "duty": 0.72},
           {"t": taken[-1].timestamp + 0.001, "command": "brake", "duty": 0.0}]
    return ScanResult(scan=Scan.empty(index=0, stamp=t0), frames=taken,
                      frame_times=np.array([f.timestamp for f in taken]),
                      headings=np.zeros(frames), motor_log=log, fault=fault)


def test_write_scan_keeps_the_cameras_jpegs_times_and_motor_log(tmp_path):
    result = recorded_result()
    origin = result.frame_times[0] - 1.0
    writer = RecordingWriter(tmp_path / "rec", reference_scanner(), source="camera")
    write_scan(writer, result, origin)
    write_scan(writer, recorded_result(fault="stall"), origin)
    recording = Recording.open(tmp_path / "rec")
    first, second = recording.scans
    assert list(read_avi_frames(first.video)) == [f.raw_jpeg for f in result.frames]
    assert np.allclose(first.frame_times, result.frame_times - origin)
    assert first.stamp == pytest.approx(result.motor_log[1]["t"] - origin)
    assert [e["command"] for e in first.motor_log] == ["status", "run", "brake"]
    assert first.motor_log[1]["duty"] == 0.72 and first.motor_log[0]["state"] == "STOP"
    assert first.complete and not second.complete
