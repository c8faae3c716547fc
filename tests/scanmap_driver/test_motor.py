"""The motor controller client, over a real pseudo-terminal to the simulated firmware.

Truth is the firmware's own state and the head's true motion; every fault the link can
suffer (garbage, fragments, stale replies, silence, disappearance) is injected on the
device side, so pyserial and the client see what a USB serial port would give them.
"""

from __future__ import annotations

import functools
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scanmap_driver.errors import DeviceError
from scanmap_driver.motor import (
    MAX_REQUEST,
    LineError,
    MotorController,
    checksum,
    frame_line,
    parse_line,
)
from scanmap_driver.sim.firmware import SimulatedFirmware

from .polling import wait_until


@pytest.fixture
def firmware():
    with SimulatedFirmware() as fw:
        yield fw


@pytest.fixture
def motor(firmware):
    with MotorController.connect(firmware.port) as m:
        yield m


# -- framing -------------------------------------------------------------------------------

bodies = st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E,
                               blacklist_characters="*#"), min_size=1, max_size=40)


def test_checksum_is_the_xor_of_the_bytes():
    assert checksum("#1 HELLO") == f"{functools.reduce(int.__xor__, b'#1 HELLO'):02X}"
    assert frame_line("PING") == b"PING*" + checksum("PING").encode() + b"\n"


@given(body=bodies, tag=st.one_of(st.none(), st.integers(0, 65535)))
def test_frame_and_parse_round_trip(body, tag):
    line = parse_line(frame_line(body, tag)[:-1])
    assert (line.tag, line.body, line.checked) == (tag, body.strip(), True)


@given(body=bodies, position=st.integers(0, 200), byte=st.integers(0x20, 0x7E))
def test_any_single_changed_byte_is_caught(body, position, byte):
    raw = bytearray(frame_line(body, 7)[:-1])
    position %= len(raw)
    if raw[position] == byte or raw[position] == ord("*") or byte == ord("*"):
        return
    raw[position] = byte
    try:
        line = parse_line(bytes(raw))
    except LineError:
        return
    pytest.fail(f"damaged line {bytes(raw)!r} parsed as {line}")


def test_unchecked_lines_parse_for_people_at_a_serial_monitor():
    assert parse_line(b"RUN CCW 600\r") == parse_line(b"RUN CCW 600")
    assert not parse_line(b"RUN CCW 600").checked
    with pytest.raises(LineError, match="TOO_LONG"):
        parse_line(b"X" * (MAX_REQUEST + 1), MAX_REQUEST)


# -- handshake -----------------------------------------------------------------------------

def test_handshake_reports_the_firmware(motor):
    assert motor.info.protocol == 1 and motor.info.drive == "dc"
    assert motor.info.firmware == "1.0.0-sim" and motor.info.watchdog_ms == 1000


def test_protocol_mismatch_is_refused_with_both_versions():
    with SimulatedFirmware(protocol=2) as fw, pytest.raises(DeviceError) as err:
        MotorController.connect(fw.port)
    assert "protocol 2" in str(err.value) and "speaks 1" in str(err.value)


def test_another_device_is_not_taken_for_a_controller():
    with SimulatedFirmware(device_name="gps-logger") as fw, \
            pytest.raises(DeviceError, match="not a scanmap motor controller"):
        MotorController.connect(fw.port)


def test_silent_device_times_out_clearly():
    with SimulatedFirmware() as fw:
        fw.silent = True
        start = time.monotonic()
        with pytest.raises(DeviceError, match="no scanmap motor controller answered HELLO"):
            MotorController.connect(fw.port, connect_timeout=1.0)
        assert time.monotonic() - start < 3.0


def test_missing_port_is_a_device_error(tmp_path):
    with pytest.raises(DeviceError, match="cannot open"):
        MotorController.connect(str(tmp_path / "ttyUSB9"))


# -- commands ------------------------------------------------------------------------------

def test_run_status_brake_stop_drive_the_head(motor, firmware):
    a0 = firmware.angle
    motor.run("CCW", 800)
    assert wait_until(lambda: firmware.angle > a0 + 1.0)
    status = motor.status()
    assert (status.state, status.direction, status.target, status.faults) == \
        ("RUN", "CCW", 800, ())
    assert status.driven and status.speed == 800
    motor.run("CW", 800)
    assert wait_until(lambda: firmware.angular_velocity < -1.0)
    motor.brake()
    assert firmware.state == "BRAKE" and not motor.status().driven
    assert wait_until(lambda: abs(firmware.angular_velocity) < 1e-3, 1.0)
    motor.stop()
    assert firmware.state == "STOP"


def test_bad_arguments_are_refused_before_sending(motor, firmware):
    for args in [("UP", 100), ("CCW", 1001), ("CCW", -1), ("CCW", 5.5)]:
        with pytest.raises(ValueError):
            motor.run(*args)
    with pytest.raises(ValueError):
        motor.set_watchdog(50)
    assert not any("RUN" in body for _, body in firmware.requests)


def test_heartbeat_keeps_a_running_motor_alive_past_the_watchdog(motor, firmware):
    motor.set_watchdog(300)
    motor.run("CCW", 800)
    time.sleep(1.2)  # the application says nothing; the heartbeat does
    assert firmware.state == "RUN" and firmware.faults == []
    assert any(body == "PING" for _, body in firmware.requests)


def test_without_heartbeat_the_watchdog_stops_the_motor_and_refuses_run(firmware):
    with MotorController.connect(firmware.port, heartbeat=None) as motor:
        motor.set_watchdog(200)
        motor.run("CCW", 800)
        assert wait_until(lambda: firmware.state == "BRAKE", 1.5)
        status = motor.status()
        assert status.state == "BRAKE" and status.faults == ("WATCHDOG",)
        assert "! FAULT WATCHDOG" in motor.events and motor.faults_seen == ["WATCHDOG"]
        with pytest.raises(DeviceError, match="refused RUN: FAULT WATCHDOG"):
            motor.run("CCW", 800)
        motor.clear_faults()
        motor.run("CCW", 800)
        assert firmware.state == "RUN"


def test_close_brakes_the_motor(firmware):
    motor = MotorController.connect(firmware.port)
    motor.run("CCW", 800)
    motor.close()
    assert firmware.state == "BRAKE"
    motor.close()  # twice is harmless


# -- a noisy or failing link ---------------------------------------------------------------

@settings(max_examples=15, deadline=None)
@given(noise=st.binary(min_size=1, max_size=200))
def test_garbage_bytes_before_a_reply_do_not_confuse_the_client(noise):
    with SimulatedFirmware(reset_on_open=False) as fw, \
            MotorController.connect(fw.port, heartbeat=None, timeout=0.2) as motor:
        fw.inject(noise + b"\n")
        motor.run("CCW", 300)
        fw.inject(noise)  # no LF: glued to the front of the next reply
        assert motor.status().target == 300


def test_fragmented_replies_are_reassembled(motor, firmware):
    firmware.fragment_replies = True
    assert motor.status().state == "STOP"
    assert motor.ping() >= 0


def test_stale_and_foreign_replies_are_skipped(motor, firmware):
    firmware.inject(frame_line("OK STATUS state=RUN dir=CW speed=9 target=9 faults=NONE t=1",
                               tag=60000))
    firmware.inject(b"OK STATUS state=RUN without checksum\n")
    assert motor.status().state == "STOP"
    assert motor.garbage_lines >= 1


def test_a_silent_device_gives_a_clear_timeout_and_the_watchdog_stops_the_motor(motor, firmware):
    motor.set_watchdog(200)
    motor.run("CCW", 800)
    firmware.silent = True
    start = time.monotonic()
    with pytest.raises(DeviceError, match=r"did not answer STATUS within 0\.50 s \(2 tries\); "
                                          r"a brake was sent"):
        motor.status()
    assert time.monotonic() - start < 3.0
    assert wait_until(lambda: firmware.state == "BRAKE", 1.0)
    assert "WATCHDOG" in firmware.faults


def test_a_vanished_device_is_reported_and_stopped_by_its_watchdog(motor, firmware):
    motor.set_watchdog(200)
    motor.run("CCW", 800)
    firmware.disappear()
    with pytest.raises(DeviceError, match="vanished"):
        for _ in range(10):
            motor.status()
            time.sleep(0.05)
    assert motor.failure is not None
    with pytest.raises(DeviceError, match="vanished"):
        motor.brake()
    assert motor.stop_safely() is not None
    assert wait_until(lambda: firmware.state == "BRAKE", 1.0)
    assert wait_until(lambda: abs(firmware.angular_velocity) < 0.01, 1.0)
    motor.close()  # does not hang on the dead port


def test_driver_fault_event_is_recorded_and_run_refused(motor, firmware):
    motor.run("CCW", 500)
    firmware.driver_fault()
    assert motor.status().faults == ("DRIVER",)
    assert "! FAULT DRIVER" in motor.events
    with pytest.raises(DeviceError, match="FAULT DRIVER"):
        motor.run("CCW", 500)
    assert not firmware.driven
