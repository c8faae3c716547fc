"""A person at a serial monitor, for protocol tests: writes raw lines to a serial port and
reads replies, checking each reply's checksum with an XOR computed here."""

from __future__ import annotations

import functools
import time

import serial


def xor_checksum(text: str) -> str:
    return f"{functools.reduce(lambda a, b: a ^ b, text.encode(), 0):02X}"


class Terminal:
    """Writes lines, reads reply bodies (checksum verified and removed); events (lines
    starting with '!') are set aside in `events`."""

    def __init__(self, port: str) -> None:
        self.link = serial.Serial(port, 115200, timeout=0.05)
        self.events: list[str] = []
        self._partial = b""  # a line cut by a timeout: its end comes with the next read

    def send(self, data: bytes) -> None:
        self.link.write(data)

    def line(self, timeout: float = 2.0) -> str | None:
        """The next reply body, or None after `timeout` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self._partial += self.link.read(1)
            if self._partial.endswith(b"\n"):
                text = self._partial[:-1].decode("ascii")
                self._partial = b""
                body, star, given = text.rpartition("*")
                assert star and given == xor_checksum(body), text
                if body.startswith("!"):
                    self.events.append(body)
                    continue
                return body
        return None

    def wait_event(self, prefix: str, timeout: float = 5.0) -> str | None:
        """The first event starting with `prefix`, reading lines for up to `timeout` s."""
        deadline = time.monotonic() + timeout
        while True:
            found = [e for e in self.events if e.startswith(prefix)]
            if found or time.monotonic() >= deadline:
                return found[0] if found else None
            self.line(timeout=0.05)

    def ask(self, command: str | bytes, timeout: float = 2.0) -> str | None:
        data = command if isinstance(command, bytes) else command.encode()
        self.send(data + b"\n")
        return self.line(timeout)

    def close(self) -> None:
        self.link.close()
