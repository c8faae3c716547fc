"""Locating a new session in a saved map, on real robot logs (issue 18 item 4).

    .venv/bin/python -m benchmarks.bench_localise [--quick] [--only LOG]

Per CARMEN log (`bench_registration.carmen`): the first half of its scans mapped with
loop closure as the Mapper does (ScanOdometry feeding a LoopCloser). Then sessions start
in the second half, located from nothing (no hint: a robot switched on somewhere in the
building) as `Mapper.load(localise=True)` locates them: each scan registered in the
session's own frame, and the newest located with the scans of the last
`context_distance` of travel, scan after scan, until two in a row agree (`Session`) or
the session has travelled SESSION_M:

* revisits: sessions starting at every STRIDE-th scan whose reference pose lies within
  REVISIT_M and REVISIT_DEG of a first-half scan's (the same place seen the same way: a
  180 deg laser sees a corridor's other side when it turns round). Located: the share
  located; travel: the median travel (m) before; wrong: the share located more than
  WRONG_M or WRONG_DEG off; error: the median over those located right. The error is
  the located scan's pose relative to the keyframe it matched, against the reference's:
  not in the map's frame, whose drift is `bench_loop_closure`'s.
* elsewhere: sessions starting at every STRIDE-th scan farther than ELSEWHERE_M from
  every first-half reference position, ended before one comes nearer (places the map
  never saw). Any located one is wrong: the false-location rate, which must stay 0,
  since a wrong start bends the saved map.

The time is the median wall time of one attempt (the place search and the ICP of every
candidate). No peer: KISS-SLAM has no relocalisation; its loop detector is what
`bench_loop_closure` compares.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.bench_loop_closure import LOGS
from benchmarks.bench_registration import Sequence, carmen
from benchmarks.carmen_logs import carmen_logs
from scanmap.graph import LoopCloser, LoopClosureConfig
from scanmap.graph.localise import Localisation, NotLocalised, Session
from scanmap.registration import ScanOdometry
from scanmap_driver.transforms import invert_pose, pose_to_se2

STRIDE = 3  # a session starts at every STRIDE-th scan of the second half that qualifies
QUICK_STRIDE = 12  # the quick run's (freiburg-101: 10 sessions instead of 39)
REVISIT_M, REVISIT_DEG = 1.0, 30.0  # a revisit: this near a mapped scan, facing alike
ELSEWHERE_M = 5.0  # a place the map never saw: this far from every mapped scan
SESSION_M = 8.0  # a session not located after this much travel gives up
WRONG_M, WRONG_DEG = 0.5, 10.0  # a location this far off the truth is wrong


def mapped_half(seq: Sequence, config: LoopClosureConfig | None = None) -> LoopCloser:
    """The first half of `seq` registered and fed to a LoopCloser (left open)."""
    registration = ScanOdometry(seq.config, initial_pose=seq.reference[0])
    closer = LoopCloser(config or LoopClosureConfig(enabled=True), seq.config)
    for scan in seq.scans[:len(seq.scans) // 2]:
        result = registration.register(scan)
        closer.add(result.pose, result, scan.points)
    closer.finish()
    return closer


def nearest_mapped(seq: Sequence, k: int) -> tuple[float, bool]:
    """(distance m to the nearest first-half reference position, whether scan k is a
    revisit of a first-half scan)."""
    mapped = seq.reference[:len(seq.scans) // 2]
    distance = np.linalg.norm(mapped[:, :2, 3] - seq.reference[k, :2, 3], axis=1)
    turned = np.degrees(np.abs([pose_to_se2(invert_pose(m) @ seq.reference[k])[2]
                                for m in mapped]))
    return float(distance.min()), bool(((distance <= REVISIT_M)
                                        & (turned <= REVISIT_DEG)).any())


def session(closer: LoopCloser, seq: Sequence, first: int, stay_away: bool,
            seconds: list[float]) -> tuple[Localisation, int, float] | None:
    """A session from scan `first` (module docstring): (where it was located, the scan
    located, the travel before) or None. `stay_away`: end it before a scan within
    ELSEWHERE_M of the map. Appends each attempt's wall time to `seconds`."""
    registration = ScanOdometry(seq.config)
    located = Session(closer)
    for k in range(first, len(seq.scans)):
        if stay_away and nearest_mapped(seq, k)[0] <= ELSEWHERE_M:
            return None
        result = registration.register(seq.scans[k])
        if np.linalg.norm(result.pose[:2, 3] - registration.poses[0][:2, 3]) > SESSION_M:
            return None
        start = time.perf_counter()
        try:
            found = located.add(seq.scans[k].points, result.pose, result.ok)
        except NotLocalised:
            continue
        finally:
            seconds.append(time.perf_counter() - start)
        travel = float(np.sum(np.linalg.norm(np.diff(seq.reference[first:k + 1, :2, 3],
                                                     axis=0), axis=1)))
        return found, k, travel
    return None


def error(closer: LoopCloser, seq: Sequence, found: Localisation, k: int
          ) -> tuple[float, float]:
    """(m, deg) of scan k located at `found`, against the keyframe it matched by the
    reference."""
    estimate = invert_pose(closer.corrected_poses()[found.node]) @ found.pose
    truth = invert_pose(seq.reference[found.node]) @ seq.reference[k]
    x, y, yaw = pose_to_se2(invert_pose(truth) @ estimate)
    return float(np.hypot(x, y)), float(np.degrees(abs(yaw)))


def measure(seq: Sequence, config: LoopClosureConfig | None = None,
            stride: int = STRIDE) -> dict:
    """The row of one log (module docstring), sessions at every `stride`-th scan."""
    closer = mapped_half(seq, config)
    seconds: list[float] = []
    half = len(seq.scans) // 2
    starts = [(k, *nearest_mapped(seq, k)) for k in range(half, len(seq.scans), stride)]
    try:
        revisits = [session(closer, seq, k, False, seconds)
                    for k, _, revisit in starts if revisit]
        elsewhere = [session(closer, seq, k, True, seconds)
                     for k, distance, _ in starts if distance > ELSEWHERE_M]
        located = [(error(closer, seq, found, k), travel)
                   for found, k, travel in filter(None, revisits)]
        keyframes = len(closer.keyframes())
    finally:
        closer.close()
    wrong = [e for e, _ in located if e[0] > WRONG_M or e[1] > WRONG_DEG]
    right = [e for e, _ in located if not (e[0] > WRONG_M or e[1] > WRONG_DEG)]
    return {"stage": "localisation", "method": "ours: a new session located (no hint)",
            "settings": f"{seq.name}, map of the first {half} scans, {len(revisits)} "
                        f"sessions at revisits and {len(elsewhere)} elsewhere in the second",
            "median_s": float(np.median(seconds)) if seconds else None,
            "error": float(np.median([e[0] for e in right])) if right else None,
            "error_unit": "m, median position error of the sessions located right",
            "revisits": len(revisits),
            "located_share": len(located) / max(len(revisits), 1),
            "travel_median_m": float(np.median([t for _, t in located])) if located else None,
            "wrong_share": len(wrong) / max(len(revisits), 1),
            "heading_error_deg": float(np.median([e[1] for e in right])) if right else None,
            "elsewhere": len(elsewhere),
            "falsely_located_share": sum(f is not None for f in elsewhere)
            / max(len(elsewhere), 1),
            "keyframes": keyframes}


def run(quick: bool = False, only: str | None = None) -> list[dict]:
    """A row per log (`quick`: freiburg-101 alone, a session at every QUICK_STRIDE-th scan);
    `only`: logs whose name contains it."""
    logs = ("freiburg-101",) if quick else carmen_logs(LOGS)
    return [measure(carmen(name, None), stride=QUICK_STRIDE if quick else STRIDE)
            for name in logs if only is None or only in name]


if __name__ == "__main__":
    from benchmarks.carmen_cli import run_from_command_line

    run_from_command_line(run, __doc__)
