"""A simulated motor controller on a real pseudo-terminal, with a DC motor turning the head.

`SimulatedFirmware` opens a pty (os.openpty) and runs, in a thread, the same logic as
firmware/scanmap_motor/scanmap_motor.ino: the line protocol of docs/motor_protocol.md,
the speed ramp (slow start) and the watchdog. Its `port` is the slave path, which
pyserial opens like a USB serial port, so the host code under test is the real one.

The head is driven by the simulator's DC motor (`sim.motor_model.DcMotor`: slow start,
dead band, speed ripple, load wander, braking), the firmware's applied speed in per mille
being the motor's duty. The true head angle is kept as a function of time
(`angle_at(t)`, time.monotonic seconds) so that a simulated camera can render the frame
for the angle at its exposure time.

Faults to inject: garbage bytes, replies split into delayed fragments, silence (the link
wedges while the microcontroller keeps running), disappearance (the pty is closed, as when
the USB cable is pulled), a stall (the head jams), a driver fault, a reset.

`scene_renderer` renders a scene's frames for the firmware's true head motion, so a
`camera.RenderedCamera` on it is a simulated webcam of the live scanner.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..motor import (
    DEVICE_NAME,
    DIRECTIONS,
    MAX_REQUEST,
    PROTOCOL_VERSION,
    SPEED_MAX,
    LineError,
    frame_line,
    parse_line,
)
from .motor_model import STEP, DcMotor, MotorModelConfig, ScanMotion
from .plan import ScanPlan
from .scene import Motion

if TYPE_CHECKING:
    from .render import FrameTruth, Renderer

RAMP_PER_SECOND = 2000  # per mille of speed per second: full speed in 0.5 s (as the sketch)
WATCHDOG_DEFAULT_MS = 1000
WATCHDOG_RANGE_MS = (100, 5000)


class _History:
    """(time, angle) samples of the head, bounded, for interpolation."""

    def __init__(self, capacity: int) -> None:
        self.t = np.zeros(capacity)
        self.angle = np.zeros(capacity)
        self.n = 0

    def add(self, t: float, angle: float) -> None:
        if self.n == self.t.size:
            half = self.t.size // 2
            self.t[:half] = self.t[-half:]
            self.angle[:half] = self.angle[-half:]
            self.n = half
        self.t[self.n] = t
        self.angle[self.n] = angle
        self.n += 1


class SimulatedFirmware:
    """The motor controller's firmware and the head's motor, behind a pseudo-terminal.

    Use as a context manager or call `close()`. `port` is the path to open with pyserial.
    motor: the DC motor's parameters; start_angle: true head angle (rad) at start; seed:
    the motor's load noise; tick: the firmware loop period (s).
    reset_on_open: like an Arduino Uno (reset by DTR), the controller resets when a host
    opens the port and answers nothing for `boot_time` s, then announces `! BOOT`.
    """

    def __init__(self, motor: MotorModelConfig | None = None, *, start_angle: float = 0.0,
                 seed: int = 0, tick: float = 0.003, protocol: int = PROTOCOL_VERSION,
                 device_name: str = DEVICE_NAME, firmware: str = "1.0.0-sim",
                 reset_on_open: bool = True, boot_time: float = 0.3,
                 history_capacity: int = 1 << 16) -> None:
        self.motor = DcMotor(motor or MotorModelConfig(), np.random.default_rng(seed),
                             start_angle)
        self.tick = tick
        self._hello = (f"{device_name} proto={protocol} fw={firmware} drive=dc")
        self._lock = threading.RLock()
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        os.close(slave)  # the host opens it; poll() on the master tells when it does
        self._poll = select.poll()
        self._poll.register(self._master, select.POLLIN | select.POLLHUP)
        self.reset_on_open = reset_on_open
        self.boot_time = boot_time
        self._host_present = False
        self._booting_until = 0.0
        # firmware state (mirrors the sketch)
        self.state = "STOP"
        self.direction = "CCW"
        self.target = 0  # per mille, unsigned
        self.applied = 0.0  # per mille, signed (CCW positive), ramped
        self.faults: list[str] = []
        self.watchdog_ms = WATCHDOG_DEFAULT_MS
        self.requests: list[tuple[float, str]] = []  # (monotonic time, body) received
        self._rx = bytearray()
        self._discarding = False
        self._booted = time.monotonic()
        self._last_request = self._booted
        # the head
        self._now = self._booted
        self._history = _History(history_capacity)
        self._history.add(self._now, start_angle)
        # fault injection
        self.stalled = False
        self.silent = False
        self.fragment_replies = False
        self._pending_garbage = bytearray()
        self._link_open = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="sim-firmware", daemon=True)
        self._thread.start()

    def __enter__(self) -> SimulatedFirmware:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the firmware thread and close the pty."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.disappear()

    # -- the head, for a simulated camera and for tests ---------------------------------
    def angle_at(self, t: float) -> float:
        """True head angle (rad, unwrapped, CCW positive) at monotonic time `t`."""
        with self._lock:
            h = self._history
            if t >= self._now:
                return self.motor.heading + self.motor.speed * min(t - self._now, 0.05)
            return float(np.interp(t, h.t[:h.n], h.angle[:h.n]))

    def heading_profile(self, start: float, end: float) -> tuple[np.ndarray, np.ndarray]:
        """The head's true angle samples (times, angles) from before `start` to `end`
        (monotonic s), for a renderer that needs the motion over an exposure."""
        with self._lock:
            h = self._history
            first = max(int(np.searchsorted(h.t[:h.n], start)) - 1, 0)
            times, angles = h.t[first:h.n].copy(), h.angle[first:h.n].copy()
        if end > times[-1]:
            times = np.append(times, end)
            angles = np.append(angles, self.angle_at(end))
        return times, angles

    @property
    def angle(self) -> float:
        """True head angle now (rad, unwrapped)."""
        return self.angle_at(time.monotonic())

    @property
    def angular_velocity(self) -> float:
        """Head angular speed (rad/s, CCW positive) at the last firmware tick."""
        with self._lock:
            return self.motor.speed

    @property
    def booting(self) -> bool:
        """True while the controller is booting (deaf) after a reset."""
        return bool(self._booting_until)

    @property
    def host_connected(self) -> bool:
        """True while a host has the port open (as far as the firmware noticed)."""
        return self._host_present

    @property
    def driven(self) -> bool:
        """True while the firmware powers the motor to turn."""
        with self._lock:
            return self.state == "RUN" and self.target > 0

    # -- fault injection ---------------------------------------------------------------
    def inject(self, data: bytes) -> None:
        """Send raw bytes to the host before the next reply (line noise, a stray print)."""
        with self._lock:
            self._pending_garbage += data

    def disappear(self) -> None:
        """Close the pty, as when the USB cable is pulled; the motor model keeps running."""
        with self._lock:
            if self._link_open:
                self._link_open = False
                with contextlib.suppress(OSError):
                    os.close(self._master)

    def driver_fault(self) -> None:
        """The driver's fault input goes active: the motor stops and the fault latches."""
        with self._lock:
            self._fault("DRIVER", brake=False)

    def reset(self, boot_time: float = 0.0) -> None:
        """A reset (brown-out, DTR): state cleared, motor stopped, deaf for `boot_time` s,
        then BOOT announced."""
        with self._lock:
            self.state, self.target, self.applied, self.faults = "STOP", 0, 0.0, []
            self.watchdog_ms = WATCHDOG_DEFAULT_MS
            self._rx.clear()
            self._booted = time.monotonic() + boot_time
            if boot_time > 0.0:
                self._booting_until = self._booted
            else:
                self._emit(f"! BOOT {self._hello}")

    # -- firmware ----------------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stop.is_set():
            data = self._read_host() if self._link_open and not self.silent else None
            if data is None:
                time.sleep(self.tick)
                data = b""
            with self._lock:
                now = time.monotonic()
                if self._booting_until:
                    data = b""  # the bootloader swallows what arrives
                    if now >= self._booting_until:
                        self._booting_until = 0.0
                        self._emit(f"! BOOT {self._hello}")
                for byte in data:
                    self._receive(byte)
                self._advance(now)

    def _read_host(self) -> bytes | None:
        """Bytes from the host within one tick; None while no host has the port open."""
        try:
            events = self._poll.poll(self.tick * 1000.0)
        except OSError:
            return None
        if any(ev & select.POLLHUP for _, ev in events):
            self._host_present = False
            return None
        if not self._host_present:
            self._host_present = True
            if self.reset_on_open:
                with self._lock:
                    self.reset(self.boot_time)
        if not events:
            return b""
        try:
            return os.read(self._master, 4096)
        except OSError:
            return None

    def _receive(self, byte: int) -> None:
        if byte == 0x0A:
            if self._discarding:
                self._discarding = False
                self._emit("ERR TOO_LONG line over 63 characters")
            elif self._rx:
                raw = bytes(self._rx)
                self._rx.clear()
                self._line(raw)
            return
        if self._discarding:
            return
        self._rx.append(byte)
        if len(self._rx) > MAX_REQUEST + 1:  # +1: a CR may precede the LF
            self._rx.clear()
            self._discarding = True

    def _line(self, raw: bytes) -> None:
        try:
            line = parse_line(raw, MAX_REQUEST)
        except LineError as exc:
            self._emit(f"ERR {exc}")
            return
        if not line.body:
            return
        self._last_request = time.monotonic()
        self.requests.append((self._last_request, line.body))
        self._emit(self._execute(line.body.split()), line.tag)

    def _execute(self, words: list[str]) -> str:
        name, args = words[0], words[1:]
        expected = {"HELLO": 0, "RUN": 2, "STOP": 0, "BRAKE": 0, "STATUS": 0, "PING": 0,
                    "WATCHDOG": 1, "CLEAR": 0}
        if name not in expected:
            return f"ERR UNKNOWN {name}"
        if len(args) != expected[name]:
            return "ERR ARGS wrong number of arguments"
        uptime = int((time.monotonic() - self._booted) * 1000)
        if name == "HELLO":
            self.state, self.target, self.applied, self.faults = "STOP", 0, 0.0, []
            return f"OK HELLO {self._hello} watchdog={self.watchdog_ms}"
        if name == "RUN":
            if args[0] not in DIRECTIONS or not args[1].isdigit() or int(args[1]) > SPEED_MAX:
                return "ERR ARGS RUN <CCW|CW> <0..1000>"
            if self.faults:
                return f"ERR FAULT {','.join(self.faults)}"
            if self.state != "RUN":
                self.applied = 0.0
            self.state, self.direction, self.target = "RUN", args[0], int(args[1])
            return f"OK RUN dir={self.direction} speed={self.target}"
        if name in ("STOP", "BRAKE"):
            self.state, self.target, self.applied = name, 0, 0.0
            return f"OK {name}"
        if name == "STATUS":
            faults = ",".join(self.faults) or "NONE"
            return (f"OK STATUS state={self.state} dir={self.direction} "
                    f"speed={round(abs(self.applied))} target={self.target} faults={faults} "
                    f"t={uptime}")
        if name == "PING":
            return f"OK PING t={uptime}"
        if name == "WATCHDOG":
            low, high = WATCHDOG_RANGE_MS
            if not args[0].isdigit() or not low <= int(args[0]) <= high:
                return f"ERR ARGS WATCHDOG <{low}..{high}>"
            self.watchdog_ms = int(args[0])
            return f"OK WATCHDOG ms={self.watchdog_ms}"
        self.faults = []
        return "OK CLEAR"

    def _fault(self, name: str, brake: bool) -> None:
        self.state, self.target, self.applied = ("BRAKE" if brake else "STOP"), 0, 0.0
        if name not in self.faults:
            self.faults.append(name)
        self._emit(f"! FAULT {name}")

    def _advance(self, now: float) -> None:
        """Ramp, watchdog and motor physics from the last tick to `now`, in motor steps."""
        steps = int((now - self._now) / STEP)
        if steps <= 0:
            return
        dt = steps * STEP
        self._now += dt
        if self.state == "RUN" and self._now - self._last_request > self.watchdog_ms / 1000.0:
            self._fault("WATCHDOG", brake=True)
        goal = self.target if self.direction == "CCW" else -self.target
        if self.state == "RUN":
            step = RAMP_PER_SECOND * dt
            self.applied += max(-step, min(step, goal - self.applied))
        if self.stalled:
            self.motor.state[1] = 0.0
        else:
            duty = self.applied / SPEED_MAX if self.state == "RUN" else 0.0
            self.motor.advance(duty, dt, brake=self.state == "BRAKE")
        self._history.add(self._now, self.motor.heading)

    def _emit(self, body: str, tag: int | None = None) -> None:
        data = bytes(self._pending_garbage) + frame_line(body, tag)
        self._pending_garbage.clear()
        if self.fragment_replies:
            cut = max(1, len(data) // 3)
            for start in range(0, len(data), cut):
                self._write(data[start:start + cut])
                time.sleep(0.01)
        else:
            self._write(data)

    def _write(self, data: bytes) -> None:
        if not self._link_open or self.silent:
            return
        with contextlib.suppress(OSError):
            os.write(self._master, data)


def scene_renderer(renderer: Renderer, firmware: SimulatedFirmware, pose: np.ndarray,
                   seed: int = 0,
                   truths: list[FrameTruth] | None = None) -> Callable[[float], bytes]:
    """`render(t)` for a `camera.RenderedCamera`: the MJPG frame the simulator renders for
    the head's true motion around time t (the firmware's heading profile over the
    exposure), with the robot standing at `pose` (x, y, yaw) in the scene. Each frame's
    truth is appended to `truths` when given."""
    rng = np.random.default_rng(seed)
    pose = np.asarray(pose, dtype=np.float64)
    margin = renderer.camera.exposure + renderer.camera.rolling_shutter + 0.05

    def render(t: float) -> bytes:
        times, angles = firmware.heading_profile(t - margin, t + margin)
        motion = ScanMotion(times, angles, capture_end=t, end_heading=float(angles[-1]),
                            log=())
        plan = ScanPlan(0, 0.0, motion, np.array([t]), pose, Motion(), pose, pose)
        frame = renderer.render(plan, 0, rng)
        if truths is not None:
            truths.append(frame.truth)
        return frame.jpeg

    return render
