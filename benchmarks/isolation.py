"""Run a peer library in a process of its own, with a time limit.

A peer that crashes (small_gicp died with SIGSEGV on a real log with empty scans) or
hangs must fail alone, reported as that peer's failure, and never take the benchmark run
down with it. `run_isolated` forks a process from a clean server process (`forkserver`:
nothing inherited from the peers, Open3D or Numba having run in this process; the server
has only imported numpy, scanmap and the first peer's module, so that a child starts in
0.1 s rather than the 3 s of a fresh interpreter importing them), calls `func(*args)`
there and returns its result, or raises `PeerFailed` saying what happened.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

PEER_TIMEOUT = 600.0  # s a peer may take on one input, unless a call says otherwise


class PeerFailed(RuntimeError):
    """A peer that raised, crashed or ran out of time; the message says which."""


def _child(conn: Connection, func: Callable[..., Any], args: tuple) -> None:
    try:
        result = (True, func(*args))
    except Exception as exc:  # reported to the parent, which raises PeerFailed
        result = (False, f"{type(exc).__name__}: {exc}")
    conn.send(result)
    conn.close()


def run_isolated(func: Callable[..., Any], *args: Any, timeout: float | None = None) -> Any:
    """`func(*args)` in a fresh process; PeerFailed on an exception, a crash or `timeout`
    seconds (default `PEER_TIMEOUT`) without an answer. `func` and `args` must be picklable
    (module-level)."""
    timeout = PEER_TIMEOUT if timeout is None else timeout
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["numpy", "scanmap", func.__module__])  # at its start
    receive, send = context.Pipe(duplex=False)
    process = context.Process(target=_child, args=(send, func, args), daemon=True)
    process.start()
    send.close()
    try:
        if not receive.poll(timeout):
            process.kill()
            raise PeerFailed(f"no answer within {timeout:g} s (killed)")
        try:
            ok, value = receive.recv()
        except EOFError:
            process.join()
            code = process.exitcode
            reason = (f"signal {signal.Signals(-code).name}" if code is not None and code < 0
                      else f"exit code {code}")
            raise PeerFailed(f"crashed ({reason})") from None
    finally:
        receive.close()
        process.join(timeout=5)
        if process.is_alive():
            process.kill()
    if not ok:
        raise PeerFailed(value)
    return value
