"""`scanmap scan`: take scans with the scanner (webcam + motor controller).

    scanmap scan --camera 0 --port /dev/ttyUSB0 [--out DIR] [--record DIR] [--continuous]

Each scan is written as `DIR/scan_NNNN.npz`; `--record` also keeps the raw recording
(the webcam's JPEGs byte for byte, frame times, motor log), which `scanmap process`
turns into the same scans later (the same `ScanAssembler`). A progress line shows the
heading swept, frames and drops. Ctrl-C brakes the motor and keeps what was taken.
`--simulate SCENE` runs it all without hardware.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from scanmap_driver import ScannerModel, reference_scanner
from scanmap_driver.camera import Camera
from scanmap_driver.scanner import Progress, ScanFailed, ScanResult

SLOW_MOTION = 5.0  # the simulator renders about 7 frames/s: run its world 5x slower


def add_device_arguments(parser: argparse.ArgumentParser) -> None:
    """Camera, controller, model and motion options shared by `scan` and `record`."""
    parser.add_argument("--camera", default="0", metavar="DEV",
                        help="V4L2 camera: index (0 for /dev/video0) or device path")
    parser.add_argument("--port", metavar="TTY", help="motor controller's serial port, "
                        "e.g. /dev/ttyUSB0 or /dev/ttyACM0")
    parser.add_argument("--scanner", type=Path, metavar="FILE",
                        help="scanner model (default: the reference scanner)")
    parser.add_argument("--scans", type=int, default=1, metavar="N",
                        help="number of scans (default 1; 0 with --continuous: until Ctrl-C)")
    parser.add_argument("--continuous", action="store_true",
                        help="scan back to back in a background thread")
    parser.add_argument("--rotation", choices=["reciprocating", "continuous"],
                        default="reciprocating",
                        help="turn back to the start after each scan (the paper's motion, "
                             "default) or keep turning one way (a slip ring)")
    parser.add_argument("--speed", type=int, default=720, metavar="PERMILLE",
                        help="motor speed while scanning, 0..1000 (default 720)")
    parser.add_argument("--direction", choices=["CCW", "CW"], default="CCW")
    parser.add_argument("--exposure", type=float, default=40, metavar="UNITS",
                        help="fixed exposure in V4L2 units of 100 us (default 40: 4 ms)")
    parser.add_argument("--simulate", metavar="SCENE",
                        help="no hardware: the simulated motor controller on a pseudo-"
                             "terminal and a webcam rendering SCENE (built-in name or file) "
                             f"at the first scan pose, {SLOW_MOTION:g} times slower than life")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `scan`."""
    parser = subparsers.add_parser(
        "scan", help="take 360 deg scans with the scanner (webcam + motor controller)",
        description="Drive the scanner (webcam and motor controller) and write each 360 deg "
                    "scan as .npz, and/or keep the raw recording (process it later with "
                    "`scanmap process`).")
    add_device_arguments(parser)
    parser.add_argument("--out", type=Path, metavar="DIR", help="write scan_NNNN.npz here")
    parser.add_argument("--record", type=Path, metavar="DIR",
                        help="also keep the raw recording in DIR")
    parser.add_argument("--ply", action="store_true", help="also write scan_NNNN.ply")
    parser.set_defaults(func=_scan)


def load_model(path: Path | None) -> ScannerModel:
    """The scanner model from a file, or the reference scanner."""
    return ScannerModel.load(path) if path else reference_scanner()


class ProgressLine:
    """One updating status line on stderr (a line per scan when stderr is not a terminal)."""

    def __init__(self) -> None:
        self.live = sys.stderr.isatty()
        self._last = 0.0

    def __call__(self, p: Progress) -> None:
        now = time.monotonic()
        if not self.live or now - self._last < 0.1:
            return
        self._last = now
        goal = f"/{math.degrees(p.target):.0f}" if p.phase == "sweep" else " to go"
        print(f"\rscan {p.index}: {p.phase} {math.degrees(p.coverage):4.0f}{goal} deg  "
              f"{p.frames} frames  {p.dropped_frames} dropped  {p.elapsed:4.1f} s ",
              end="", file=sys.stderr, flush=True)

    def done(self, result: ScanResult) -> None:
        """Summarise a finished (or failed) scan on its own line."""
        state = f"FAILED ({result.fault})" if result.fault else "done"
        start = "\r" if self.live else ""
        points = "" if result.summary is None else f"{len(result.scan)} points, "
        print(f"{start}scan {result.scan.index}: {state}, {points}"
              f"{len(result.frame_times)} frames, "
              f"{result.dropped_frames + result.overflow_frames} dropped, "
              f"{math.degrees(result.coverage):.0f} deg in {result.duration:.1f} s       ",
              file=sys.stderr)


def _scan(args: argparse.Namespace) -> int:
    if args.out is None and args.record is None:
        raise SystemExit("scanmap scan: give --out DIR and/or --record DIR")
    return run_device(args, process=True, on_scan=lambda r: _save(r.scan, args))


def _save(scan, args: argparse.Namespace) -> None:
    if args.out is None:
        return
    stem = args.out / f"scan_{scan.index:04d}"
    scan.save(stem.with_suffix(".npz"))
    if args.ply:
        scan.save_ply(stem.with_suffix(".ply"))


@contextlib.contextmanager
def open_devices(args: argparse.Namespace, model: ScannerModel
                 ) -> Iterator[tuple[Camera, str, float | None]]:
    """(camera, controller port, exposure in s) for the live scanner or the simulator."""
    from scanmap_driver.camera import CameraConfig, RenderedCamera, V4L2Camera

    if args.simulate is None:
        if args.port is None:
            raise SystemExit("scanmap: --port TTY is required (the motor controller)")
        device = int(args.camera) if args.camera.isdigit() else args.camera
        with V4L2Camera(device, CameraConfig(exposure=args.exposure)) as camera:
            yield camera, args.port, args.exposure * 1e-4
        return
    from scanmap_driver.sim import resolve_scene
    from scanmap_driver.sim.firmware import SimulatedFirmware, scene_renderer
    from scanmap_driver.sim.motor_model import MotorModelConfig
    from scanmap_driver.sim.render import Renderer

    scene = resolve_scene(args.simulate)
    renderer = Renderer(scene, model)
    motor = MotorModelConfig(full_speed=MotorModelConfig().full_speed / SLOW_MOTION)
    with SimulatedFirmware(motor) as firmware, \
            RenderedCamera(scene_renderer(renderer, firmware, scene.scan_poses[0]),
                           frame_rate=model.camera.frame_rate / SLOW_MOTION) as camera:
        yield camera, firmware.port, renderer.camera.exposure


def run_device(args: argparse.Namespace, process: bool, on_scan) -> int:
    """Open camera and controller, take the scans, record them if asked; shared by
    `scan` and `record`. Returns the exit code."""
    from scanmap_driver.continuous_scanning import ContinuousScanning
    from scanmap_driver.heading_decoder import encoder_headings
    from scanmap_driver.live_recording import write_scan
    from scanmap_driver.motor import MotorController
    from scanmap_driver.recording import RecordingWriter
    from scanmap_driver.scanner import ScanConfig, Scanner

    model = load_model(args.scanner)
    slow = SLOW_MOTION if args.simulate else 1.0
    settings = ScanConfig(speed=args.speed, direction=args.direction,
                            continuous=args.rotation == "continuous",
                            keep_frames=args.record is not None, time_limit=8.0 * slow,
                            return_time_limit=8.0 * slow, frame_timeout=1.0 * slow,
                            stall_time=1.0 * slow)
    assembler = None
    if process:
        from scanmap_driver.assembly import ScanAssembler

        def assembler() -> ScanAssembler:
            return ScanAssembler(model)
    progress = ProgressLine()
    origin = time.monotonic()
    with open_devices(args, model) as (camera, port, exposure), \
            MotorController.connect(port) as motor, \
            Scanner(camera, motor, encoder_headings(model), assembler, settings,
                    on_progress=progress) as scanner:
        writer = None if args.record is None else RecordingWriter(
            args.record, model, source="simulator" if args.simulate else "camera")

        def finished(result: ScanResult) -> None:
            progress.done(result)
            if writer is not None:
                write_scan(writer, result, origin, exposure)
            on_scan(result)

        try:
            if args.continuous:
                with ContinuousScanning(scanner) as scanning:
                    for taken, result in enumerate(scanning, start=1):
                        finished(result)
                        if args.scans and taken >= args.scans:
                            break
                    if scanning.dropped_scans:
                        print(f"{scanning.dropped_scans} scans dropped (processing fell "
                              "behind)", file=sys.stderr)
            else:
                for _ in range(args.scans):
                    finished(scanner.scan())
        except ScanFailed as exc:
            finished(exc.result)
            raise
        except KeyboardInterrupt:
            if scanner.last_result is not None and scanner.last_result.fault:
                finished(scanner.last_result)
            raise
    return 0
