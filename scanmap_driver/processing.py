"""Offline processing: a raw recording becomes processed scan files and a summary.

For each scan of the recording, in order: `scan_NNNN.npz` and `scan_NNNN.ply` (points in
`base_link`) and one `summary.json` for the run (frames, points, headings covered, lines
rejected and why). A damaged video keeps the scans and frames before the damage: the scan
is assembled from the good frames, marked incomplete, and the error is reported. A scan
whose recorder was killed mid-scan is recovered from its journal (`recording.py`) and
reported with the number of frames recovered.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

from .assembly import ScanAssembler, ScanSummary
from .errors import RecordingError
from .files import write_json
from .recording import Recording, scan_name
from .scan import Scan
from .scanner_model import ScannerModel


def recording_scans(recording: Recording, model: ScannerModel | None = None
                    ) -> Iterator[tuple[Scan, ScanSummary, str | None]]:
    """Assemble each scan of `recording`: (scan, summary, error message or None)."""
    model = model or recording.model
    for record in recording.scans:
        assembler = ScanAssembler(model)
        error = None
        try:
            for frame in recording.frames(record.index):
                assembler.add_frame(frame.image, frame.time)
        except RecordingError as exc:
            error = str(exc)
        if record.recovered and error is None:
            error = (f"{record.sidecar}: the recorder stopped mid-scan; recovered "
                     f"{record.frame_times.shape[0]} frames written before it stopped")
        scan, summary = assembler.finish(record.index, record.odom_start, record.odom_end)
        if error or not record.complete:
            summary.complete = False
        yield scan, summary, error


def save_processed_scan(scan: Scan, summary: ScanSummary, error: str | None, out: Path,
                        ply: bool = True) -> dict:
    """Write `scan_NNNN.npz` (and `.ply`) into `out`; returns its summary.json entry."""
    stem = scan_name(scan.index)
    scan.save(out / f"{stem}.npz")
    if ply:
        scan.save_ply(out / f"{stem}.ply")
    return summary.to_dict() | {"file": f"{stem}.npz", "error": error}


def process_recording(path: str | os.PathLike[str], out: str | os.PathLike[str], *,
                      model: ScannerModel | None = None, ply: bool = True,
                      progress: Callable[[str], None] | None = None) -> list[dict]:
    """Write the processed scans of the recording at `path` into `out`; returns summaries."""
    recording = Recording.open(path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summaries = []
    for scan, summary, error in recording_scans(recording, model):
        summaries.append(save_processed_scan(scan, summary, error, out, ply))
        write_json(out / "summary.json", {"recording": str(path), "scans": summaries})
        if progress:
            progress(f"scan {scan.index}: {summary.frames} frames, {summary.points} points, "
                     f"{summary.headings_covered_deg:.0f} deg covered"
                     + (f"; {error}" if error else ""))
    return summaries
