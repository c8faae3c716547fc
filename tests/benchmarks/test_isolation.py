"""A peer run in its own process answers, or fails alone with the reason."""

from __future__ import annotations

import os
import signal
import time

import pytest

from benchmarks.isolation import PeerFailed, run_isolated


def _square(x: float) -> float:
    return x * x


def _segfault() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def _hang() -> None:
    time.sleep(60)


def _raise() -> None:
    raise ValueError("empty scan")


def test_a_peer_answers_from_its_own_process():
    assert run_isolated(_square, 3.0, timeout=60) == 9.0


def test_a_crashing_peer_is_reported_with_its_signal():
    with pytest.raises(PeerFailed, match="SIGSEGV"):
        run_isolated(_segfault, timeout=60)


def test_a_hanging_peer_is_killed_at_its_time_limit():
    start = time.perf_counter()
    with pytest.raises(PeerFailed, match="no answer within 3 s"):
        run_isolated(_hang, timeout=3)
    assert time.perf_counter() - start < 30


def test_a_peer_exception_is_reported_by_type_and_message():
    with pytest.raises(PeerFailed, match="ValueError: empty scan"):
        run_isolated(_raise, timeout=60)
