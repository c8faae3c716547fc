"""`scanmap calibrate TARGET ...`: calibrate a part of the scanner into a scanner model file.

Each target is a subcommand of its own (`camera`: intrinsics from board images; `wall`:
the paper's wall calibration from a recorded scan), added in `register` beside the
others. They all write a `scanmap.scanner/1` file: an existing one is updated in place
(only the calibrated part changes), otherwise a new one is made from the reference scanner
with the calibrated part. `camera` also writes the intrinsics with their reprojection
errors (overall and per image) as an OpenCV calibration YAML beside it (`opencv_sidecar`):
the scanner model has no place for them.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from scanmap_driver import CalibrationError, ScannerModel, reference_scanner
from scanmap_driver.files import read_json
from scanmap_driver.scanner_model import FORMAT


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `calibrate` and its targets."""
    parser = subparsers.add_parser(
        "calibrate", help="calibrate the scanner (camera intrinsics, ...)",
        description="Calibrate a part of the scanner and write it into a scanner model "
                    f"file ({FORMAT}).")
    parser.set_defaults(func=lambda _args: _print_help(parser))
    targets = parser.add_subparsers(dest="target", metavar="TARGET")
    _register_camera(targets)
    _register_wall(targets)


def _print_help(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _register_camera(targets: argparse._SubParsersAction) -> None:
    parser = targets.add_parser(
        "camera", help="camera intrinsics from images of a ChArUco board or chessboard",
        description="Camera intrinsics (focal lengths, principal point, distortion) from "
                    "images of a calibration board. Tilt the board by 20-45 deg, in a "
                    "different direction in each image.")
    parser.add_argument("images", nargs="+", metavar="IMAGES", help="board images")
    parser.add_argument("--board", required=True, choices=["charuco", "chessboard"])
    parser.add_argument("--squares", required=True, type=_squares, metavar="COLSxROWS",
                        help="board size in squares, e.g. 5x7 (a chessboard of 12x7 "
                             "squares has 11x6 inner corners)")
    parser.add_argument("--square-size", required=True, type=float, metavar="M",
                        help="side of a square (m)")
    parser.add_argument("--marker-size", type=float, metavar="M",
                        help="side of a ChArUco marker (m); required with --board charuco")
    parser.add_argument("--dictionary", default="DICT_6X6_250",
                        help="ArUco dictionary of a ChArUco board (default DICT_6X6_250)")
    parser.add_argument("--legacy", action="store_true",
                        help="ChArUco board in the layout of OpenCV < 4.6 (matters only for "
                             "an even number of rows)")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE",
                        help=f"scanner model ({FORMAT}) to update or create; the OpenCV "
                             "calibration YAML with the reprojection errors goes beside it "
                             "(FILE's stem + .camera.yaml)")
    parser.set_defaults(func=_camera)


def _squares(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS such as 5x7, got {text!r}")
    return int(match[1]), int(match[2])


def _camera(args: argparse.Namespace) -> int:
    # The calibration package brings scipy.optimize (0.2 s): loaded when calibrating.
    from scanmap_driver.calibration import (
        CharucoBoard,
        Chessboard,
        calibrate_camera,
        write_opencv_yaml,
    )

    if args.board == "charuco":
        if args.marker_size is None:
            raise CalibrationError("--marker-size: required with --board charuco")
        board = CharucoBoard(args.squares, args.square_size, args.marker_size,
                             args.dictionary, args.legacy)
    else:
        board = Chessboard(args.squares, args.square_size)
    model, existing = _target_model(args.out)
    result = calibrate_camera(args.images, board, frame_rate=model.camera.frame_rate)
    cam, (sfx, sfy, scx, scy) = result.camera, result.sigma
    print(f"calibrated from {result.image_count} of {len(args.images)} images "
          f"({cam.width}x{cam.height}), reprojection error {result.rms:.3f} px rms")
    print(f"  fx {cam.fx:.2f} +- {sfx:.2f}  fy {cam.fy:.2f} +- {sfy:.2f}  "
          f"cx {cam.cx:.2f} +- {scx:.2f}  cy {cam.cy:.2f} +- {scy:.2f} px")
    print("  distortion (k1 k2 p1 p2 k3) " + " ".join(f"{d:.5g}" for d in cam.distortion))
    for name, rms in zip(result.images, result.per_image_rms, strict=True):
        print(f"  {name}: {rms:.3f} px")
    for rejected in result.rejected:
        print(f"  rejected {rejected.name}: {rejected.reason}")
    model.with_changes(camera=cam).save(args.out)
    sidecar = opencv_sidecar(args.out)
    write_opencv_yaml(result, sidecar)
    print(f"wrote the OpenCV calibration (with the reprojection errors) to {sidecar}")
    if existing:
        print(f"updated the camera of the scanner model {args.out}")
    else:
        print(f"wrote {args.out}: the reference scanner with this camera (calibrate the "
              "rest of the geometry before scanning)")
    return 0


def opencv_sidecar(out: Path) -> Path:
    """The OpenCV YAML written beside the scanner model `out` (scanner.json ->
    scanner.camera.yaml)."""
    return out.with_suffix(".camera.yaml")


def _target_model(path: Path) -> tuple[ScannerModel, bool]:
    """The model to update: the existing file's (validated), else the reference scanner."""
    if not path.exists():
        return reference_scanner(), False
    data = read_json(path, CalibrationError)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CalibrationError(
            f"{path}: exists and is not a scanner model ({FORMAT}); not overwriting it")
    return ScannerModel.from_dict(data, source=str(path)), True


def _register_wall(targets: argparse._SubParsersAction) -> None:
    parser = targets.add_parser(
        "wall", help="laser plane, camera tilt, separation and encoder zero from wall scans",
        description="The paper's calibration: scan a flat wall that the robot faces at a "
                    "measured distance; solve until the wall is vertical, flat and at that "
                    "distance. Two recordings, near and far, pin the camera tilt apart from "
                    "its height. Refuses to write what the data do not determine.")
    parser.add_argument("recordings", type=Path, nargs="+", metavar="RECORDING",
                        help="recording folder(s), each holding a wall scan")
    parser.add_argument("--distance", type=float, nargs="+", required=True, metavar="M",
                        help="distance from the scanner axis to the wall (m), one per "
                             "recording")
    parser.add_argument("--scanner", type=Path, default=None, metavar="FILE",
                        help="starting model (default: the first recording's own)")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE")
    parser.set_defaults(func=_wall)


def _wall(args: argparse.Namespace) -> int:
    from scanmap_driver.calibration.wall import calibrate_wall_recordings
    from scanmap_driver.recording import Recording

    if len(args.distance) != len(args.recordings):
        raise CalibrationError(f"calibrate wall: {len(args.recordings)} recordings but "
                               f"{len(args.distance)} distances")
    recordings = [Recording.open(path) for path in args.recordings]
    start = ScannerModel.load(args.scanner) if args.scanner else recordings[0].model
    result = calibrate_wall_recordings(recordings, args.distance, start)
    print(f"{result.wall_points} wall and {result.floor_points} floor points, "
          f"residual rms {result.rms * 1000:.1f} mm")
    for name, value in result.values.items():
        mark = "  (weakly determined)" if name in result.undetermined else ""
        print(f"  {name:20s} {value:+.5f} +- {result.sigmas[name]:.1e}{mark}")
    print("  point uncertainty (p95): " + ", ".join(
        f"{band}: {sigma * 1000:.1f} mm" for band, sigma in result.point_sigma.items()))
    for note in result.notes:
        print(f"  note: {note}")
    calibrated = result.require_supported()
    calibrated.save(args.out)
    print(f"wrote {args.out}")
    return 0
