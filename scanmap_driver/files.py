"""File helpers shared by every writer and reader: atomic writes and safe npz/JSON loads.

Nothing recorded or mapped is lost: files are written to a temporary name in the same
folder, flushed to the disk (fsync), renamed over the target, and the folder is flushed
too, so a reader (after a crash or a power cut as well) finds the old file or the new
one, never a half-written one.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
import tokenize
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ScanmapError

_MAX_INT_DIGITS = 300  # float64 reaches 1.8e308
_MAX_DEFLATE = 1032  # deflate's largest expansion ratio
_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it over `path` if the block succeeds.

    The temporary name carries this process's id, so that the first write into a folder
    removes what killed writers left there (`remove_orphans`)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    if target.parent not in _SWEPT:
        remove_orphans(target.parent)
        _SWEPT.add(target.parent)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.",
                                    suffix=_TMP + target.suffix, dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual mode
    try:
        yield tmp
        publish(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


_TMP = ".tmp"
_SWEPT: set[Path] = set()  # folders this process has swept already


def remove_orphans(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files of `atomic_path` in `folder` whose writer is dead (killed
    mid-write: SIGKILL, a power cut); return them. Another live writer's are kept."""
    removed = []
    for tmp in Path(folder).glob(f".*.*.*{_TMP}*"):
        pid = _writer_pid(tmp.name)
        if pid is not None and pid != os.getpid() and not _alive(pid):
            tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def _writer_pid(name: str) -> int | None:
    """The writer's process id in an `atomic_path` temporary name, else None."""
    stem = name[: name.rfind(_TMP)] if _TMP in name else ""
    parts = stem.rsplit(".", 2)  # ".target", pid, mkstemp's random part
    return int(parts[1]) if len(parts) == 3 and parts[1].isdigit() else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def fsync_file(path: str | os.PathLike[str]) -> None:
    """Flush a closed file's data to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_folder(folder: str | os.PathLike[str]) -> None:
    """Flush a folder's entries (a rename, a new or removed file) to the disk."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def publish(tmp: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Make the finished file `tmp` durable and rename it over `target` (same folder)."""
    fsync_file(tmp)
    os.replace(tmp, target)
    fsync_folder(Path(target).parent)


def write_json(path: str | os.PathLike[str], data: Any) -> None:
    """Write `data` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")


def read_json(path: str | os.PathLike[str], error: type[ScanmapError]) -> Any:
    """Read a JSON file, raising `error` that names the file when it is missing or malformed."""
    try:
        text = Path(path).read_bytes().decode()
    except FileNotFoundError:
        raise error(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read the file ({exc})") from None
    try:
        return json.loads(text, parse_int=_json_int)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, an over-long integer
        raise error(f"{path}: not valid JSON ({exc})") from None


def _json_int(digits: str) -> int:
    """A JSON integer that also fits a float (a longer one is damage, not a value)."""
    if len(digits.lstrip("-")) > _MAX_INT_DIGITS:
        raise ValueError(f"integer of {len(digits)} digits")
    return int(digits)


def save_npz(path: str | os.PathLike[str], **arrays: np.ndarray) -> None:
    """Write arrays to an .npz (what `np.load` reads), atomically: each array deflated
    where that pays (`_deflates`), stored as it is where it does not (measured coordinates:
    deflating a map's 1.4 MB of float32 points took 60-70 ms to save 10 %, while its
    grid's 2.2 MB shrink to 5 % in 10 ms)."""
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED,
                                                   compresslevel=_DEFLATE_LEVEL) as archive:
        for name, value in arrays.items():
            array = np.asanyarray(value)
            member = name + ".npy"
            if not _deflates(array):
                member = zipfile.ZipInfo(member, date_time=(1980, 1, 1, 0, 0, 0))
                member.compress_type = zipfile.ZIP_STORED
            with archive.open(member, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, array, allow_pickle=False)


_DEFLATE_LEVEL = 1  # zlib's fastest: a map grid's arrays deflate about as far as at 6
_DEFLATE_SAMPLE = 1 << 16  # bytes of an array tried before deflating all of it
_DEFLATE_GAIN = 0.8  # deflate when the sample shrinks below this share of its size


def _deflates(array: np.ndarray) -> bool:
    """Whether deflating `array` pays: its first `_DEFLATE_SAMPLE` bytes shrink below
    `_DEFLATE_GAIN` of their size (small arrays always: it costs nothing)."""
    if array.nbytes <= _DEFLATE_SAMPLE or array.dtype.hasobject:
        return True
    head = np.ascontiguousarray(array.reshape(-1)[:_DEFLATE_SAMPLE // array.itemsize])
    return len(zlib.compress(head.tobytes(), _DEFLATE_LEVEL)) < _DEFLATE_GAIN * head.nbytes


def load_npz(path: str | os.PathLike[str], error: type[ScanmapError],
             required: tuple[str, ...] = (), skip: tuple[str, ...] = ()
             ) -> dict[str, np.ndarray]:
    """Load every array of an .npz but those in `skip`, without pickle; `error` names the
    file and missing keys."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            if not isinstance(npz, np.lib.npyio.NpzFile):
                raise ValueError("a single array, not an archive of named arrays")
            _check_sizes(npz)
            arrays = {key: npz[key] for key in npz.files if key not in skip}
    except FileNotFoundError:
        raise error(f"{path}: file not found") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error,
            NotImplementedError, MemoryError, SyntaxError, tokenize.TokenError) as exc:
        # SyntaxError, TokenError: numpy parses each array's header as Python literals
        raise error(f"{path}: not a readable .npz file ({exc})") from None
    missing = [key for key in required if key not in arrays and key not in skip]
    if missing:
        raise error(f"{path}: missing arrays {missing}")
    return arrays


def _check_sizes(npz: np.lib.npyio.NpzFile) -> None:
    """ValueError when an array's header claims more bytes than its member holds, or a
    member more than deflate can expand its compressed bytes to: nothing is allocated for
    a size the file does not back."""
    for info in npz.zip.infolist():
        with npz.zip.open(info) as member:
            version = np.lib.format.read_magic(member)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(member)
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(member)
            else:
                raise ValueError(f"{info.filename}: unsupported .npy version {version}")
        claimed = math.prod(shape) * dtype.itemsize
        if claimed > info.file_size or info.file_size > _MAX_DEFLATE * info.compress_size + 4096:
            raise ValueError(f"{info.filename}: its header claims {claimed} bytes, the member "
                             f"holds {info.file_size} ({info.compress_size} compressed)")


def exact_array(raw: np.ndarray, where: str, dtype: type | np.dtype,
                error: type[ScanmapError], allow_nan: bool = False) -> np.ndarray:
    """`raw` as `dtype` when every value survives the conversion unchanged: integers not
    wrapped (a colour of -1 is refused, not read as 255), floats finite after it (unless
    NaN is allowed); else `error` naming `where`."""
    target = np.dtype(dtype)
    if raw.dtype.kind not in ("iu" if target.kind in "iu" else "iuf"):
        raise error(f"{where}: expected {target.name} values, got {raw.dtype}")
    with np.errstate(all="ignore"):
        value = raw.astype(target)
    if target.kind in "iu":
        if not np.array_equal(value, raw):
            raise error(f"{where}: values outside the range of {target.name}")
    elif not np.isfinite(np.where(np.isnan(raw), 0.0, value) if allow_nan else value).all():
        raise error(f"{where}: expected finite values (no NaN, inf or float overflow)")
    return value
