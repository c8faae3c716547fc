"""Faults mid-scan on the simulated rig (tests/scanmap_driver/sim_rig.py): the encoder disk
unreadable for over a second, the camera gone, the serial line dropped, the controller
resetting. Each: the motor is told to stop first, the frames taken up to the fault are
kept and readable from a recording, and the error says what happened and when.

Truth: the simulated firmware's requests and state, the motor model's head speed, and
the moment each fault was injected (monotonic clock)."""

from __future__ import annotations

import math
import re
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from scanmap_driver import reference_scanner
from scanmap_driver.errors import DeviceError
from scanmap_driver.live_recording import write_scan
from scanmap_driver.recording import Recording, RecordingWriter
from scanmap_driver.scanner import ScanConfig, ScanFailed
from scanmap_driver.sim.motor_model import MotorModelConfig

from .polling import wait_until
from .sim_rig import WallAssembler, rig

FAST = MotorModelConfig(full_speed=2.0 * math.pi * 1.6)
FAULT_AT = 0.6  # s after the scan starts
BLACKOUT = 1.3  # s the encoder disk stays unreadable


class BlackoutAssembler(WallAssembler):
    """The rig's assembler, blind to the encoder disk from FAULT_AT for BLACKOUT seconds."""

    start: float = math.nan

    def add_frame(self, image: np.ndarray, timestamp: float) -> float | None:
        if FAULT_AT <= timestamp - self.start < FAULT_AT + BLACKOUT:
            return None
        return super().add_frame(image, timestamp)


def encoder_blackout(r) -> None:
    BlackoutAssembler.start = time.monotonic()
    r.scanner.new_assembler = BlackoutAssembler


def camera_unplugged(r) -> None:
    original = r.camera.read

    def read():
        if time.monotonic() >= unplugged_at:
            raise DeviceError("camera /dev/video0: no frame (unplugged)")
        return original()

    unplugged_at = time.monotonic() + FAULT_AT
    r.camera.read = read


def serial_dropped(r) -> None:
    threading.Timer(FAULT_AT, r.firmware.disappear).start()


def controller_reset(r) -> None:
    threading.Timer(FAULT_AT, r.firmware.reset).start()


FAULTS = {  # injection, ScanFailed.reason, what the message must say, delay allowed (s)
    "encoder": (encoder_blackout, "stall", "no heading decoded in 1.0 s", 1.0 + 0.5),
    "camera": (camera_unplugged, "camera", "no frame (unplugged)", 0.5),
    "serial": (serial_dropped, "motor", "vanished", 0.5),
    "reset": (controller_reset, "motor", "controller reset (it announced BOOT)", 0.5),
}


@pytest.mark.parametrize("fault", FAULTS)
def test_fault_mid_scan_stops_the_motor_first_and_keeps_a_readable_recording(fault, tmp_path):
    inject, reason, says, delay = FAULTS[fault]
    with rig(ScanConfig(keep_frames=True), FAST) as r:
        started = time.monotonic()
        inject(r)
        with pytest.raises(ScanFailed) as err:
            r.scanner.scan()
        caught = time.monotonic()
        failed = err.value
        assert failed.reason == reason and says in str(failed)

        if fault == "serial":  # nothing reaches the controller: its watchdog brakes
            assert "braking failed too" in str(failed)
            assert wait_until(lambda: "WATCHDOG" in r.firmware.faults, 2.0)
        else:  # the host's BRAKE came before the error reached the caller
            assert "motor braked" in str(failed)
            brakes = [t for t, body in r.firmware.requests if body == "BRAKE"]
            assert brakes and started + FAULT_AT <= brakes[0] <= caught
        assert wait_until(lambda: abs(r.firmware.angular_velocity) < 1e-3, 2.0)
        assert not r.firmware.driven

        at = float(re.search(r"at (\d+\.\d+) s into the scan", str(failed)).group(1))
        assert FAULT_AT <= at <= FAULT_AT + delay
        assert at <= caught - started + 0.005  # the message rounds it to 0.01 s

        result = failed.result
        assert result.fault == reason and len(result.frames) == len(result.frame_times) >= 10
        assert result.frame_times[-1] <= caught

        model = reference_scanner()
        model = model.with_changes(camera=replace(model.camera, width=4, height=2,
                                                  cx=2.0, cy=1.0))
        writer = RecordingWriter(tmp_path / "rec", model, "fault test")
        write_scan(writer, result, origin=started)
    recording = Recording.open(tmp_path / "rec")
    record = recording.scans[0]
    assert not record.complete
    assert np.allclose(record.frame_times, result.frame_times - started)
    assert len(list(recording.frames(0))) == len(result.frames)
