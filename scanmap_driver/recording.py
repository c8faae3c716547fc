"""Raw recordings: what the scanner's hardware produced, kept as it was delivered.

A recording is a folder (docs/architecture.md):

    recording.json       the index (below)
    scan_0000.avi        scan 0's video: MJPG in an AVI container, one JPEG per frame,
                         stored byte for byte as the camera (or the simulator) sent it
    scan_0000.json       scan 0's sidecar (below)
    ...
    ground_truth/        simulated recordings only (`scanmap_driver.sim.truth`)

`recording.json`:

    format      "scanmap.recording/1"
    software    {"name": "scanmap", "version": "0.1.0"}: what wrote the recording
    source      what produced the frames: "camera", "simulator", ... (free text)
    scanner     the scanner model, a `scanmap.scanner/1` object
    scans       [{"index": 0, "video": "scan_0000.avi", "sidecar": "scan_0000.json",
                  "frames": 52}, ...] in recording order
    extra       optional object: anything the producer wants kept (the simulator puts
                its scene, seed and lighting here)

`scan_NNNN.json`:

    format      "scanmap.recording.scan/1"
    index       the scan's number
    video       the video file's name
    complete    false when the scan was cut short (a fault); its frames are still kept
    stamp       recording time (s) when the scan started (the motor's start command)
    exposure    the camera's exposure time (s), null if unknown
    frame_times one per frame of the video: recording time (s) of the frame's mid-exposure
    motor_log   [{"t": s, "command": "run" | "brake" | "stop" | ..., "duty": -1..1}, ...]:
                the commands sent to the motor, at recording times; more keys allowed
    odometry    {"start": [x, y, yaw], "end": [x, y, yaw]}: pose of `base_link` in `odom`
                at the first and last frame (m, rad), or null without odometry

Times are seconds from the start of the recording. Every file is written under a
temporary name and renamed; the index is rewritten after each scan, so a crash keeps every
finished scan. While a scan is recorded its video grows as `scan_NNNN.avi.part` (a valid
AVI prefix) beside a journal `scan_NNNN.journal` (JSON lines: a header with index,
video, stamp and exposure, then `{"t": time}` per frame written and `{"motor": {...}}` per
motor command), both flushed frame by frame; a recorder killed mid-scan leaves them, and
`Recording.open` recovers that scan (complete: false, recovered: true) with every frame
written before the kill. Reading checks every field (a `RecordingError` names the file
and field), and a corrupt or truncated video yields its good frames before the
`RecordingError` that names the file and the frame.

The AVI container (RIFF, AVI 1.0 with an `idx1` index) is written here rather than by
`cv2.VideoWriter`, which would decode and re-encode the webcam's JPEGs (a second lossy
step, and 4:2:0 chroma where webcams send 4:2:2); OpenCV and FFmpeg read the files.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, BinaryIO

import cv2
import numpy as np

from .errors import CalibrationError, RecordingError
from .files import fsync_folder, publish, read_json, write_json
from .jpeg import jpeg_to_bgr
from .scanner_model import ScannerModel
from .transforms import se2_to_pose
from .validate import check_keys, integer, number, vector

FORMAT = "scanmap.recording/1"
SCAN_FORMAT = "scanmap.recording.scan/1"
INDEX_NAME = "recording.json"
GROUND_TRUTH = "ground_truth"
JOURNAL_FORMAT = "scanmap.recording.journal/1"
PARTIAL_SUFFIX = ".part"
JOURNAL_SUFFIX = ".journal"
DEFAULT_JPEG_QUALITY = 95  # for frames handed over decoded (BGR)

_KEYFRAME = 0x10
_HAS_INDEX = 0x10
_OPEN_SIZE = 0xFFFFFFFE  # the size of a list still being written (the file's end)
_MAX_LIST_DEPTH = 4  # 'movi' inside RIFF, 'rec ' inside 'movi': deeper nesting is damage


def scan_name(index: int) -> str:
    """File stem of a scan: scan_0000."""
    return f"scan_{index:04d}"


# -- AVI container ------------------------------------------------------------------------

def _chunk(fourcc: bytes, payload: bytes) -> bytes:
    return fourcc + struct.pack("<I", len(payload)) + payload + (b"\0" if len(payload) % 2 else b"")


def _headers(width: int, height: int, frame_rate: float, frames: int, largest: int) -> bytes:
    """The `hdrl` list of an MJPG AVI."""
    rate = max(round(frame_rate * 1000), 1)
    avih = struct.pack("<14I", round(1e6 / frame_rate) if frame_rate > 0 else 0, 0, 0,
                       _HAS_INDEX, frames, 0, 1, largest, width, height, 0, 0, 0, 0)
    strh = (b"vids" + b"MJPG" + struct.pack("<IHHIIIIIIIIhhhh", 0, 0, 0, 0, 1000, rate, 0,
                                            frames, largest, 0xFFFFFFFF, 0, 0, 0, width,
                                            height))
    strf = struct.pack("<IiiHH4sIiiII", 40, width, height, 1, 24, b"MJPG", width * height * 3,
                       0, 0, 0, 0)
    strl = b"LIST" + struct.pack("<I", 4 + 8 + len(strh) + 8 + len(strf)) + b"strl" \
        + _chunk(b"strh", strh) + _chunk(b"strf", strf)
    hdrl = b"hdrl" + _chunk(b"avih", avih) + strl
    return b"LIST" + struct.pack("<I", len(hdrl)) + hdrl


class AviWriter:
    """Writes JPEG frames into an MJPG AVI file as they come; `close` finishes the file."""

    def __init__(self, stream: BinaryIO, width: int, height: int, frame_rate: float) -> None:
        self._stream = stream
        self._size = (width, height)
        self._rate = frame_rate
        self._index: list[tuple[int, int]] = []  # (offset from 'movi', size)
        self._stream.write(self._prefix(_OPEN_SIZE, _OPEN_SIZE))  # readable while it grows
        self._movi_start = self._stream.tell() - 4  # position of the 'movi' fourcc

    def _prefix(self, riff_size: int, movi_size: int) -> bytes:
        """RIFF header, `hdrl` and the head of the 'movi' list."""
        largest = max((size for _, size in self._index), default=0)
        headers = _headers(*self._size, self._rate, len(self._index), largest)
        return (b"RIFF" + struct.pack("<I", riff_size) + b"AVI " + headers
                + b"LIST" + struct.pack("<I", movi_size) + b"movi")

    @property
    def frames(self) -> int:
        """Frames written so far."""
        return len(self._index)

    def write(self, jpeg: bytes) -> None:
        """Append one JPEG frame."""
        offset = self._stream.tell() - self._movi_start
        self._stream.write(_chunk(b"00dc", jpeg))
        self._index.append((offset, len(jpeg)))

    def close(self) -> None:
        """Write the index and the headers now that the sizes are known."""
        end_of_movi = self._stream.tell()
        index = b"".join(b"00dc" + struct.pack("<III", _KEYFRAME, offset, size)
                         for offset, size in self._index)
        self._stream.write(_chunk(b"idx1", index))
        total = self._stream.tell()
        self._stream.seek(0)
        self._stream.write(self._prefix(total - 8, end_of_movi - self._movi_start))
        self._stream.seek(total)


def read_avi_frames(path: str | os.PathLike[str]) -> Iterator[bytes]:
    """The JPEG payloads of an MJPG AVI in order (any writer: RIFF chunks '##dc'/'##db').

    Raises RecordingError naming the file after the last good frame when the file is not
    an AVI, or is cut short.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the video ({exc})") from None
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"AVI ":
        raise RecordingError(f"{path}: not an AVI file")
    yield from _movi_frames(path, data, 12, len(data), in_movi=False)


def _movi_frames(path: Path, data: bytes, start: int, end: int, in_movi: bool,
                 depth: int = 1) -> Iterator[bytes]:
    if depth > _MAX_LIST_DEPTH:
        raise RecordingError(f"{path}: lists nested deeper than {_MAX_LIST_DEPTH} (damaged)")
    pos = start
    while pos + 8 <= end:
        fourcc = data[pos:pos + 4]
        size = struct.unpack_from("<I", data, pos + 4)[0]
        body = pos + 8
        if fourcc == b"LIST":
            kind = data[body:body + 4]
            stop = min(body + size, end)
            if kind in (b"movi", b"rec "):
                yield from _movi_frames(path, data, body + 4, stop, True, depth + 1)
            if body + size > len(data):
                raise RecordingError(f"{path}: the file is truncated inside its "
                                     f"{kind.decode(errors='replace')!r} list")
        elif in_movi and fourcc[2:] in (b"dc", b"db"):
            if body + size > len(data):
                raise RecordingError(f"{path}: the file is truncated inside a frame")
            yield data[body:body + size]
        pos = body + size + (size & 1)


def decode_jpeg(jpeg: bytes, where: str, shape: tuple[int, int] | None = None) -> np.ndarray:
    """BGR image of one JPEG frame; RecordingError (naming `where`) if it is damaged."""
    body = jpeg.rstrip(b"\0")
    if not body.startswith(b"\xff\xd8") or not body.endswith(b"\xff\xd9"):
        raise RecordingError(f"{where}: not a complete JPEG image (damaged or truncated)")
    image = jpeg_to_bgr(body)
    if image is None:
        raise RecordingError(f"{where}: the JPEG image does not decode")
    if shape is not None and image.shape[:2] != shape:
        raise RecordingError(f"{where}: image is {image.shape[1]}x{image.shape[0]}, the "
                             f"recording's camera is {shape[1]}x{shape[0]}")
    return image


# -- Reading ------------------------------------------------------------------------------

@dataclass(frozen=True)
class ScanRecord:
    """One scan's sidecar, validated. Times are recording times (s)."""

    index: int
    video: Path
    sidecar: Path
    complete: bool
    stamp: float
    exposure: float | None
    frame_times: np.ndarray
    motor_log: tuple[dict, ...]
    odometry_start: np.ndarray | None  # (x, y, yaw) in `odom`
    odometry_end: np.ndarray | None
    recovered: bool = False  # rebuilt from the journal of a recorder killed mid-scan

    @property
    def odom_start(self) -> np.ndarray:
        """4x4 pose of `base_link` in `odom` at the first frame (NaN without odometry)."""
        return _pose(self.odometry_start)

    @property
    def odom_end(self) -> np.ndarray:
        """4x4 pose of `base_link` in `odom` at the last frame (NaN without odometry)."""
        return _pose(self.odometry_end)


def _pose(se2: np.ndarray | None) -> np.ndarray:
    return np.full((4, 4), np.nan) if se2 is None else se2_to_pose(*se2)


@dataclass(frozen=True)
class RecordedFrame:
    """One decoded frame of a scan: its number in the scan, time (s) and BGR image."""

    index: int
    time: float
    image: np.ndarray


@dataclass(frozen=True)
class Recording:
    """A validated recording folder; `frames(i)` decodes scan i's video."""

    path: Path
    model: ScannerModel
    software: dict
    source: str
    scans: tuple[ScanRecord, ...]
    extra: dict = field(default_factory=dict)

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> Recording:
        """Read and validate `recording.json` and every sidecar."""
        folder = Path(path)
        index_path = folder / INDEX_NAME
        if not folder.is_dir():
            raise RecordingError(f"{folder}: not a recording folder")
        data = read_json(index_path, RecordingError)
        where = str(index_path)
        top = check_keys(data, where, RecordingError,
                         ["format", "software", "source", "scanner", "scans"], ["extra"])
        if top["format"] != FORMAT:
            raise RecordingError(f"{where}: format: expected {FORMAT!r}, got {top['format']!r}")
        try:
            model = ScannerModel.from_dict(top["scanner"], source=f"{where}: scanner")
        except CalibrationError as exc:
            raise RecordingError(str(exc)) from None
        if not isinstance(top["scans"], list):
            raise RecordingError(f"{where}: scans: expected a list")
        scans = []
        for i, entry in enumerate(top["scans"]):
            item = check_keys(entry, f"{where}: scans[{i}]", RecordingError,
                              ["index", "video", "sidecar", "frames"])
            scans.append(_read_sidecar(folder, item, f"{where}: scans[{i}]"))
        indexed = {record.index for record in scans}
        for journal in sorted(folder.glob(f"scan_*{JOURNAL_SUFFIX}")):
            record = _recover(folder, journal)
            if record.index not in indexed:
                scans.append(record)
        for key in ("software", "extra"):
            if not isinstance(top.get(key, {}), dict):
                raise RecordingError(f"{where}: {key}: expected an object")
        if not isinstance(top["source"], str):
            raise RecordingError(f"{where}: source: expected a string")
        return cls(folder, model, dict(top["software"]), str(top["source"]), tuple(scans),
                   dict(top.get("extra", {})))

    @property
    def ground_truth(self) -> Path | None:
        """The `ground_truth/` folder of a simulated recording, else None."""
        path = self.path / GROUND_TRUTH
        return path if path.is_dir() else None

    def scan(self, index: int) -> ScanRecord:
        """The scan with this index."""
        for record in self.scans:
            if record.index == index:
                return record
        raise RecordingError(f"{self.path}: no scan {index} "
                             f"(scans: {[r.index for r in self.scans]})")

    def frames(self, index: int) -> Iterator[RecordedFrame]:
        """Decoded frames of scan `index`, in order, each with its time.

        A damaged or truncated video yields the frames before the damage, then raises a
        RecordingError naming the file and the frame.
        """
        record = self.scan(index)
        shape = (self.model.camera.height, self.model.camera.width)
        count = 0
        jpegs = read_avi_frames(record.video)
        if record.recovered:  # the video may hold the start of one more frame
            jpegs = itertools.islice(jpegs, record.frame_times.shape[0])
        for count, jpeg in enumerate(jpegs, start=1):
            where = f"{record.video}: frame {count - 1}"
            if count > record.frame_times.shape[0]:
                raise RecordingError(f"{record.video}: more frames than the "
                                     f"{record.frame_times.shape[0]} frame_times of "
                                     f"{record.sidecar.name}")
            yield RecordedFrame(count - 1, float(record.frame_times[count - 1]),
                        decode_jpeg(jpeg, where, shape))
        if count < record.frame_times.shape[0]:
            raise RecordingError(f"{record.video}: the video ends after {count} of "
                                 f"{record.frame_times.shape[0]} frames (truncated?)")


def _recover(folder: Path, journal: Path) -> ScanRecord:
    """The scan a recorder killed mid-scan left: its journal's frames, complete: false."""
    try:
        text = journal.read_bytes().decode()
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{journal}: cannot read the journal ({exc})") from None
    lines = text.split("\n")[:-1]  # the last piece lacks its newline: cut by the kill
    if not lines:
        raise RecordingError(f"{journal}: the journal has no header line")
    entries = []
    for number_, line in enumerate(lines, start=1):
        try:
            entries.append(json.loads(line))
        except ValueError:
            raise RecordingError(f"{journal}: line {number_}: not valid JSON") from None
    head = check_keys(entries[0], f"{journal}: line 1", RecordingError,
                      ["format", "index", "video", "stamp", "exposure"])
    if head["format"] != JOURNAL_FORMAT:
        raise RecordingError(f"{journal}: line 1: format: expected {JOURNAL_FORMAT!r}")
    index = integer(head["index"], f"{journal}: line 1: index", RecordingError, low=0)
    video = head["video"]
    if video != f"{scan_name(index)}.avi":
        raise RecordingError(f"{journal}: line 1: video: expected {scan_name(index)}.avi")
    sidecar = {"format": SCAN_FORMAT, "index": index, "video": video, "complete": False,
               "stamp": head["stamp"], "exposure": head["exposure"], "frame_times": [],
               "motor_log": []}
    for number_, entry in enumerate(entries[1:], start=2):
        if isinstance(entry, dict) and entry.keys() == {"t"}:
            sidecar["frame_times"].append(entry["t"])
        elif isinstance(entry, dict) and entry.keys() == {"motor"}:
            sidecar["motor_log"].append(entry["motor"])
        else:
            raise RecordingError(f"{journal}: line {number_}: expected {{\"t\": time}} or "
                                 f"{{\"motor\": command}}")
    partial = folder / (video + PARTIAL_SUFFIX)
    name = partial.name if partial.is_file() else video
    entry = {"index": index, "video": name, "sidecar": journal.name,
             "frames": len(sidecar["frame_times"])}
    record = _check_sidecar(folder, entry, sidecar | {"video": name}, str(journal),
                            str(journal))
    return replace(record, recovered=True)


def _read_sidecar(folder: Path, entry: dict, where: str) -> ScanRecord:
    integer(entry["index"], f"{where}.index", RecordingError, low=0)
    for key in ("video", "sidecar"):
        name = entry[key]
        if not isinstance(name, str) or Path(name).name != name:
            raise RecordingError(f"{where}.{key}: expected a file name in the folder, "
                                 f"got {name!r}")
    path = folder / entry["sidecar"]
    return _check_sidecar(folder, entry, read_json(path, RecordingError), str(path), where)


def _check_sidecar(folder: Path, entry: dict, data: Any, side: str, where: str
                   ) -> ScanRecord:
    """Validate a scan's sidecar `data` (read from `side`) against its index `entry`."""
    path = Path(side)
    index = entry["index"]
    top = check_keys(data, side, RecordingError,
                     ["format", "index", "video", "stamp", "frame_times", "motor_log"],
                     ["complete", "exposure", "odometry"])
    if top["format"] != SCAN_FORMAT:
        raise RecordingError(f"{side}: format: expected {SCAN_FORMAT!r}, got {top['format']!r}")
    if integer(top["index"], f"{side}: index", RecordingError) != index:
        raise RecordingError(f"{side}: index: expected {index} as in {INDEX_NAME}")
    if top["video"] != entry["video"]:
        raise RecordingError(f"{side}: video: expected {entry['video']!r} as in {INDEX_NAME}")
    video = folder / entry["video"]
    if not video.is_file():
        raise RecordingError(f"{video}: video file not found")
    times = top["frame_times"]
    if not isinstance(times, list):
        raise RecordingError(f"{side}: frame_times: expected a list of times")
    frame_times = np.array([number(t, f"{side}: frame_times[{i}]", RecordingError)
                            for i, t in enumerate(times)])
    if np.any(np.diff(frame_times) <= 0.0):
        raise RecordingError(f"{side}: frame_times: expected increasing times")
    if integer(entry["frames"], f"{where}.frames", RecordingError) != frame_times.shape[0]:
        raise RecordingError(f"{side}: frame_times: {frame_times.shape[0]} times, "
                             f"{INDEX_NAME} says {entry['frames']} frames")
    if not isinstance(top["motor_log"], list):
        raise RecordingError(f"{side}: motor_log: expected a list")
    log = []
    for i, item in enumerate(top["motor_log"]):
        if not isinstance(item, dict) or "t" not in item or "command" not in item:
            raise RecordingError(f"{side}: motor_log[{i}]: expected an object with t and "
                                 f"command")
        number(item["t"], f"{side}: motor_log[{i}].t", RecordingError)
        log.append(dict(item))
    exposure = top.get("exposure")
    if exposure is not None:
        exposure = number(exposure, f"{side}: exposure", RecordingError, low=0.0)
    odometry = top.get("odometry")
    start = end = None
    if odometry is not None:
        odo = check_keys(odometry, f"{side}: odometry", RecordingError, ["start", "end"])
        start = vector(odo["start"], 3, f"{side}: odometry.start", RecordingError)
        end = vector(odo["end"], 3, f"{side}: odometry.end", RecordingError)
    complete = top.get("complete", True)
    if not isinstance(complete, bool):
        raise RecordingError(f"{side}: complete: expected true or false")
    return ScanRecord(index, video, path, complete,
                      number(top["stamp"], f"{side}: stamp", RecordingError), exposure,
                      frame_times, tuple(log), start, end)


# -- Writing ------------------------------------------------------------------------------

class ScanWriter:
    """Collects one scan: frames (JPEG bytes or BGR images) with times, the motor log and
    odometry. Use it as a context manager from `RecordingWriter.scan`.

    Every frame reaches the partial video and the journal before `add_jpeg` returns, so a
    recorder killed mid-scan keeps it (module docstring)."""

    def __init__(self, owner: RecordingWriter, index: int, stamp: float,
                 exposure: float | None) -> None:
        self._owner = owner
        self.index = index
        self.stamp = float(stamp)
        self.exposure = exposure
        self.frame_times: list[float] = []
        self.motor_log: list[dict] = []
        self.odometry: tuple[np.ndarray, np.ndarray] | None = None
        name = scan_name(index)
        self.video = owner.path / f"{name}.avi"
        self.sidecar = owner.path / f"{name}.json"
        self._partial = owner.path / f"{name}.avi{PARTIAL_SUFFIX}"
        self._journal_path = owner.path / f"{name}{JOURNAL_SUFFIX}"
        self._stream = open(self._partial, "wb")
        self._journal = open(self._journal_path, "w")
        cam = owner.model.camera
        self._avi = AviWriter(self._stream, cam.width, cam.height, cam.frame_rate)
        self._stream.flush()
        self._note({"format": JOURNAL_FORMAT, "index": index, "video": self.video.name,
                    "stamp": self.stamp, "exposure": exposure})

    def _note(self, entry: dict) -> None:
        """Append one line to the journal and hand it to the OS (a kill keeps it)."""
        self._journal.write(json.dumps(entry) + "\n")
        self._journal.flush()

    def add_jpeg(self, jpeg: bytes, time: float) -> None:
        """One frame as the camera's JPEG bytes (kept byte for byte)."""
        if not math.isfinite(time) or (self.frame_times and not time > self.frame_times[-1]):
            raise RecordingError(f"{self.video}: frame time {time} is not finite or does not "
                                 f"increase")
        self._avi.write(jpeg)
        self._stream.flush()
        self.frame_times.append(float(time))
        self._note({"t": float(time)})

    def add_image(self, image: np.ndarray, time: float,
                  quality: int = DEFAULT_JPEG_QUALITY) -> None:
        """One frame as a BGR image (encoded to JPEG: use `add_jpeg` when you have them)."""
        ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise RecordingError(f"{self.video}: OpenCV could not encode frame "
                                 f"{len(self.frame_times)}")
        self.add_jpeg(data.tobytes(), time)

    def log_motor(self, time: float, command: str, **fields: Any) -> None:
        """Record a motor command at a recording time."""
        entry = {"t": float(time), "command": command, **fields}
        self.motor_log.append(entry)
        self._note({"motor": entry})

    def set_odometry(self, start: np.ndarray, end: np.ndarray) -> None:
        """Odometry (x, y, yaw) of `base_link` in `odom` at the first and last frame."""
        self.odometry = (np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64))

    def __enter__(self) -> ScanWriter:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        """Finish the video and the sidecar, also after a fault (then complete: false);
        the journal goes once the index lists the scan."""
        self._avi.close()
        self._stream.close()
        publish(self._partial, self.video)
        sidecar = {
            "format": SCAN_FORMAT, "index": self.index, "video": self.video.name,
            "complete": kind is None, "stamp": self.stamp, "exposure": self.exposure,
            "frame_times": self.frame_times, "motor_log": self.motor_log,
            "odometry": None if self.odometry is None else {
                "start": [float(x) for x in self.odometry[0]],
                "end": [float(x) for x in self.odometry[1]]},
        }
        write_json(self.sidecar, sidecar)
        self._owner._finished(self)
        self._journal.close()
        self._journal_path.unlink()
        fsync_folder(self._owner.path)


class RecordingWriter:
    """Writes a recording folder scan by scan; the index is up to date after every scan."""

    def __init__(self, path: str | os.PathLike[str], model: ScannerModel, source: str,
                 extra: dict | None = None) -> None:
        from . import __version__

        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        self.model = model
        self._index = {"format": FORMAT,
                       "software": {"name": "scanmap", "version": __version__},
                       "source": source, "scanner": model.to_dict(), "scans": [],
                       "extra": extra or {}}
        write_json(self.path / INDEX_NAME, self._index)

    def scan(self, stamp: float, exposure: float | None = None) -> ScanWriter:
        """Start the next scan (numbered in order)."""
        return ScanWriter(self, len(self._index["scans"]), stamp, exposure)

    def _finished(self, scan: ScanWriter) -> None:
        self._index["scans"].append({"index": scan.index, "video": scan.video.name,
                                     "sidecar": scan.sidecar.name,
                                     "frames": len(scan.frame_times)})
        write_json(self.path / INDEX_NAME, self._index)
