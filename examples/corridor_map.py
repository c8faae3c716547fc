"""Map the corridor recording and print a short report: the README's main command.

    .venv/bin/python examples/corridor_map.py

The recording (./data/corridor_recording) holds 20 scans of the simulator's built-in
corridor (1.5 m wide), 2 s each, as the webcam delivered them (MJPG) with the motor log,
odometry and ground truth. On a fresh machine it is simulated once and kept. The map
goes to ./data/corridor_map: map.npz, map.yaml + map.pgm, trajectory.tum, overhead.png,
occupancy.png and report.json, the same as `scanmap map data/corridor_recording --out
data/corridor_map`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sim_data import DATA, ensure_recording

from scanmap import MapUpdate, map_to_folder, report_text
from scanmap.cli import exit_without_collecting


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=DATA / "corridor_recording")
    parser.add_argument("--scans", type=int, default=20,
                        help="scans to simulate when the recording is missing (default 20)")
    parser.add_argument("--out", type=Path, default=DATA / "corridor_map")
    parser.add_argument("--workers", type=int, default=None,
                        help="threads assembling scans (default: one per CPU this process "
                             "may use) and simulator processes (default 2)")
    args = parser.parse_args(argv)

    recording = ensure_recording(args.recording, "corridor", args.scans, args.workers or 2)

    def progress(done: int, total: int, update: MapUpdate) -> None:
        pose = update.pose
        print(f"  scan {update.index}: {update.registration.status.value}, robot at "
              f"({pose[0, 3]:.2f}, {pose[1, 3]:.2f}) m ({done}/{total})")

    print(f"mapping {recording}")
    report = map_to_folder(recording, args.out, workers=args.workers, progress=progress)
    print(report_text(report))
    print(f"map: {args.out / 'overhead.png'}, {args.out / 'occupancy.png'}, "
          f"{args.out / 'map.yaml'}")
    return 0


if __name__ == "__main__":
    exit_without_collecting(main())
