"""The Arduino sketch and the simulated firmware against the same protocol conformance
suite (docs/motor_protocol.md), over a pseudo-terminal.

The sketch firmware/scanmap_motor/scanmap_motor.ino runs in two builds, both driven by
the same tests:

* host: compiled for this machine with g++ and a small stand-in for the Arduino core
  (tests/scanmap_driver/arduino_shim), the fast one;
* avr: built for the board it targets (ATmega328P at 16 MHz, avr-gcc and the Arduino AVR
  core, firmware/build_avr.py) and run in simavr by firmware/simavr/uart_pty_runner.c,
  which bridges UART0 to the pty and keeps simulated time in step with the wall clock.

Each build logs every change of the motor pins on stderr as "t=<ms> <pin>=<value>", so
the tests also check what the H-bridge would see. A missing toolchain fails the tests
(scripts/setup.sh installs it); it never skips them.
"""

from __future__ import annotations

import importlib.util
import os
import re
import select
import shutil
import subprocess
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest
import serial

from scanmap_driver.motor import MotorController
from scanmap_driver.sim.firmware import SimulatedFirmware

from .polling import wait_until
from .serial_terminal import Terminal, xor_checksum

ROOT = Path(__file__).resolve().parents[2]
SKETCH = ROOT / "firmware" / "scanmap_motor" / "scanmap_motor.ino"
SHIM = Path(__file__).resolve().parent / "arduino_shim"
PWM, IN1, IN2 = "A9", "D7", "D8"
STEP, DIR, ENABLE = "D3", "D4", "D5"
Build = Callable[[str], list[str]]  # drive ("dc" or "step") -> the command that runs it


def load_build_avr() -> ModuleType:
    """firmware/build_avr.py (a script, not a package) as a module."""
    spec = importlib.util.spec_from_file_location("build_avr", ROOT / "firmware" / "build_avr.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


BUILD_AVR = load_build_avr()


@pytest.fixture(scope="session")
def host_build(tmp_path_factory) -> Build:
    """The sketch compiled for this machine (once per session and drive)."""
    compiler = shutil.which("g++")
    assert compiler, "no g++ to compile the Arduino sketch for this machine: scripts/setup.sh"
    out = tmp_path_factory.mktemp("firmware_host")

    def command(drive: str) -> list[str]:
        binary = out / f"scanmap_motor_{drive}"
        if not binary.exists():
            subprocess.run([compiler, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-O1",
                            f"-DDRIVE={BUILD_AVR.DRIVES[drive]}", f"-I{SHIM}",
                            "-x", "c++", str(SKETCH), "-x", "none", str(SHIM / "host_main.cpp"),
                            "-o", str(binary)], check=True, capture_output=True, timeout=120)
        return [str(binary)]

    return command


@pytest.fixture(scope="session")
def avr_build(tmp_path_factory) -> Build:
    """The sketch built for an ATmega328P, run in simavr (built once per session)."""
    out = tmp_path_factory.mktemp("firmware_avr")
    runner = BUILD_AVR.build_runner(out)
    return lambda drive: [str(runner), str(BUILD_AVR.build_elf(out, drive))]


@pytest.fixture(params=["host", "avr"])
def build(request) -> Build:
    """Either build of the sketch."""
    return request.getfixturevalue(f"{request.param}_build")


class SketchDevice:
    """A build of the sketch on a pty: `port` for the host, `pins()` for its outputs."""

    def __init__(self, command: list[str]) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self.process = subprocess.Popen(command, stdin=master, stdout=master,
                                        stderr=subprocess.PIPE, text=True)
        os.close(master)
        self._log: list[tuple[int, str, int]] = []
        self._reader = threading.Thread(target=self._read_pins, daemon=True)
        self._reader.start()
        try:
            self._await_boot(slave)
        finally:
            os.close(slave)

    def _await_boot(self, slave: int, timeout: float = 10.0) -> None:
        """Read the BOOT line, so that a host opening the port never starts mid-line (the
        simulated ATmega sends it at 115200 baud, over a few ms)."""
        received, deadline = b"", time.monotonic() + timeout
        while not re.search(rb"! BOOT [^\n]*\n", received):
            left = deadline - time.monotonic()
            assert left > 0 and self.process.poll() is None, f"no BOOT line: {received!r}"
            if select.select([slave], [], [], left)[0]:
                received += os.read(slave, 256)

    def _read_pins(self) -> None:
        for line in self.process.stderr:
            match = re.fullmatch(r"t=(\d+) ([AD]\d+)=(-?\d+)\s*", line)
            if match:
                self._log.append((int(match[1]), match[2], int(match[3])))

    def pins(self) -> dict[str, int]:
        """The present value of every pin written so far."""
        return {pin: value for _, pin, value in list(self._log)}

    def changes(self, pin: str) -> list[tuple[int, int]]:
        """(time in ms, value) of every change of `pin` so far."""
        return [(t, value) for t, name, value in list(self._log) if name == pin]

    def close(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=5.0)


@pytest.fixture(params=["simulated", "host", "avr"])
def device(request):
    """A controller: the simulated firmware or a build of the sketch; `.port` is the path
    a host opens."""
    if request.param == "simulated":
        dev = SimulatedFirmware(reset_on_open=False)
    else:
        dev = SketchDevice(request.getfixturevalue(f"{request.param}_build")("dc"))
    yield dev
    dev.close()


@pytest.fixture
def terminal(device):
    term = Terminal(device.port)
    yield term
    term.close()


# -- conformance: every implementation --------------------------------------------------------

def tagged(body: str) -> bytes:
    return f"{body}*{xor_checksum(body)}".encode()


@pytest.mark.parametrize(("request_line", "reply"), [
    (b"HELLO", re.compile(r"OK HELLO scanmap-motor proto=1 fw=\S+ drive=dc watchdog=1000")),
    (tagged("#7 STATUS"), re.compile(
        r"#7 OK STATUS state=STOP dir=CCW speed=0 target=0 faults=NONE t=\d+")),
    (tagged("#65535 PING"), re.compile(r"#65535 OK PING t=\d+")),
    (b"PING\r", re.compile(r"OK PING t=\d+")),
    (b"RUN CW 250", "OK RUN dir=CW speed=250"),
    (b"#3 BRAKE", "#3 OK BRAKE"),
    (b"STOP", "OK STOP"),
    (b"WATCHDOG 300", "OK WATCHDOG ms=300"),
    (b"CLEAR", "OK CLEAR"),
    (b"FLY", "ERR UNKNOWN FLY"),
    (b"#9 RUN CCW", "#9 ERR ARGS wrong number of arguments"),
    (b"PING now", "ERR ARGS wrong number of arguments"),
    (b"RUN UP 500", "ERR ARGS RUN <CCW|CW> <0..1000>"),
    (b"RUN CCW 1001", "ERR ARGS RUN <CCW|CW> <0..1000>"),
    (b"RUN CCW -5", "ERR ARGS RUN <CCW|CW> <0..1000>"),
    (b"WATCHDOG 50", "ERR ARGS WATCHDOG <100..5000>"),
    (b"PI\xffNG", "ERR BAD_BYTE byte outside printable ASCII"),
    (b"X" * 80, "ERR TOO_LONG line over 63 characters"),
    (b"#5 PING*00", re.compile(r"ERR CHECKSUM .*")),
    (b"#5 PING*", re.compile(r"ERR CHECKSUM .*")),
])
def test_replies_follow_the_protocol(terminal, request_line, reply):
    got = terminal.ask(request_line)
    if isinstance(reply, str):
        assert got == reply
    else:
        assert got is not None and reply.fullmatch(got), got
    assert terminal.ask("PING").startswith("OK PING")  # the link recovers


def test_split_writes_make_one_line(terminal):
    terminal.send(b"PI")
    time.sleep(0.05)
    terminal.send(b"NG\r\n")
    assert terminal.line().startswith("OK PING t=")


def test_speed_ramps_to_the_target(terminal):
    terminal.ask("RUN CCW 1000")
    fields = dict(w.split("=") for w in terminal.ask("STATUS").split()[2:])
    assert fields["state"] == "RUN" and fields["target"] == "1000"
    assert int(fields["speed"]) < 1000  # full speed takes 0.5 s
    time.sleep(0.7)
    terminal.ask("PING")
    fields = dict(w.split("=") for w in terminal.ask("STATUS").split()[2:])
    assert fields["speed"] == "1000" and fields["faults"] == "NONE"


def test_watchdog_brakes_a_silent_host_and_latches_until_clear(terminal):
    assert terminal.ask("WATCHDOG 200") == "OK WATCHDOG ms=200"
    assert terminal.ask("RUN CCW 800").startswith("OK RUN")
    time.sleep(0.6)  # the host says nothing
    status = terminal.ask("STATUS")
    assert "state=BRAKE" in status and "faults=WATCHDOG" in status
    assert "! FAULT WATCHDOG" in terminal.events
    assert terminal.ask("RUN CCW 800") == "ERR FAULT WATCHDOG"
    assert terminal.ask("CLEAR") == "OK CLEAR"
    assert terminal.ask("RUN CCW 800").startswith("OK RUN")
    terminal.ask("WATCHDOG 200")
    time.sleep(0.6)
    assert terminal.ask("HELLO").startswith("OK HELLO")  # HELLO clears faults too
    assert terminal.ask("RUN CCW 800").startswith("OK RUN")


def test_host_client_drives_either_controller(device):
    with MotorController.connect(device.port) as motor:
        assert motor.info.protocol == 1 and motor.info.drive == "dc"
        motor.set_watchdog(400)
        motor.run("CW", 600)
        time.sleep(0.8)  # longer than the watchdog: the heartbeat keeps it alive
        status = motor.status()
        assert (status.state, status.direction, status.speed, status.faults) == \
            ("RUN", "CW", 600, ())
        motor.brake()
        assert motor.status().state == "BRAKE"


def test_host_client_recovers_from_line_noise(device):
    """Noise before the host's first HELLO damages that line; the controller answers it
    without a tag, the client drops that answer, retries, and the session works."""
    with serial.Serial(device.port, 115200) as noisy:
        noisy.write(b"\x00\xfe\x13#2 RU")  # no LF: glued to the client's first HELLO
    with MotorController.connect(device.port) as motor:
        assert motor.info.protocol == 1
        motor.run("CCW", 300)
        assert motor.status().target == 300


def test_uptime_keeps_pace_with_the_wall_clock(terminal):
    """`t` is the uptime in ms (protocol): the simulated ATmega must run in real time, or
    the watchdog would not mean what the host's heartbeat assumes."""
    first, since = int(terminal.ask("PING").split("t=")[1]), time.monotonic()
    time.sleep(0.5)
    second, wall = int(terminal.ask("PING").split("t=")[1]), time.monotonic() - since
    assert abs((second - first) - 1000 * wall) <= 0.1 * 1000 * wall + 20

# -- what the sketch puts on its pins ---------------------------------------------------------

@pytest.fixture
def sketch(build):
    dev = SketchDevice(build("dc"))
    yield dev
    dev.close()


def test_sketch_drives_the_h_bridge(sketch):
    with MotorController.connect(sketch.port) as motor:
        assert wait_until(lambda: sketch.pins().get(PWM) == 0)
        motor.run("CCW", 500)
        assert wait_until(lambda: sketch.pins().get(PWM) == 127)  # 500 per mille of 255
        assert sketch.pins()[IN1] == 1 and sketch.pins()[IN2] == 0
        motor.run("CW", 500)  # ramps through zero to the other direction
        assert wait_until(lambda: sketch.pins()[IN1] == 0 and sketch.pins()[IN2] == 1)
        assert wait_until(lambda: sketch.pins().get(PWM) == 127)
        motor.brake()  # short brake: both inputs high, enable on
        # the three pins change one after another: wait for all of them, or a poll
        # between the writes sees the inputs braked and the enable not yet raised
        assert wait_until(lambda: (sketch.pins()[IN1], sketch.pins()[IN2],
                                   sketch.pins().get(PWM)) == (1, 1, 255))
        motor.stop()  # coast: all off
        assert wait_until(lambda: (sketch.pins()[IN1], sketch.pins()[IN2],
                                   sketch.pins()[PWM]) == (0, 0, 0))


def test_sketch_ramp_takes_half_a_second_to_full_speed(sketch):
    with MotorController.connect(sketch.port) as motor:
        motor.run("CCW", 1000)
        assert wait_until(lambda: sketch.pins().get(PWM) == 255, 2.0)
    changes = [(t, v) for t, v in sketch.changes(PWM) if v > 0]
    rise = changes[-1][0] - changes[0][0]
    assert 0.4 * 1000 <= rise <= 0.7 * 1000


def test_sketch_brakes_by_itself_when_the_host_vanishes(sketch):
    motor = MotorController.connect(sketch.port, heartbeat=None)
    motor.set_watchdog(200)
    motor.run("CCW", 800)
    assert wait_until(lambda: sketch.pins().get(PWM, 0) > 100)
    motor._link.close()  # the host process is gone without a word
    assert wait_until(lambda: (sketch.pins()[IN1], sketch.pins()[IN2]) == (1, 1), 1.0)


def test_step_dir_build_enables_the_driver_only_while_turning(build):
    dev = SketchDevice(build("step"))
    try:
        with MotorController.connect(dev.port) as motor:
            assert motor.info.drive == "step"
            assert wait_until(lambda: dev.pins().get(ENABLE) == 1)  # disabled at rest
            motor.run("CW", 500)
            assert wait_until(lambda: dev.pins().get(ENABLE) == 0 and dev.pins().get(DIR) == 0)
            assert wait_until(lambda: sum(v == 1 for _, v in dev.changes(STEP)) >= 10)  # pulses
            motor.stop()
            assert wait_until(lambda: dev.pins().get(ENABLE) == 1)
    finally:
        dev.close()


@pytest.mark.parametrize("drive", ["dc", "step"])
def test_avr_build_fits_the_atmega328p(avr_build, drive):
    """Flash: 32 KiB less the Uno's 512-byte bootloader; static RAM: at most 75 % of the
    2 KiB (the Arduino IDE's low-memory warning), leaving the rest to the stack."""
    elf = avr_build(drive)[1]
    sizes = {name: int(size) for name, size, *_ in (
        line.split() for line in subprocess.run(["avr-size", "-A", elf], check=True,
                                                capture_output=True, text=True).stdout
        .splitlines()[2:] if line.strip())}
    assert sizes[".text"] + sizes[".data"] <= 32 * 1024 - 512
    assert sizes[".data"] + sizes[".bss"] <= 0.75 * 2048


def test_avr_step_rate_follows_the_speed(avr_build):
    """Full speed is MAX_STEP_RATE, 3200 steps/s (firmware/README.md), on the simulated
    16 MHz clock: pin times are simulated, so this holds on a loaded machine too. (Only on
    the ATmega: the host build's loop sleeps 0.2 ms, too coarse for a 312 µs interval.)"""
    dev = SketchDevice(avr_build("step"))
    try:
        with MotorController.connect(dev.port) as motor:
            motor.run("CCW", 1000)
            # Simulated time runs slower than the wall clock on a loaded machine: wait long.
            assert wait_until(lambda: len(dev.changes(STEP)) > 2 * 3200 * 0.9, timeout=30)
    finally:
        dev.close()
    rises = [t for t, value in dev.changes(STEP) if value == 1]
    start = rises[0] + 600  # past the ramp (0.5 s to full speed)
    steps = sum(start <= t < start + 200 for t in rises)
    assert 0.98 * 640 <= steps <= 1.02 * 640
