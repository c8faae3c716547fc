"""The serial motor controller: a pyserial client of the protocol in docs/motor_protocol.md.

The controller (firmware/scanmap_motor, or the simulated firmware on a pseudo-terminal)
turns the scanner head; the camera, not the controller, measures the heading. This client
does the version handshake, sends speed/direction/stop/brake, reads status and faults,
and keeps the firmware's watchdog fed from a heartbeat thread, so the motor stops on its
own when this process goes silent.

Every failure of the link becomes a `DeviceError` that says what happened: no answer
within the timeout (after trying to stop the motor), a device that vanished, a refusal.
Damaged lines (garbage bytes, bad checksums, late answers) are dropped and counted.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import serial

from .errors import DeviceError

log = logging.getLogger(__name__)

try:  # a POSIX port that vanishes can fail in termios (tcdrain, tcflush), not in OSError
    from termios import error as _TermiosError
except ImportError:  # Windows
    _TermiosError = OSError
LINK_ERRORS = (serial.SerialException, OSError, _TermiosError)

PROTOCOL_VERSION = 1
DEVICE_NAME = "scanmap-motor"
MAX_REQUEST = 63  # characters before LF: the firmware's receive buffer
MAX_REPLY = 127
MAX_ID = 65535
DIRECTIONS = ("CCW", "CW")
SPEED_MAX = 1000


# -- line framing (shared with the simulated firmware) -------------------------------------

def checksum(text: str) -> str:
    """Two hex digits: XOR of the bytes of `text`."""
    value = 0
    for byte in text.encode("ascii"):
        value ^= byte
    return f"{value:02X}"


def frame_line(body: str, tag: int | None = None) -> bytes:
    """The wire form of a line: optional `#tag ` prefix, body, `*checksum`, LF."""
    text = body if tag is None else f"#{tag} {body}"
    return f"{text}*{checksum(text)}\n".encode("ascii")


@dataclass(frozen=True)
class Line:
    """A parsed line: its tag (None if absent), body, and whether it carried a checksum."""

    tag: int | None
    body: str
    checked: bool


class LineError(ValueError):
    """A line that must not be executed; `code` is the protocol's ERR code."""

    def __init__(self, code: str, detail: str) -> None:
        super().__init__(f"{code} {detail}")
        self.code = code


def parse_line(raw: bytes, limit: int = MAX_REPLY) -> Line:
    """Parse one line (without its LF; a trailing CR is ignored); raises LineError."""
    raw = raw.removesuffix(b"\r")
    if len(raw) > limit:
        raise LineError("TOO_LONG", f"{len(raw)} > {limit} characters")
    if any(b < 0x20 or b > 0x7E for b in raw):
        raise LineError("BAD_BYTE", "byte outside printable ASCII")
    text = raw.decode("ascii")
    checked = False
    star = text.rfind("*")
    if star >= 0:
        given, text = text[star + 1:], text[:star]
        if given.upper() != checksum(text):
            raise LineError("CHECKSUM", f"expected {checksum(text)}, got {given!r}")
        checked = True
    tag = None
    if text.startswith("#"):
        head, _, rest = text.partition(" ")
        if not head[1:].isdigit() or int(head[1:]) > MAX_ID:
            raise LineError("ARGS", f"bad tag {head!r}")
        tag, text = int(head[1:]), rest
    return Line(tag, text.strip(), checked)


def parse_fields(words: list[str]) -> dict[str, str]:
    """`key=value` words as a dict (words without '=' are skipped)."""
    return dict(word.split("=", 1) for word in words if "=" in word)


# -- the client ----------------------------------------------------------------------------

@dataclass(frozen=True)
class FirmwareInfo:
    """What the controller said in the handshake."""

    protocol: int
    firmware: str
    drive: str
    watchdog_ms: int


@dataclass(frozen=True)
class MotorStatus:
    """One STATUS reply, stamped with the host's monotonic time."""

    state: str
    direction: str
    speed: int
    target: int
    faults: tuple[str, ...]
    uptime_ms: int
    host_time: float = field(default_factory=time.monotonic)

    @property
    def driven(self) -> bool:
        """True while the motor is powered to turn."""
        return self.state == "RUN" and self.target > 0


class MotorController:
    """A connected motor controller. Use `MotorController.connect(port)` or the constructor
    with an open `serial.Serial`; `close()` stops the motor and the heartbeat.

    timeout: seconds to wait for one reply; retries: extra tries of a request that got no
    reply (every request is idempotent); heartbeat: longest gap (s) between requests, kept
    by PINGs when the link is otherwise idle, and never more than a quarter of the
    firmware's watchdog (None: no heartbeat thread).
    """

    def __init__(self, link: serial.SerialBase, *, timeout: float = 0.5, retries: int = 1,
                 heartbeat: float | None = 0.2, connect_timeout: float = 4.0) -> None:
        self._link = link
        self.port = str(getattr(link, "port", None) or "serial link")
        self.timeout = timeout
        self.retries = retries
        self._lock = threading.RLock()
        self._rx = bytearray()
        self._next_tag = 1
        self._last_exchange = 0.0
        self._failure: DeviceError | None = None
        self._closing = threading.Event()
        self.garbage_lines = 0
        self.events: list[str] = []
        self.faults_seen: list[str] = []
        self.resets = 0  # BOOT announcements seen: each one a controller reset
        self.info = self._handshake(connect_timeout)
        self._watchdog = self.info.watchdog_ms / 1000.0
        self._heartbeat: threading.Thread | None = None
        if heartbeat is not None:
            self._heartbeat = threading.Thread(target=self._beat, args=(heartbeat,),
                                               name=f"motor-heartbeat {self.port}", daemon=True)
            self._heartbeat.start()

    @classmethod
    def connect(cls, port: str, *, baudrate: int = 115200, **options: Any) -> MotorController:
        """Open `port` and do the version handshake; DeviceError if it fails."""
        try:
            link = serial.Serial(port, baudrate=baudrate, timeout=0.05, write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"motor controller: cannot open {port}: {exc}") from None
        try:
            return cls(link, **options)
        except BaseException:
            link.close()
            raise

    def __enter__(self) -> MotorController:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commands ----------------------------------------------------------------------
    def run(self, direction: str, speed: int) -> None:
        """Turn the head: `direction` "CCW" (heading grows) or "CW", `speed` 0..1000."""
        if direction not in DIRECTIONS:
            raise ValueError(f"direction: expected one of {DIRECTIONS}, got {direction!r}")
        if not (isinstance(speed, int) and 0 <= speed <= SPEED_MAX):
            raise ValueError(f"speed: expected an integer 0..{SPEED_MAX}, got {speed!r}")
        self._request(f"RUN {direction} {speed}")

    def stop(self) -> None:
        """Coast: motor outputs off at once."""
        self._request("STOP")

    def brake(self) -> None:
        """Brake at once (H-bridge short brake, stepper holding torque)."""
        self._request("BRAKE")

    def ping(self) -> int:
        """Heartbeat; returns the controller's uptime (ms)."""
        return int(parse_fields(self._request("PING"))["t"])

    def clear_faults(self) -> None:
        """Clear latched faults so that RUN is accepted again."""
        self._request("CLEAR")

    def set_watchdog(self, milliseconds: int) -> None:
        """Set the firmware watchdog timeout (100..5000 ms)."""
        if not (isinstance(milliseconds, int) and 100 <= milliseconds <= 5000):
            raise ValueError(f"watchdog: expected 100..5000 ms, got {milliseconds!r}")
        self._request(f"WATCHDOG {milliseconds}")
        self._watchdog = milliseconds / 1000.0

    def status(self) -> MotorStatus:
        """The controller's state, applied and target speed, direction and faults."""
        words = self._request("STATUS")
        fields = parse_fields(words)
        try:
            faults = fields["faults"]
            return MotorStatus(
                state=fields["state"], direction=fields["dir"], speed=int(fields["speed"]),
                target=int(fields["target"]),
                faults=() if faults == "NONE" else tuple(faults.split(",")),
                uptime_ms=int(fields["t"]))
        except (KeyError, ValueError):
            raise DeviceError(f"motor controller on {self.port}: malformed STATUS reply "
                              f"{' '.join(words)!r}") from None

    def stop_safely(self) -> str | None:
        """Try to brake the motor, whatever state the link is in; returns why it failed."""
        try:
            self._request("BRAKE", while_closing=True)
        except DeviceError as exc:
            return str(exc)
        return None

    @property
    def failure(self) -> DeviceError | None:
        """The error that ended the link (a vanished device), if any."""
        return self._failure

    def close(self) -> None:
        """Stop the motor (best effort), the heartbeat, and close the port."""
        if self._closing.is_set():
            return
        self._closing.set()
        if self._failure is None:
            self.stop_safely()
        if self._heartbeat is not None:
            self._heartbeat.join(timeout=2.0)
        with self._lock, contextlib.suppress(*LINK_ERRORS):
            self._link.close()

    # -- internals ---------------------------------------------------------------------
    def _handshake(self, connect_timeout: float) -> FirmwareInfo:
        """Send HELLO until a controller answers, then check the protocol version."""
        deadline = time.monotonic() + connect_timeout
        with contextlib.suppress(*LINK_ERRORS):
            self._link.reset_input_buffer()
        tags: set[int] = set()
        while time.monotonic() < deadline:
            tag = self._send("HELLO")
            tags.add(tag)
            reply = self._await(tags, min(deadline, time.monotonic() + 0.3), "HELLO")
            if reply is None:
                continue
            words = reply
            if len(words) < 2 or words[0] != "HELLO" or words[1] != DEVICE_NAME:
                raise DeviceError(f"{self.port}: not a scanmap motor controller "
                                  f"(answered {' '.join(words)!r})")
            fields = parse_fields(words)
            try:
                info = FirmwareInfo(int(fields["proto"]), fields["fw"], fields["drive"],
                                    int(fields["watchdog"]))
            except (KeyError, ValueError):
                raise DeviceError(f"{self.port}: malformed HELLO reply "
                                  f"{' '.join(words)!r}") from None
            if info.protocol != PROTOCOL_VERSION:
                raise DeviceError(
                    f"{self.port}: the controller speaks motor protocol {info.protocol}, "
                    f"this host speaks {PROTOCOL_VERSION}; flash firmware/scanmap_motor")
            log.info("motor controller on %s: firmware %s, %s drive, watchdog %d ms",
                     self.port, info.firmware, info.drive, info.watchdog_ms)
            return info
        raise DeviceError(f"{self.port}: no scanmap motor controller answered HELLO within "
                          f"{connect_timeout:.1f} s (wrong port, no firmware, or wrong baud rate)")

    def _request(self, command: str, while_closing: bool = False) -> list[str]:
        """Send `command`, return the OK reply's words after the command name."""
        with self._lock:
            if self._failure is not None:
                raise DeviceError(str(self._failure))
            if self._closing.is_set() and not while_closing:
                raise DeviceError(f"motor controller on {self.port} is closed")
            name = command.split()[0]
            for _ in range(self.retries + 1):
                tag = self._send(command)
                reply = self._await({tag}, time.monotonic() + self.timeout, name)
                if reply is not None:
                    return reply[1:]
            sent = ""
            if name != "BRAKE":
                with contextlib.suppress(DeviceError):
                    self._send("BRAKE")
                    sent = "a brake was sent, and "
            raise DeviceError(
                f"motor controller on {self.port} did not answer {name} within "
                f"{self.timeout:.2f} s ({self.retries + 1} tries); {sent}the firmware "
                "watchdog stops the motor if the link is dead")

    def _send(self, command: str) -> int:
        tag = self._next_tag
        self._next_tag = self._next_tag % MAX_ID + 1
        try:  # no flush(): tcdrain has no timeout on a wedged adapter; write() has one
            self._link.write(frame_line(command, tag))
        except LINK_ERRORS as exc:
            raise self._vanished(exc) from None
        return tag

    def _await(self, tags: set[int], deadline: float, name: str) -> list[str] | None:
        """Words of the reply carrying one of `tags` (after OK), or None on timeout."""
        while True:
            raw = self._read_line(deadline)
            if raw is None:
                return None
            try:
                line = parse_line(raw)
            except LineError as exc:
                self._garbage(raw, str(exc))
                continue
            if not line.checked:
                self._garbage(raw, "no checksum")
                continue
            if line.body.startswith("!"):
                self._event(line.body)
                continue
            if line.tag not in tags:
                log.debug("motor: dropped reply %r (waiting for %s)", line.body, sorted(tags))
                continue
            words = line.body.split()
            self._last_exchange = time.monotonic()
            if words and words[0] == "OK" and len(words) > 1 and words[1] == name:
                return words[1:]
            if words and words[0] == "ERR":
                if len(words) > 1 and words[1] == "FAULT":
                    self._note_faults(words[2:3])
                raise DeviceError(f"motor controller on {self.port} refused {name}: "
                                  f"{' '.join(words[1:])}")
            raise DeviceError(f"motor controller on {self.port}: unexpected reply "
                              f"{line.body!r} to {name}")

    def _read_line(self, deadline: float) -> bytes | None:
        """The next LF-terminated line (without LF), or None at the deadline."""
        while True:
            newline = self._rx.find(b"\n")
            if newline >= 0:
                raw = bytes(self._rx[:newline])
                del self._rx[:newline + 1]
                return raw
            if len(self._rx) > 2 * MAX_REPLY:
                self._garbage(bytes(self._rx), "over-long line")
                self._rx.clear()
            if time.monotonic() >= deadline:
                return None
            try:
                chunk = self._link.read(max(1, self._link.in_waiting))
            except LINK_ERRORS as exc:
                raise self._vanished(exc) from None
            self._rx += chunk

    def _vanished(self, exc: BaseException) -> DeviceError:
        self._failure = DeviceError(
            f"motor controller on {self.port} vanished ({exc}); the firmware watchdog stops "
            "the motor if it is still powered")
        return self._failure

    def _garbage(self, raw: bytes, why: str) -> None:
        self.garbage_lines += 1
        log.debug("motor: dropped damaged line %r (%s)", raw[:80], why)

    def _event(self, body: str) -> None:
        self.events.append(body)
        words = body.split()
        if len(words) >= 2 and words[1] == "BOOT":
            self.resets += 1
            log.warning("motor controller on %s reset (%s)", self.port, body)
        if len(words) >= 3 and words[1] == "FAULT":
            self._note_faults(words[2:3])
            log.warning("motor controller on %s reports fault %s", self.port, words[2])

    def _note_faults(self, words: list[str]) -> None:
        for word in words:
            self.faults_seen.extend(f for f in word.split(",") if f not in self.faults_seen)

    def _beat(self, interval: float) -> None:
        while not self._closing.wait(min(interval, self._watchdog / 4) / 2):
            if time.monotonic() - self._last_exchange < min(interval, self._watchdog / 4):
                continue
            try:
                self.ping()
            except DeviceError as exc:
                if self._failure is not None or self._closing.is_set():
                    return
                log.warning("motor heartbeat: %s", exc)
