"""A reactive controller on scanmap's obstacle queries, polling at 100 Hz while the mapper maps.

    .venv/bin/python examples/controller.py [--recording DIR] [--speed 1]

The mapper runs in a background thread on a recording replayed at its recorded pace, as
the live scanner delivers scans (each when its sweep ends; --speed replays faster), and
publishes a new obstacle snapshot after every scan. The control loop, in the main
thread, asks `mapper.obstacles.nearest(x, y)` at the robot's newest pose 100 times a
second and commands a forward speed:

* full speed while the nearest obstacle is beyond --slow m, slowing linearly to zero
  at --stop m;
* the same law on the path ahead (`mapper.obstacles.travel`: how far the robot's circle
  can drive along its heading before it touches anything not known free), counting
  unknown space there as an obstacle, and at most --creep m/s when unknown space is
  what stops it (the scanner cannot see the floor near the robot: unknown is never free,
  so the robot enters it only creeping). Unknown space beside the path (the unlit strip
  at a wall's foot) does not slow it; obstacles beside it do;
* zero when the data are stale (the newest scan older than --max-age), the sensor is
  faulted, the pose is invalid (not finite or beyond the map's coordinate limit: a
  diverged filter), or no scan has arrived yet.

When the recording ends no new scans come, the data go stale and the robot stops. It
prints what it did and the latency percentiles of the `nearest` calls; the summary also
holds how far known free space reached (`clearance`) in the polls where unknown space
was nearer than any obstacle, in any direction (`unknown_nearer_than_obstacles`).
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from sim_data import DATA, ensure_recording

from scanmap import Mapper, MapperConfig, Nearest, QueryStatus, Scan, ScanSource, Travel
from scanmap_driver import write_json

RATE = 100.0  # Hz


@dataclass(frozen=True)
class Limits:
    """Speeds (m/s) and distances (m) of the control law."""

    top: float = 0.5
    creep: float = 0.1
    slow: float = 1.0
    stop: float = 0.3


HALTING = (QueryStatus.STALE, QueryStatus.FAULTED, QueryStatus.INVALID)  # answers that stop


def speed_command(nearest: Nearest, ahead: Travel, radius: float, limits: Limits
                  ) -> tuple[float, str]:
    """Forward speed (m/s) for a `nearest` answer and the free `ahead` travel of a robot
    of `radius` (m), and why."""
    for answer in (nearest, ahead):
        if answer.status in HALTING:
            return 0.0, answer.status.name.lower()
        if not np.isfinite(answer.age):
            return 0.0, "no data"
    path = radius + ahead.distance  # as if what the path meets were straight ahead
    distance = min(nearest.distance, path)
    ramp = (distance - limits.stop) / (limits.slow - limits.stop)
    speed = limits.top * float(np.clip(ramp, 0.0, 1.0))
    reason = "clear" if ramp >= 1.0 else "slowing" if ramp > 0.0 else "obstacle"
    if ahead.status == QueryStatus.UNKNOWN and path < nearest.distance \
            and nearest.distance > limits.stop and speed < limits.creep:
        return limits.creep, "unknown ahead"  # no obstacle within --stop m: creep into it
    return speed, reason


def paced(scans: Iterable, speed: float, clock=time.monotonic) -> Iterator[Scan]:
    """The scans as a live scanner hands them over: each when its sweep ends (recorded
    time / speed after the first scan's start), re-stamped on `clock`."""
    origin = start = None
    for item in scans:
        scan = getattr(item, "scan", item)
        if not len(scan):
            continue
        if origin is None:
            origin, start = float(scan.stamp), clock()
        times = start + (scan.time - origin) / speed
        time.sleep(max(0.0, float(times.max()) - clock()))
        yield replace(scan, time=times, stamp=start + (scan.stamp - origin) / speed)


def scan_interval(source: ScanSource) -> float:
    """Median time (s) between the starts of the recording's scans (2 s for one scan)."""
    stamps = [record.stamp for record in source.recording.scans]
    return float(np.median(np.diff(stamps))) if len(stamps) > 1 else 2.0


def control_loop(mapper: Mapper, mapping, limits: Limits, linger: float) -> dict:
    """Poll at RATE until the mapping thread has ended `linger` s ago; returns a summary."""
    latencies, reasons, transitions, unknown_clearance = [], Counter(), [], []
    period, last_reason, ended_at = 1.0 / RATE, None, None
    start = next_tick = time.monotonic()
    while ended_at is None or time.monotonic() < ended_at + linger:
        pose = mapper.latest_pose
        x, y, yaw = (pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])) \
            if pose is not None else (0.0, 0.0, 0.0)
        before = time.perf_counter_ns()
        nearest = mapper.obstacles.nearest(x, y)
        latencies.append(time.perf_counter_ns() - before)
        ahead = mapper.obstacles.travel((x, y, yaw), limits.slow)
        speed, reason = speed_command(nearest, ahead, mapper.obstacles.robot.radius, limits)
        reasons[reason] += 1
        if nearest.status == QueryStatus.UNKNOWN and np.isfinite(nearest.age):
            unknown_clearance.append(nearest.clearance)  # unknown nearer than obstacles
        if reason != last_reason:
            # The answer that stopped the robot, if one did: the data can go stale between
            # the two queries, and `nearest` then still reads as fresh.
            status = next((a.status for a in (nearest, ahead) if a.status in HALTING),
                          nearest.status)
            transitions.append({"t": time.monotonic() - start, "reason": reason,
                                "speed": speed, "status": status.name,
                                "distance": nearest.distance, "age": nearest.age})
            print(f"  t={transitions[-1]['t']:5.2f} s  {reason:15s} speed {speed:.2f} m/s  "
                  f"nearest {nearest.distance:.2f} m, {status.name}")
            last_reason = reason
        if ended_at is None and not mapping.running:
            ended_at = time.monotonic()
        next_tick += period
        time.sleep(max(0.0, next_tick - time.monotonic()))
    micro = np.array(latencies) / 1e3
    return {"polls": len(latencies), "seconds": time.monotonic() - start,
            "latency_us": {f"p{q}": float(np.percentile(micro, q)) for q in (50, 90, 99)}
            | {"max": float(micro.max())},
            "polls_by_reason": dict(reasons), "transitions": transitions,
            "unknown_nearer_than_obstacles": len(unknown_clearance),
            "unknown_clearance_m": {f"p{q}": float(np.percentile(unknown_clearance, q))
                                    for q in (10, 50, 90)} if unknown_clearance else {},
            "final": transitions[-1], "scans_mapped": mapping.mapped,
            "mapping_error": None if mapping.error is None else str(mapping.error)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=DATA / "corridor_recording")
    parser.add_argument("--scans", type=int, default=20,
                        help="scans to simulate when the recording is missing (default 20)")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed (default 1)")
    parser.add_argument("--max-age", type=float, default=None,
                        help="data older than this (s) are stale (default: 1.5 times the "
                             "recording's scan interval, replayed)")
    parser.add_argument("--top", type=float, default=Limits.top)
    parser.add_argument("--creep", type=float, default=Limits.creep)
    parser.add_argument("--slow", type=float, default=Limits.slow)
    parser.add_argument("--stop", type=float, default=Limits.stop)
    parser.add_argument("--summary", type=Path, default=None, help="write a JSON summary")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)

    recording = ensure_recording(args.recording, "corridor", args.scans, args.workers)
    source = ScanSource.open(recording, workers=args.workers)
    max_age = args.max_age or scan_interval(source) * 1.5 / args.speed
    mapper = Mapper(source.model, MapperConfig(max_age=max_age))
    mapper.warm_up()  # compile before the "robot" moves
    print(f"replaying {recording} ({source.count} scans) at {args.speed:g}x; control at "
          f"{RATE:.0f} Hz; data older than {max_age:.1f} s are stale")
    mapping = mapper.start(paced(source, args.speed))
    limits = Limits(args.top, args.creep, args.slow, args.stop)
    summary = control_loop(mapper, mapping, limits, linger=max_age + 0.5)
    latency = summary["latency_us"]
    print(f"{summary['polls']} polls in {summary['seconds']:.1f} s; nearest() latency "
          f"p50 {latency['p50']:.1f} us, p90 {latency['p90']:.1f} us, p99 "
          f"{latency['p99']:.1f} us, max {latency['max']:.0f} us")
    print(f"{summary['scans_mapped']} scans mapped; polls by reason: "
          f"{summary['polls_by_reason']}; final: {summary['final']['reason']}, speed "
          f"{summary['final']['speed']:.2f} m/s")
    if args.summary:
        write_json(args.summary, summary)
    return 0 if summary["mapping_error"] is None else 1


if __name__ == "__main__":
    raise SystemExit(main())
