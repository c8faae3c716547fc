"""Hypothesis mutations of files, shared by the fuzz test of every reader.

A mutated file must be read or refused with the reader's one `ScanmapError` subclass,
whose message names the file: never another exception, a hang, or an allocation the
file does not justify (`read_within`).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import signal
import struct
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from scanmap_driver.errors import ScanmapError

T = TypeVar("T")

FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow, HealthCheck.data_too_large])
_DELETE = object()  # a mutation that deletes the node
TIME_LIMIT = 20  # s: a reader slower than this on a small file hangs
HUGE = 10**12

HOSTILE_JSON = [None, True, False, 0, -1, -(2**63), 2**64, 10**400, 1e308, -1e308, math.nan,
                math.inf, -math.inf, 1e-320, "", "x" * 300, "NaN", [], {}, [1.0, 2.0],
                [[[[[]]]]], {"unexpected": 1}]


@contextlib.contextmanager
def _time_limit(seconds: int) -> Iterator[None]:
    def hang(signum: int, frame: Any) -> None:
        raise AssertionError(f"the reader did not finish within {seconds} s")
    previous = signal.signal(signal.SIGALRM, hang)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def read_within(read: Callable[[], T], error: type[ScanmapError], path: Path) -> T | None:
    """`read()`'s result, or None when it raised `error` naming `path`'s file."""
    with _time_limit(TIME_LIMIT):
        try:
            return read()
        except error as exc:
            assert path.name in str(exc), f"the error does not name {path.name}: {exc}"
            return None


# -- bytes ------------------------------------------------------------------------------

@st.composite
def mutated_bytes(draw: st.DrawFn, data: bytes) -> bytes:
    """`data` truncated, with bits flipped, a span overwritten, inserted or deleted, or a
    32-bit field set to a huge or negative size."""
    n = len(data)
    kind = draw(st.sampled_from(["truncate", "flip", "overwrite", "insert", "delete", "size"]))
    at = draw(st.integers(0, max(n - 1, 0)))
    if kind == "truncate":
        return data[:at]
    if kind == "flip":
        out = bytearray(data)
        for pos in draw(st.lists(st.integers(0, max(n - 1, 0)), min_size=1, max_size=8)):
            if out:
                out[pos] ^= 1 << draw(st.integers(0, 7))
        return bytes(out)
    if kind == "size":
        value = draw(st.sampled_from([0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, HUGE % 2**32, 0]))
        return data[:at] + struct.pack("<I", value) + data[at + 4:]
    chunk = draw(st.binary(min_size=1, max_size=64))
    if kind == "overwrite":
        return data[:at] + chunk + data[at + len(chunk):]
    if kind == "insert":
        return data[:at] + chunk + data[at:]
    return data[:at] + data[at + len(chunk):]


# -- JSON -------------------------------------------------------------------------------

def _paths(tree: Any, prefix: tuple = ()) -> list[tuple]:
    """Every node's path (keys and indices) in a JSON tree, the root's too."""
    out = [prefix]
    if isinstance(tree, dict):
        for key, value in tree.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(tree, list):
        for i, value in enumerate(tree):
            out += _paths(value, (*prefix, i))
    return out


@st.composite
def mutated_json(draw: st.DrawFn, tree: Any) -> str:
    """The JSON text of `tree` with one node deleted, replaced by a hostile value (wrong
    type, NaN, inf, huge, negative, nested), or given an unknown key; or its text
    mutated as bytes."""
    if draw(st.integers(0, 4)) == 0:
        return draw(mutated_bytes(json.dumps(tree).encode())).decode(errors="replace")
    path = draw(st.sampled_from(_paths(tree)))
    if not path:
        return json.dumps(draw(st.sampled_from(HOSTILE_JSON)))
    action = draw(st.sampled_from(["delete", "replace", "replace", "extra"]))
    node = _node(tree, path)
    if action == "extra" and isinstance(node, dict):
        return json.dumps(_changed(tree, path, node | {"unexpected_field": 1}))
    value = _DELETE if action == "delete" else draw(st.sampled_from(HOSTILE_JSON))
    return json.dumps(_changed(tree, path, value))


def _node(tree: Any, path: tuple) -> Any:
    for key in path:
        tree = tree[key]
    return tree


def _changed(tree: Any, path: tuple, value: Any) -> Any:
    """A copy of `tree` with the node at `path` set to `value` (deleted for _DELETE)."""
    changed = json.loads(json.dumps(tree))
    parent = _node(changed, path[:-1])
    if value is _DELETE:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return changed


# -- npz --------------------------------------------------------------------------------

def _hostile_arrays(value: np.ndarray) -> list[np.ndarray]:
    """Wrong dtypes and shapes, NaN and inf, negative and huge values for one array."""
    if value.dtype.kind in "US":  # text (JSON in a 0-d array)
        return [np.array(1.5), np.zeros((2, 2)), np.array(""), np.array("{"), np.array("[]"),
                np.array(["a", "b"]), np.array('{"unexpected": NaN}')]
    out = [value.astype(np.int16) - 1, value.astype(np.float64) * 1e300,
           value.astype(np.complex128), value.astype(str), value.astype(bool),
           np.zeros((0,) + value.shape[1:], value.dtype), value.reshape(-1), value[None],
           np.array(7, value.dtype), np.full(value.shape, -1, np.int64),
           np.full(value.shape, 2**40, np.int64)]
    if value.dtype.kind == "f":
        out += [np.full(value.shape, np.nan, value.dtype), np.full(value.shape, np.inf)]
    return out


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def huge_header_npz(arrays: dict[str, np.ndarray], key: str) -> bytes:
    """An npz whose `key` member's header claims 10^12 elements over a few bytes of data."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, value in arrays.items():
            member = io.BytesIO()
            if name == key:
                header = {"descr": np.lib.format.dtype_to_descr(value.dtype),
                          "fortran_order": False, "shape": (HUGE, *value.shape[1:])}
                np.lib.format.write_array_header_1_0(member, header)
                member.write(value.tobytes()[:64])
            else:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
            archive.writestr(f"{name}.npy", member.getvalue())
    return buffer.getvalue()


@st.composite
def mutated_npz(draw: st.DrawFn, arrays: dict[str, np.ndarray],
                keys: list[str] | None = None) -> bytes:
    """The npz of `arrays` with one array (of `keys`, default all) deleted, replaced by a
    hostile one, or given a header that claims 10^12 elements; or the file mutated as
    bytes."""
    key = draw(st.sampled_from(sorted(arrays) if keys is None else keys))
    action = draw(st.sampled_from(["delete", "hostile", "hostile", "hostile", "huge", "bytes"]))
    if action == "bytes":
        return draw(mutated_bytes(npz_bytes(arrays)))
    if action == "huge":
        return huge_header_npz(arrays, key)
    changed = dict(arrays)
    if action == "delete":
        del changed[key]
    else:
        changed[key] = draw(st.sampled_from(_hostile_arrays(np.asarray(arrays[key]))))
    return npz_bytes(changed)


def finite_json(tree: Any) -> Any:
    """`tree` after a strict JSON round trip: fails on NaN or inf anywhere in it."""
    return json.loads(json.dumps(tree, allow_nan=False))


def every_json_mutation(tree: Any) -> Iterator[tuple[tuple, Any]]:
    """(path, mutated tree) for every node of `tree` deleted and replaced by each hostile
    value: the sweep that hypothesis' sampling may miss."""
    for path in _paths(tree)[1:]:
        for value in [_DELETE, *(v for v in HOSTILE_JSON if v != 10**400)]:  # read_json
            # refuses integers beyond float64; in memory they are a caller's bug
            yield path, _changed(tree, path, value)



def every_npz_mutation(arrays: dict[str, np.ndarray], keys: list[str] | None = None
                       ) -> Iterator[tuple[str, bytes]]:
    """(key, npz bytes) for every array (of `keys`) deleted, replaced by each hostile array,
    and given a header claiming 10^12 elements: the sweep sampling may miss."""
    for key in sorted(arrays) if keys is None else keys:
        yield key, huge_header_npz(arrays, key)
        yield key, npz_bytes({k: v for k, v in arrays.items() if k != key})
        for value in _hostile_arrays(np.asarray(arrays[key])):
            yield key, npz_bytes(arrays | {key: value})


def sweep_json_reader(original: Any, from_dict: Callable[..., Any],
                      error: type[ScanmapError], first_of_lists: bool = False) -> None:
    """Every mutation of `every_json_mutation(original)`: `from_dict(tree, source=...)`
    refuses it with `error` naming the source, or keeps the written value as it was
    (what `to_dict` gives back; it leaves out defaults). `first_of_lists`: the first item
    of each list stands for the others."""
    for path, tree in every_json_mutation(original):
        if first_of_lists and any(isinstance(key, int) and key > 0 for key in path[:-1]):
            continue
        try:
            value = from_dict(tree, source="sweep.json")
        except error as exc:
            assert "sweep.json" in str(exc)
            continue
        written = finite_json(value.to_dict())
        for key in path[:-1]:
            written, tree = written[key], tree[key]
        kept = path[-1] in tree and path[-1] in written
        if kept and not isinstance(tree[path[-1]], dict):
            assert written[path[-1]] == tree[path[-1]], path
