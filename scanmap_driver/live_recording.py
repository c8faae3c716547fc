"""Live scans into a raw recording: a `ScanResult` of the `Scanner` written with its
frames, motor log and odometry (`scanmap scan --record`, `scanmap record`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .transforms import pose_to_se2

if TYPE_CHECKING:
    from .recording import RecordingWriter
    from .scanner import ScanResult


class _Incomplete(Exception):
    """Ends a ScanWriter block so that the scan is marked incomplete."""


def write_scan(writer: RecordingWriter, result: ScanResult, origin: float,
               exposure: float | None = None) -> None:
    """Add a scan to a raw recording: its frames (the camera's JPEGs byte for byte when it
    delivered them), motor log and odometry. Times become seconds since `origin`
    (monotonic); a partial scan (result.fault) is marked incomplete."""
    runs = [e["t"] for e in result.motor_log if e["command"] == "run"]
    stamp = runs[0] if runs else (result.frame_times[0] if result.frame_times.size else origin)
    try:
        with writer.scan(stamp - origin, exposure) as out:
            for frame in result.frames:
                if frame.raw_jpeg is not None:
                    out.add_jpeg(frame.raw_jpeg, frame.timestamp - origin)
                else:
                    out.add_image(frame.image, frame.timestamp - origin)
            for entry in result.motor_log:
                extra = {k: v for k, v in entry.items() if k not in ("t", "command")}
                out.log_motor(entry["t"] - origin, entry["command"], **extra)
            if result.scan.has_odometry:
                out.set_odometry(pose_to_se2(result.scan.odom_start),
                                 pose_to_se2(result.scan.odom_end))
            if result.fault is not None:
                raise _Incomplete
    except _Incomplete:
        pass
