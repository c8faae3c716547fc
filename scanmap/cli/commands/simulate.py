"""`scanmap simulate SCENE --out DIR`: a simulated raw recording with ground truth.

SCENE is a built-in scene (`corridor`, `office`) or a `scanmap.scene/1` file. The output
is a recording folder exactly as the scanner would record it (MJPG video and sidecar per
scan, `recording.json`) plus `ground_truth/`; with `--ideal`, processed scans cast
directly from the geometry (no images) instead. Deterministic for a seed.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from scanmap_driver import ScannerModel, reference_scanner
from scanmap_driver.sim import builtin_scene_names, resolve_scene
from scanmap_driver.sim.scene import LIGHTING


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `simulate`."""
    parser = subparsers.add_parser(
        "simulate", help="simulate a recording (frames + ground truth) in a scene",
        description="Render the frames the scanner's webcam would record while scanning a "
                    "scene, and write them as a raw recording with ground truth.")
    parser.add_argument("scene", metavar="SCENE",
                        help=f"built-in scene ({', '.join(builtin_scene_names())}) or a "
                             "scene file")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="recording folder to write")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--scans", type=int, default=None, metavar="N",
                        help="the first N scan poses of the scene (default all)")
    parser.add_argument("--lighting", choices=sorted(LIGHTING), default=None,
                        help="room light (default: the scene's ambient level)")
    parser.add_argument("--ideal", action="store_true",
                        help="write processed scans cast from the geometry, no images")
    parser.add_argument("--scanner", type=Path, default=None, metavar="FILE",
                        help="scanner model (default: the reference scanner)")
    parser.add_argument("--rolling-shutter", type=float, default=0.0, metavar="S",
                        help="read-out time from the first image row to the last (s)")
    parser.add_argument("--workers", type=int, default=2, help="render threads (default 2)")
    parser.set_defaults(func=_simulate)


def _simulate(args: argparse.Namespace) -> int:
    # The renderer needs Open3D (about 1 s to import): loaded only when simulating.
    from scanmap_driver.sim.camera_effects import SimCameraConfig
    from scanmap_driver.sim.simulate import lit_scene, simulate_ideal, simulate_recording

    scene = lit_scene(resolve_scene(args.scene), args.lighting)
    model = ScannerModel.load(args.scanner) if args.scanner else reference_scanner()
    start = time.perf_counter()
    if args.ideal:
        simulate_ideal(scene, args.out, model, seed=args.seed, scans=args.scans,
                       progress=print)
    else:
        simulate_recording(scene, args.out, model, seed=args.seed, scans=args.scans,
                           camera=SimCameraConfig(rolling_shutter=args.rolling_shutter),
                           workers=args.workers, progress=print)
    print(f"wrote {args.out} in {time.perf_counter() - start:.1f} s")
    return 0
