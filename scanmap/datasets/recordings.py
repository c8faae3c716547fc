"""What the Mapper maps offline: a raw recording or a folder of processed scans, in order.

A raw recording (`recording.json`, videos) is assembled here, frames to scans, with the
driver's own pipeline (`processing.recording_scans`: JPEG decoding, laser extraction,
heading decoding, triangulation). Scans are independent, so `workers` threads assemble
several at once: OpenCV's decoder and the Numba kernels release the GIL, so the threads
use every core while the mapper consumes the scans in order. A folder of processed scans
(`scan_NNNN.npz`, as `scanmap process` or `scanmap simulate --ideal` write them) is read
in order.

Each scan comes with the wall and CPU seconds spent on it per stage ("decode": reading
and decoding the video; "extract": stripe, heading, triangulation, colour; "load": a
scan file), and, for a recording, the assembly summary and any error (a damaged video
keeps its good frames; a scan whose encoder disk was unreadable throughout comes as an
empty scan with the error).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

from scanmap.stage_clock import StageClock
from scanmap_driver.cpus import usable_cpus
from scanmap_driver.errors import RecordingError, ScanError
from scanmap_driver.processing import recording_scans
from scanmap_driver.recording import GROUND_TRUTH, INDEX_NAME, RecordedFrame, Recording, ScanRecord
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel, reference_scanner


@dataclass(frozen=True, eq=False)
class InputScan:
    """One scan of the input with what it cost per stage, its summary and error."""

    scan: Scan
    timing: StageClock
    summary: dict | None = None
    error: str | None = None


class _TimedRecording:
    """One scan of a recording whose frame decoding is timed (a `Recording` to
    `recording_scans`, which asks only for `model`, `scans` and `frames`)."""

    def __init__(self, recording: Recording, record: ScanRecord) -> None:
        self.model = recording.model
        self.scans = (record,)
        self._recording = recording
        self.decoding = StageClock()

    def frames(self, index: int) -> Iterator[RecordedFrame]:
        frames = self._recording.frames(index)
        while True:
            with self.decoding.stage("decode"):
                frame = next(frames, None)
            if frame is None:
                return
            yield frame


def assemble(recording: Recording, record: ScanRecord, model: ScannerModel) -> InputScan:
    """Scan `record` of `recording`, assembled with `model`, timed."""
    clock = StageClock()
    timed = _TimedRecording(recording, record)
    with clock.stage("extract"):
        try:
            scan, summary, error = next(recording_scans(timed, model))  # type: ignore[arg-type]
            summary_dict = summary.to_dict()
        except ScanError as exc:
            scan, summary_dict, error = Scan.empty(record.index, record.stamp), None, str(exc)
            scan = replace(scan, odom_start=record.odom_start, odom_end=record.odom_end)
    decode_wall = timed.decoding.wall.get("decode", 0.0)
    decode_cpu = timed.decoding.cpu.get("decode", 0.0)
    clock.add("extract", -decode_wall, -decode_cpu)  # the rest of the assembly
    clock.add("decode", decode_wall, decode_cpu)
    return InputScan(scan, clock, summary_dict, error)


class ScanSource:
    """The scans of INPUT in order (see the module docstring); iterate it once."""

    def __init__(self, path: Path, kind: str, model: ScannerModel, count: int,
                 recording: Recording | None, files: list[Path], workers: int) -> None:
        self.path = path
        self.kind = kind  # "recording" or "scans"
        self.model = model
        self.count = count
        self.recording = recording
        self._files = files
        self.workers = max(1, int(workers))

    @classmethod
    def open(cls, path: str | os.PathLike[str], model: ScannerModel | None = None,
             workers: int | None = None) -> ScanSource:
        """A recording folder (with `recording.json`) or a folder of `scan_NNNN.npz`.

        model: the scanner model (default: the recording's own; the reference scanner for
        scan files, which do not carry one). workers: threads assembling scans (default:
        one per CPU this process may use).
        """
        path = Path(path)
        workers = usable_cpus() if workers is None else workers
        if (path / INDEX_NAME).is_file():
            recording = Recording.open(path)
            if not recording.scans:  # stopped before its first turn: an IndexError later
                raise RecordingError(f"{path / INDEX_NAME}: lists no scans, nothing to map")
            return cls(path, "recording", model or recording.model, len(recording.scans),
                       recording, [], workers)
        files = sorted(path.glob("scan_*.npz")) if path.is_dir() else []
        if not files:
            raise RecordingError(f"{path}: neither a recording ({INDEX_NAME}) nor a folder of "
                                 "processed scans (scan_NNNN.npz)")
        return cls(path, "scans", model or reference_scanner(), len(files), None, files,
                   workers)

    @property
    def ground_truth(self) -> Path | None:
        """The input's `ground_truth/` folder (simulated input), else None."""
        folder = self.path / GROUND_TRUTH
        return folder if folder.is_dir() else None

    def sweep_seconds(self) -> float | None:
        """How long the recording's scans took to record: per scan, first to last frame
        plus one frame period, summed (None for scan files)."""
        if self.recording is None:
            return None
        period = 1.0 / self.model.camera.frame_rate
        return float(sum(r.frame_times[-1] - r.frame_times[0] + period
                         for r in self.recording.scans if r.frame_times.size))

    def __iter__(self) -> Iterator[InputScan]:
        if self.recording is None:
            yield from self._files_in_order()
        else:
            yield from self._assembled_in_order(self.recording)

    def _files_in_order(self) -> Iterator[InputScan]:
        for file in self._files:
            clock = StageClock()
            with clock.stage("load"):
                scan = Scan.load(file)
            yield InputScan(scan, clock)

    def _assembled_in_order(self, recording: Recording) -> Iterator[InputScan]:
        """Assemble `workers` scans at a time ahead of the consumer, yield them in order."""
        records = iter(recording.scans)
        with ThreadPoolExecutor(self.workers, thread_name_prefix="scanmap-assemble") as pool:
            pending: deque[Future] = deque()
            for record in records:
                pending.append(pool.submit(assemble, recording, record, self.model))
                if len(pending) > self.workers:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
