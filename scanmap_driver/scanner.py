"""The scanning loop: camera + motor controller -> one `Scan` per 360 deg sweep.

One scan (the paper's reciprocating motion): start taking frames, start the motor, decode
the heading of each frame as it comes and turn the frame into points, stop when the
headings cover 360 deg plus a small overlap, stop taking frames, and turn the head back to
where it started. With `continuous=True` the head keeps turning one way instead.

The loop depends on small injected parts, so any camera, decoder and laser pipeline plugs
in: a `Camera`, `decode_heading(frame) -> heading (rad) or None` (the encoder disk's:
`heading_decoder.encoder_headings`), and a factory of `Assembler`s, which take a scan's
frames one by one (returning each frame's heading) and build the `Scan` at the end:
`assembly.ScanAssembler`, the offline path's own, so a live scan and its recording
processed later (`scanmap process`) give the same points. Without an assembler the loop
only takes frames and headings (`scanmap record`). A grabber thread
(`frame_grabber.FrameGrabber`) reads the camera all the time into a bounded buffer, so a
slow consumer never blocks the camera. Scans back to back in a background thread:
`continuous_scanning.ContinuousScanning`; a scan into a raw recording:
`live_recording.write_scan`.

Faults are handled, not hidden: a stall (headings stop advancing while the motor is
driven, or the encoder disk is unreadable), a camera that stops delivering, a motor
controller that vanishes or resets, a scan over its time limit, Ctrl-C. In each case the
motor is braked first, then the frames stop, the partial data is kept
(`ScanFailed.result`, `Scanner.last_result`), and the error says what happened and when
(seconds into the scan).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .camera import Camera, CameraFrame
from .errors import DeviceError, ScanError
from .frame_grabber import FrameGrabber
from .heading_decoder import HeadingDecoder
from .heading_tracker import HeadingTracker
from .motor import MotorController
from .scan import Scan

log = logging.getLogger(__name__)

Odometry = Callable[[float], np.ndarray]


class Assembler(Protocol):
    """Builds one scan from its frames (`assembly.ScanAssembler` is one)."""

    def add_frame(self, image: np.ndarray, timestamp: float) -> float | None:
        """Take a frame; return its heading (rad), None when the encoder is unreadable."""

    def finish(self, index: int = 0, odom_start: np.ndarray | None = None,
               odom_end: np.ndarray | None = None) -> tuple[Scan, Any]:
        """The scan of the frames taken, and a summary of what went into it."""


@dataclass(frozen=True)
class ScanConfig:
    """How to drive one scan.

    speed: motor speed (per mille) while scanning (720: about 1.8 s per revolution on the
    reference DC motor); direction: "CCW" (heading grows) or "CW".
    overlap: extra turn beyond 360 deg (rad). continuous: keep turning one way instead of
    returning the head to its start after each scan.
    time_limit: longest sweep (s). frame_timeout: longest wait for a frame (s).
    stall_time, stall_angle: the heading must advance stall_angle (rad) within every
    stall_time (s) while the motor is driven. status_interval: seconds between STATUS
    polls (the motor log). return_speed, return_time_limit: the move back to the start;
    brake_lead: how long (s) the head keeps its speed once braked, to time the brake.
    keep_frames: keep every frame (image and JPEG) in the result, for a recording.
    buffer_frames: frames the grabber holds before it drops the oldest.
    """

    speed: int = 720
    direction: str = "CCW"
    overlap: float = math.radians(10.0)
    continuous: bool = False
    time_limit: float = 8.0
    frame_timeout: float = 1.0
    stall_time: float = 1.0
    stall_angle: float = math.radians(5.0)
    status_interval: float = 0.25
    return_speed: int = 800
    brake_lead: float = 0.04
    return_time_limit: float = 8.0
    keep_frames: bool = False
    buffer_frames: int = 100

    def __post_init__(self) -> None:
        if self.direction not in ("CCW", "CW"):
            raise ValueError(f"direction: expected 'CCW' or 'CW', got {self.direction!r}")
        for name in ("time_limit", "frame_timeout", "stall_time", "status_interval",
                     "return_time_limit"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected > 0 s, got {getattr(self, name)}")

    @property
    def sign(self) -> float:
        """+1 when the heading grows during the sweep, -1 when it shrinks."""
        return 1.0 if self.direction == "CCW" else -1.0


@dataclass
class ScanResult:
    """Everything one sweep produced, complete or partial.

    scan: the points; summary: the assembler's account of them (None without one).
    frames: every frame (when ScanConfig.keep_frames). frame_times,
    headings: per frame taken (heading NaN where undecoded). coverage: heading swept (rad).
    motor_log: what was sent to the motor controller and its STATUS replies, as dicts with
    "t" (monotonic s), "command" ("run", "brake", "status") and "duty" (-1..1, CCW
    positive) or the status fields; the recording's motor log. dropped_frames: frames the
    camera lost; overflow_frames: frames the grabber dropped because the loop fell behind.
    fault: None, or why the sweep ended early (the ScanFailed reason).
    """

    scan: Scan
    summary: Any = None
    frames: list[CameraFrame] = field(default_factory=list)
    frame_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    headings: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coverage: float = 0.0
    motor_log: list[dict] = field(default_factory=list)
    dropped_frames: int = 0
    overflow_frames: int = 0
    undecoded_frames: int = 0
    duration: float = 0.0
    fault: str | None = None


class ScanFailed(DeviceError):
    """A scan ended by a fault; the motor was stopped first.

    reason: "stall", "camera", "motor", "time_limit", "return" (the scan is complete but
    the head did not get back) or "cancelled"; result: the partial data.
    """

    def __init__(self, reason: str, message: str, result: ScanResult) -> None:
        super().__init__(message)
        self.reason = reason
        self.result = result


@dataclass(frozen=True)
class Progress:
    """Where a scan is, for a progress display."""

    index: int
    phase: str
    coverage: float
    target: float
    frames: int
    dropped_frames: int
    elapsed: float


# -- the scanner ---------------------------------------------------------------------------

class _Sweep:
    """Data gathered during one sweep."""

    def __init__(self, settings: ScanConfig, assembler: Assembler | None) -> None:
        self.settings = settings
        self.assembler = assembler
        self.tracker = HeadingTracker(settings.sign)
        self.frames: list[CameraFrame] = []
        self.times: list[float] = []
        self.headings: list[float] = []
        self.motor_log: list[dict] = []
        self.undecoded = 0
        self.started = time.monotonic()
        self.dropped_at_start = 0
        self.overflow_at_start = 0
        self.resets_at_start = 0


class Scanner:
    """Drives the camera and the motor controller to take scans.

    new_assembler: makes the Assembler of each scan; None takes frames and headings only
    (for `scanmap record`).
    odometry: odometry(t) -> 4x4 pose of base_link in odom, for the scan's start and end.
    on_progress: called after each frame with a `Progress`.
    """

    def __init__(self, camera: Camera, motor: MotorController, decode_heading: HeadingDecoder,
                 new_assembler: Callable[[], Assembler] | None = None,
                 settings: ScanConfig | None = None,
                 *, odometry: Odometry | None = None,
                 on_progress: Callable[[Progress], None] | None = None) -> None:
        self.camera = camera
        self.motor = motor
        self.decode_heading = decode_heading
        self.new_assembler = new_assembler
        self.settings = settings or ScanConfig()
        self.odometry = odometry
        self.on_progress = on_progress
        self.last_result: ScanResult | None = None
        self._grabber: FrameGrabber | None = None
        self._index = 0
        self._cancel: threading.Event | None = None

    def __enter__(self) -> Scanner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Brake the motor and stop reading the camera (camera and motor stay open)."""
        self.motor.stop_safely()
        if self._grabber is not None:
            self._grabber.stop()
            self._grabber = None

    def scan(self, index: int | None = None, keep_running: bool = False,
             cancel: threading.Event | None = None) -> ScanResult:
        """Take one scan. Raises ScanFailed (a DeviceError) with the partial data on a fault;
        on Ctrl-C the motor is braked and KeyboardInterrupt goes on (data in last_result).

        keep_running: leave the motor turning after the sweep (continuous scanning).
        cancel: when set (by another thread), the scan ends at the next frame with
        ScanFailed("cancelled") and the motor braked.
        """
        self._cancel = cancel
        self._index = self._index if index is None else index
        grabber = self._start_capture()
        sweep = _Sweep(self.settings, self.new_assembler() if self.new_assembler else None)
        sweep.dropped_at_start = self.camera.dropped_frames
        sweep.overflow_at_start = grabber.overflow
        sweep.resets_at_start = self.motor.resets
        result = None
        try:
            self._sweep(sweep, grabber)
            result = self.last_result = self._result(sweep, grabber, None)
            if not (self.settings.continuous and keep_running):
                self._motor(sweep, grabber, "brake", result=result)
            if not self.settings.continuous:
                self._return_to_start(sweep, grabber, result)
        except ScanFailed:
            raise
        except BaseException:  # Ctrl-C, a decoder or processor error: motor first
            self._stop_motor(sweep)
            if result is None:
                self.last_result = self._result(sweep, grabber, "interrupted")
            raise
        finally:
            self._index += 1
        return result

    # -- phases ------------------------------------------------------------------------
    def _start_capture(self) -> FrameGrabber:
        if self._grabber is None:
            self._grabber = FrameGrabber(self.camera, self.settings.buffer_frames)
        self._grabber.discard()
        return self._grabber

    def _sweep(self, sweep: _Sweep, grabber: FrameGrabber) -> None:
        s = self.settings
        target = 2.0 * math.pi + s.overlap
        driven_since: float | None = None
        next_status = 0.0
        while sweep.tracker.progress < target:
            now = time.monotonic()
            if now >= next_status:
                self._motor(sweep, grabber, "status")
                next_status = now + s.status_interval
            frame = self._next_frame(sweep, grabber)
            self._take(sweep, frame)
            if driven_since is None and sweep.tracker.start is not None:
                self._motor(sweep, grabber, "run", s.direction, s.speed)
                driven_since = time.monotonic()
            elif driven_since is None and now - sweep.started > s.stall_time:
                raise self._fail(sweep, grabber, "stall",
                                 f"no heading decoded in {s.stall_time:.1f} s before the "
                                 "motor started (encoder disk not visible?)")
            if driven_since is not None:
                self._check_sweep(sweep, grabber, driven_since)
            self._report("sweep", sweep, grabber, target)

    def _next_frame(self, sweep: _Sweep, grabber: FrameGrabber, result: ScanResult | None = None
                    ) -> CameraFrame:
        """The next frame, or ScanFailed("camera") when the camera failed or fell silent
        (ScanFailed("cancelled") when the scan was cancelled)."""
        if self._cancel is not None and self._cancel.is_set():
            raise self._fail(sweep, grabber, "cancelled", "cancelled", result)
        timeout = self.settings.frame_timeout
        try:
            frame = grabber.get(timeout)
        except DeviceError as exc:
            raise self._fail(sweep, grabber, "camera", str(exc), result) from exc
        if frame is None:
            raise self._fail(sweep, grabber, "camera",
                             f"the camera delivered no frame for {timeout:.1f} s "
                             f"(after {len(sweep.times)} frames of this scan)", result)
        return frame

    def _motor(self, sweep: _Sweep, grabber: FrameGrabber, command: str, *args: Any,
               result: ScanResult | None = None) -> None:
        """Send "run" (direction, speed), "brake" or "status" to the motor controller and
        log it; a failure (or a fault the controller reports) becomes ScanFailed("motor")."""
        try:
            if command == "status":
                status = self.motor.status()
                sweep.motor_log.append({
                    "t": status.host_time, "command": "status", "state": status.state,
                    "direction": status.direction, "speed": status.speed,
                    "target": status.target, "faults": list(status.faults)})
                if status.faults:
                    raise DeviceError("the motor controller reports fault(s) "
                                      f"{','.join(status.faults)}")
                if self.motor.resets != sweep.resets_at_start:
                    raise DeviceError("the motor controller reset (it announced BOOT): it "
                                      f"stopped the motor and forgot the scan; now {status.state}")
                return
            getattr(self.motor, command)(*args)
        except DeviceError as exc:
            raise self._fail(sweep, grabber, "motor", str(exc), result) from exc
        entry: dict[str, Any] = {"t": time.monotonic(), "command": command, "duty": 0.0}
        if command == "run":
            direction, speed = args
            entry["duty"] = (1.0 if direction == "CCW" else -1.0) * speed / 1000.0
        sweep.motor_log.append(entry)

    def _stop_motor(self, sweep: _Sweep) -> str | None:
        """Brake whatever the state of the link; log it; return why it failed, if it did."""
        error = self.motor.stop_safely()
        sweep.motor_log.append({"t": time.monotonic(), "command": "brake", "duty": 0.0,
                                "ok": error is None})
        return error

    def _take(self, sweep: _Sweep, frame: CameraFrame) -> None:
        """Decode, track and assemble one frame of the sweep."""
        if sweep.assembler is None:
            heading = self.decode_heading(frame)
        else:
            heading = sweep.assembler.add_frame(frame.image, frame.timestamp)
        if heading is not None and not math.isfinite(heading):
            heading = None
        if heading is not None and not sweep.tracker.update(frame.timestamp, heading):
            heading = None
        if self.settings.keep_frames:
            sweep.frames.append(frame)
        sweep.times.append(frame.timestamp)
        sweep.headings.append(math.nan if heading is None else heading)
        if heading is None:
            sweep.undecoded += 1

    def _check_sweep(self, sweep: _Sweep, grabber: FrameGrabber, driven_since: float) -> None:
        s = self.settings
        now = time.monotonic()
        if now - driven_since > s.time_limit:
            raise self._fail(sweep, grabber, "time_limit",
                             f"the scan exceeded its {s.time_limit:.1f} s time limit at "
                             f"{math.degrees(sweep.tracker.progress):.0f} deg")
        if now - driven_since < s.stall_time:
            return
        advance = sweep.tracker.advance_within(s.stall_time, now)
        if advance is None:  # nothing decoded for a whole window
            advance = 0.0 if now - sweep.tracker.time > s.stall_time else None
        if advance is not None and advance < s.stall_angle:
            why = ("no heading decoded" if now - sweep.tracker.time > s.stall_time else
                   f"the heading advanced only {math.degrees(advance):.1f} deg")
            raise self._fail(sweep, grabber, "stall",
                             f"stall: {why} in {s.stall_time:.1f} s while the motor was "
                             f"driven at {s.speed} (at {math.degrees(sweep.tracker.progress):.0f}"
                             " deg of the scan)")

    def _return_to_start(self, sweep: _Sweep, grabber: FrameGrabber,
                         result: ScanResult) -> None:
        """Turn the head back until the decoded heading is at the scan's start again.

        Frames come every 40 ms, so the brake is timed by extrapolating the last heading at
        the tracked speed, minus the distance the head coasts while braking (brake_lead).
        """
        s = self.settings
        tracker = sweep.tracker
        back = "CW" if s.direction == "CCW" else "CCW"
        time.sleep(0.1)  # let the brake settle before reversing
        grabber.discard()
        started = time.monotonic()
        self._motor(sweep, grabber, "run", back, s.return_speed, result=result)
        while True:
            speed = max(-s.sign * tracker.speed, 0.0)  # progress lost per second
            if speed > 0.0:
                brake_at = tracker.time + (tracker.progress - speed * s.brake_lead) / speed
                wait = brake_at - time.monotonic()
                if wait < 1.5 / self.camera.frame_rate:
                    time.sleep(max(wait, 0.0))
                    break
            if time.monotonic() - started > s.return_time_limit:
                raise self._fail(sweep, grabber, "return",
                                 f"the head did not return to its start within "
                                 f"{s.return_time_limit:.1f} s", result)
            frame = self._next_frame(sweep, grabber, result)
            heading = self.decode_heading(frame)
            if heading is not None and math.isfinite(heading):
                tracker.update(frame.timestamp, heading)
            self._report("return", sweep, grabber, 0.0)
        self._motor(sweep, grabber, "brake", result=result)

    # -- results and faults ------------------------------------------------------------
    def _fail(self, sweep: _Sweep, grabber: FrameGrabber, reason: str, message: str,
              result: ScanResult | None = None) -> ScanFailed:
        """Brake the motor FIRST, then keep the partial data, then describe the fault."""
        stop_error = self._stop_motor(sweep)
        if result is None:
            result = self._result(sweep, grabber, reason)
        else:
            result.fault = reason
        self.last_result = result
        note = f"; braking failed too ({stop_error})" if stop_error else "; motor braked"
        when = f" (at {time.monotonic() - sweep.started:.2f} s into the scan)"
        log.error("scan %d: %s%s%s", self._index, message, when, note)
        return ScanFailed(reason, f"scan {self._index}: {message}{when}{note}; "
                                  f"{len(result.scan)} points of {len(sweep.times)} frames kept",
                          result)

    def _result(self, sweep: _Sweep, grabber: FrameGrabber, fault: str | None) -> ScanResult:
        scan, summary = self._assemble(sweep, fault)
        return ScanResult(
            scan=scan, summary=summary, frames=list(sweep.frames),
            frame_times=np.array(sweep.times), headings=np.array(sweep.headings),
            coverage=sweep.tracker.progress, motor_log=list(sweep.motor_log),
            dropped_frames=self.camera.dropped_frames - sweep.dropped_at_start,
            overflow_frames=grabber.overflow - sweep.overflow_at_start,
            undecoded_frames=sweep.undecoded, duration=time.monotonic() - sweep.started,
            fault=fault)

    def _assemble(self, sweep: _Sweep, fault: str | None) -> tuple[Scan, Any]:
        """The assembler's scan, with the odometry at the first and last frame."""
        stamp = sweep.times[0] if sweep.times else sweep.started
        if sweep.assembler is None or not sweep.times:
            return Scan.empty(index=self._index, stamp=stamp), None
        poses: dict[str, np.ndarray] = {}
        if self.odometry is not None:
            poses = {"odom_start": self.odometry(sweep.times[0]),
                     "odom_end": self.odometry(sweep.times[-1])}
        try:
            return sweep.assembler.finish(self._index, **poses)
        except ScanError as exc:
            if fault is None:
                raise
            log.warning("scan %d: the partial data gives no points (%s)", self._index, exc)
            return Scan.empty(index=self._index, stamp=stamp), None

    def _report(self, phase: str, sweep: _Sweep, grabber: FrameGrabber, target: float) -> None:
        if self.on_progress is None:
            return
        self.on_progress(Progress(
            index=self._index, phase=phase, coverage=sweep.tracker.progress, target=target,
            frames=len(sweep.times),
            dropped_frames=self.camera.dropped_frames - sweep.dropped_at_start
            + grabber.overflow - sweep.overflow_at_start,
            elapsed=time.monotonic() - sweep.started))
