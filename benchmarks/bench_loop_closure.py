"""Loop closure on real robot logs: ours with and without it, beside KISS-SLAM, same scans.

Sequences: the CARMEN logs of `bench_registration.carmen` (raw ODOM as the prior, the
corrected FLASER poses as reference). Methods, all single-threaded but for our loop
closure's own worker thread, all started from the first reference pose:
* ours: `ScanOdometry` alone (scan-to-map ICP, odometry prior);
* ours + loop closure: the same registration feeding a `LoopCloser` (pose graph, loops by
  place and proximity verified by ICP, GTSAM with a Cauchy kernel), its corrected poses
  read after the last scan;
* KISS-SLAM (0.0.2): KISS-ICP odometry with the odometry increment as its motion
  prediction, local maps split every `kiss_split` m, MapClosures loop detection, its
  pose graph, poses read after its fine-grained optimisation. It gets each scan extruded
  into a wall as the registration benchmark's peers do. It runs in a process of its own
  with a time limit (`run_isolated`): a crash or a hang is reported as its failure.

Figures: ATE RMSE after SE(2) alignment (`ate_m`) and without (`ate_unaligned_m`: every
method starts at the first reference pose), mean error of 1 m relative motions, median wall
time per scan (registration + the caller's part of loop closure), the loop closer's
optimisation times (in its thread), and the time to rebuild the 2.5D grid from every
scan's kept points at the corrected poses (`rebuild_grid`, what the Mapper does after an
optimisation), and `ate_loops_at_reference_m`: the same graph with every loop measured
exactly (`loops_at_reference`), which tells the loops' own errors from the drift between
them. Run: `.venv/bin/python -m benchmarks.bench_loop_closure`.

Per log also the rebuilds the Mapper does after each optimisation (`GridRebuilder`: from
the checkpoint of its previous rebuild before the first scan that moved more than a
quarter of a cell): how many, their median and longest wall time, and the mean share of
the scans they fused again (`rebuild_redone_share`).

A last row times the rebuild for the 3-D scanner: the simulated office's ideal scans
kept as the Mapper keeps them (`scan_contribution`: one ray per 5 cm voxel, about 4,300
a scan), cycled to REBUILD_SCANS scans, as seconds per 1000 scans (the issue's budget:
under 1 s), whole (`rebuild_grid`) and by a `GridRebuilder` after a loop has moved the
last quarter of the scans (`last_quarter_moved_s`); and by the Mapper's default, a
`SubmapRebuilder` (`submap_*`: submaps of 25 scans built as scans come, merged moved by
their corrections after a loop; `submap_rebuilds`).

`ate_loops_everywhere_m` bounds what any loop closure could do with this registration:
its registration edges with an exact loop (by the reference) from every keyframe to the
nearest older one within ORACLE_RADIUS; the rest is the drift of the stretches no
revisit reaches. On Edmonton that bound is 0.41 m against 0.66 without loops (its
stretches 62-163 and 252-340 never come back), on Belgioioso 0.073 against 0.21: a
threefold reduction is out of reach there for any loop closure over this registration.

The figures of the last whole run are in `benchmarks/results/latest.md`. KISS-SLAM has
closed no loop on these extruded 2-D scans (on ACES none with local maps split every 5,
10 or 30 m and density maps of 0.1 to 0.5 m; on Intel its MapClosures detections failed
its own overlap test), so it ends at its odometry's error. Without loops, how the drift
of the stretches that never come back cancels under the SE(2) alignment is luck: one
slip registered differently moves the ATE by tenths of a metre (Edmonton, before and
after the registration's search below 0.8 of the recent fitness: 0.56 -> 0.66 m without
loops, 0.32 -> 0.55 with).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before Open3D loads: single-threaded peers

import contextlib
import io
import time

import numpy as np

from benchmarks.bench_registration import Sequence, _scores, carmen, run_ours
from benchmarks.carmen_logs import carmen_logs
from benchmarks.isolation import PeerFailed, run_isolated
from scanmap.evaluation.trajectory_errors import ate_rmse
from scanmap.graph import Edge, LoopCloser, LoopClosureConfig, PoseGraph
from scanmap.grid.height_grid import GridConfig
from scanmap.mapping.rebuild import (
    Contribution,
    GridRebuilder,
    SubmapRebuilder,
    rebuild_grid,
    scan_contribution,
)
from scanmap.registration import ScanOdometry
from scanmap_driver.transforms import invert_pose, se2_to_pose

# The shared logs in the order of the tables; `carmen_logs` adds any other one present.
LOGS = ("intel", "aces", "fhw", "freiburg-101", "belgioioso", "edmonton", "acapulco")


def run_loop_closure(seq: Sequence, config: LoopClosureConfig | None = None,
                     versions: list[np.ndarray] | None = None
                     ) -> tuple[np.ndarray, list[float], LoopCloser]:
    """Ours with loop closure: (corrected poses, seconds per scan, the closer).
    versions: gets the corrected poses of every scan so far each time a scan finds a new
    optimisation published (what the Mapper rebuilds its grid at), and the last ones."""
    registration = ScanOdometry(seq.config, initial_pose=seq.reference[0])
    closer = LoopCloser(config or LoopClosureConfig(enabled=True), seq.config)
    seconds, seen = [], 0
    try:
        for scan in seq.scans:
            start = time.perf_counter()
            result = registration.register(scan)
            closer.add(result.pose, result, scan.points)
            seconds.append(time.perf_counter() - start)
            if versions is not None and closer.version != seen:
                seen = closer.version
                versions.append(closer.corrected_poses())
        closer.finish()
        if versions is not None:
            versions.append(closer.corrected_poses())
        return closer.corrected_poses(), seconds, closer
    finally:
        closer.close()


def run_kiss_slam(seq: Sequence, split: float = 10.0) -> tuple[np.ndarray, list[float]]:
    """KISS-SLAM on the extruded scans, odometry as its prediction (see the docstring);
    run in a process of its own (`run_isolated`)."""
    from kiss_slam.config import KissSLAMConfig
    from kiss_slam.slam import KissSLAM

    config = KissSLAMConfig()
    config.odometry.preprocessing.max_range = seq.max_range
    config.odometry.preprocessing.min_range = seq.min_range
    config.odometry.preprocessing.deskew = False
    config.odometry.mapping.voxel_size = seq.max_range / 100.0
    config.odometry.registration.max_num_threads = 1
    config.local_mapper.splitting_distance = split
    config.local_mapper.voxel_size = 0.1
    config.loop_closer.detector.density_map_resolution = 0.1
    config.occupancy_mapper.max_range = seq.max_range
    slam = KissSLAM(config)
    seconds = []
    with contextlib.redirect_stdout(io.StringIO()):  # it prints every closure it tries
        for k in range(len(seq.scans)):
            points = seq.peer_points(k)
            start = time.perf_counter()
            if k:
                slam.odometry.last_delta = seq.odometry_step(k)
            slam.process_scan(points, np.zeros(len(points)))
            seconds.append(time.perf_counter() - start)
        slam.generate_new_node()  # closes the last local map, as its pipeline does at the end
        poses, _ = slam.fine_grained_optimization()
    print(f"KISS-SLAM on {seq.name}: {len(slam.get_closures())} loops closed")
    return np.array([seq.reference[0] @ p for p in poses])[:len(seq.scans)], seconds


def compare(seq: Sequence) -> dict:
    """One row: ours with loop closure, ours without and KISS-SLAM as peers."""
    versions: list[np.ndarray] = []
    poses, seconds, closer = run_loop_closure(seq, versions=versions)
    rebuilds = incremental_rebuilds(seq, versions)
    row = {"stage": "loop closure", "method": "ours: ScanOdometry + LoopCloser",
           "settings": f"{seq.name}, {len(seq.scans)} scans", **_scores(poses, seconds, seq),
           "ate_unaligned_m": ate_rmse(poses, seq.reference, "none"),
           "ate_loops_at_reference_m": ate_rmse(
               loops_at_reference(closer, seq.reference), seq.reference, "se2"),
           "ate_loops_everywhere_m": ate_rmse(
               loops_everywhere(closer, seq.reference), seq.reference, "se2"),
           "loops": len(closer.loops), "optimisations": len(closer.optimise_seconds),
           "optimise_median_s": float(np.median(closer.optimise_seconds))
           if closer.optimise_seconds else None,
           "optimise_max_s": max(closer.optimise_seconds, default=None),
           "rebuild_s": rebuild_seconds(seq, poses),
           "rebuilds": len(rebuilds), "rebuild_median_s": float(np.median(rebuilds[:, 0])),
           "rebuild_max_s": float(rebuilds[:, 0].max()),
           "rebuild_redone_share": float(rebuilds[:, 1].mean())}
    plain, plain_seconds = run_ours(seq)
    peers = {"ours without loop closure": {**_scores(plain, plain_seconds, seq),
                                           "ate_unaligned_m": ate_rmse(plain, seq.reference,
                                                                       "none")}}
    try:
        kiss, kiss_seconds = run_isolated(run_kiss_slam, seq)
        peers["KISS-SLAM"] = {**_scores(kiss, kiss_seconds, seq),
                              "ate_unaligned_m": ate_rmse(kiss, seq.reference, "none")}
    except PeerFailed as exc:  # a peer that fails is reported in its place
        peers["KISS-SLAM"] = {"failed": str(exc)}
    row["error"], row["error_unit"] = row["ate_m"], "m, ATE RMSE (SE(2)-aligned)"
    for values in peers.values():
        if "ate_m" in values:
            values["error"] = values["ate_m"]
    row["peers"] = peers
    return row


def loops_at_reference(closer: LoopCloser, reference: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the closer's graph optimised as it was, but each loop edge measuring the
    reference's relative pose: what these loops would give had ICP measured them exactly
    (by the reference). Near `ate_m`: the loops' own errors do not limit the ATE. Above
    it: what is left is the drift of the registration between loops, where the path never
    comes back, which SE(2) alignment may have hidden better without loops (see
    `loops_everywhere`). Well below it: the loops
    (or the registration edges inside a loop, which a loop's ICP may share) are off."""
    graph = PoseGraph()
    graph.poses, graph.fixed = list(closer.graph.poses), closer.graph.fixed
    graph.edges = [Edge(e.source, e.target, invert_pose(reference[e.source])
                        @ reference[e.target], e.information, loop=True) if e.loop else e
                   for e in closer.graph.edges]
    return graph.optimise(closer.corrected_poses(), closer.config.loop_kernel)


ORACLE_RADIUS = 6.0  # m: `loops_everywhere` joins keyframes this near (by the reference)


def loops_everywhere(closer: LoopCloser, reference: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the closer's registration edges with an exact loop (by the reference,
    weighted as a loop edge at the sigma floors) from every keyframe to the nearest older
    one within ORACLE_RADIUS and min_separation of travel: the most any loop closure could
    do with this registration, had it found and measured every revisit exactly. What is
    left is the drift of the stretches no revisit reaches."""
    c = closer.config
    keyframes = closer.state()["keyframes"]
    travel = np.concatenate([[0.0], np.cumsum(np.linalg.norm(
        np.diff(reference[:, :2, 3], axis=0), axis=1))])
    information = np.diag([c.loop_sigma ** -2, c.loop_sigma ** -2, c.loop_yaw_sigma ** -2])
    graph = PoseGraph()
    graph.poses, graph.fixed = list(closer.graph.poses), closer.graph.fixed
    graph.edges = [e for e in closer.graph.edges if not e.loop]
    for k, node in enumerate(keyframes):
        older = keyframes[:k][travel[node] - travel[keyframes[:k]] >= c.min_separation]
        if len(older):
            distance = np.linalg.norm(reference[older, :2, 3] - reference[node, :2, 3], axis=1)
            if distance.min() <= ORACLE_RADIUS:
                candidate = older[int(np.argmin(distance))]
                graph.edges.append(Edge(candidate, node, invert_pose(reference[candidate])
                                        @ reference[node], information, loop=True))
    return graph.optimise(np.array(closer.graph.poses), c.loop_kernel)


def _kept_2d(seq: Sequence) -> list[Contribution]:
    """Each scan of `seq` as a rebuild keeps it (every point, the laser 0.3 m up)."""
    return [Contribution.of_rays(scan.points, np.broadcast_to([0.0, 0.0, 0.3],
                                                              scan.points.shape),
                                 float(scan.stamp)) for scan in seq.scans]


def rebuild_seconds(seq: Sequence, poses: np.ndarray) -> float:
    """Wall time of `rebuild_grid` over every scan of `seq` at `poses` (laser 0.3 m up)."""
    contributions = _kept_2d(seq)
    start = time.perf_counter()
    rebuild_grid(GridConfig(max_range=seq.max_range), poses, contributions)
    return time.perf_counter() - start


def incremental_rebuilds(seq: Sequence, versions: list[np.ndarray]) -> np.ndarray:
    """(V, 2) per optimisation in `versions` (`run_loop_closure`), in turn: the wall time
    of a `GridRebuilder` rebuild at its poses, as the Mapper does after each, and the
    share of its scans that rebuild fused again (the rest it took from its checkpoints)."""
    contributions = _kept_2d(seq)
    rebuilds = GridRebuilder(GridConfig(max_range=seq.max_range))
    out = []
    for poses in versions:
        start = time.perf_counter()
        rebuilds.rebuild(poses, contributions[:len(poses)])
        out.append((time.perf_counter() - start, 1.0 - rebuilds.reused / len(poses)))
    return np.array(out).reshape(-1, 2)


REBUILD_SCANS = 200


def rebuild_3d(scans: int = REBUILD_SCANS) -> list[dict]:
    """Seconds per 1000 scans to rebuild the grid of the 3-D scanner (module docstring):
    a row for fusing every kept ray again, one for the submaps."""
    from scanmap.grid.rays import scan_rays
    from scanmap_driver.scanner_model import reference_scanner
    from scanmap_driver.sim import builtin_scene, ideal_scans

    model, poses, kept = reference_scanner(), [], []
    for ideal in ideal_scans(builtin_scene("office"), model):
        points, origins = scan_rays(ideal.scan, model, ideal.frame_poses)
        poses.append(ideal.pose_start)
        kept.append(scan_contribution(points, origins, ideal.pose_start,
                                      float(ideal.scan.stamp), GridConfig().resolution))
    cycle = [k % len(kept) for k in range(scans)]
    poses, kept = np.array([poses[k] for k in cycle]), [kept[k] for k in cycle]
    rebuild_grid(GridConfig(), poses[:2], kept[:2])  # compiled apart
    seconds = []
    for _ in range(3):
        start = time.perf_counter()
        rebuild_grid(GridConfig(), poses, kept)
        seconds.append(time.perf_counter() - start)
    per_scan = float(np.median(seconds)) / scans
    # A loop back to where the robot was three quarters of the way: the last quarter of
    # the scans turns 0.5 deg about the scan there and shifts 5 cm; then back again.
    pivot = poses[3 * scans // 4 - 1]
    moved = poses.copy()
    moved[3 * scans // 4:] = pivot @ se2_to_pose(0.05, 0.0, np.radians(0.5)) \
        @ invert_pose(pivot) @ poses[3 * scans // 4:]
    rebuilds = GridRebuilder(GridConfig())
    rebuilds.rebuild(poses, kept)
    after_loop = []
    for k in range(4):
        start = time.perf_counter()
        rebuilds.rebuild(moved if k % 2 == 0 else poses, kept)
        after_loop.append(time.perf_counter() - start)
    settings = (f"sim office, 3-D scanner, {scans} scans ({len(set(cycle))} cycled), "
                f"{int(np.mean([len(k.points) for k in kept]))} rays a scan kept")
    whole = {"stage": "loop closure", "method": "grid rebuild from kept rays (rebuild_grid)",
             "settings": settings, "median_s": per_scan, "per_1000_scans_s": 1000 * per_scan,
             "budget_s": 1e-3, "last_quarter_moved_s": float(np.median(after_loop)),
             "last_quarter_moved_per_1000_scans_s":
                 1000 * float(np.median(after_loop)) / scans,
             "error": None, "error_unit": "", "peers": {}}
    submaps = submap_rebuilds(poses, kept, moved)
    return [whole, {"stage": "loop closure",
                    "method": "grid rebuild from submaps (SubmapRebuilder, the default)",
                    "settings": settings + ", 25 a submap, after a loop that moved the last "
                                           "quarter; time per scan",
                    "median_s": submaps["submap_last_quarter_moved_per_1000_scans_s"] / 1000,
                    "budget_s": 1e-3, **submaps, "error": None, "error_unit": "",
                    "peers": {}}]


def submap_rebuilds(poses: np.ndarray, kept: list, moved: np.ndarray) -> dict:
    """The Mapper's default rebuild (`SubmapRebuilder`, 25 scans a submap) of the same
    scans, per 1000 scans: building the submaps as scans come (in its thread, off the
    per-scan path), and the rebuild after a loop, median of three: the last quarter moved
    (as above), and a correction spread along the whole run (pose k turned by 0.5 deg
    k/N about the first and shifted 5 cm k/N: every submap moves, each nearly rigidly);
    with the submaps it built again (bent beyond a quarter cell) and their memory."""
    n = len(poses)
    spread = np.array([se2_to_pose(0.05 * k / n, 0.0, np.radians(0.5) * k / n) @ pose
                       for k, pose in enumerate(poses)])
    rebuilds = SubmapRebuilder(GridConfig())
    start = time.perf_counter()
    rebuilds.prepare(poses, kept)
    out = {"submap_build_per_1000_scans_s": 1000 * (time.perf_counter() - start) / n,
           "submap_mb_per_1000_scans": 1000 / n * sum(
               s.grid.nbytes for s in rebuilds._submaps) / 1e6}
    for name, placed in (("last_quarter_moved", moved), ("spread_correction", spread)):
        seconds = []
        for _ in range(3):
            rebuilds.prepare(poses, kept)  # the submaps as mapped, before the loop
            start = time.perf_counter()
            rebuilds.rebuild(placed, kept)
            seconds.append(time.perf_counter() - start)
        out[f"submap_{name}_per_1000_scans_s"] = 1000 * float(np.median(seconds)) / n
        out[f"submap_{name}_rebuilt_scans"] = n - rebuilds.reused
        rebuilds.rebuild(poses, kept)  # back, as mapped
    return out


def run(quick: bool = False, only: str | None = None) -> list[dict]:
    """A row per log (with `quick` freiburg-101 alone: the shortest log, 292 scans, that
    closes loops); `only`: logs whose name contains it."""
    logs = ("freiburg-101",) if quick else carmen_logs(LOGS)
    rows = [compare(carmen(name, None)) for name in logs if only is None or only in name]
    if only is None or only in "rebuild":
        rows += rebuild_3d(50 if quick else REBUILD_SCANS)
    return rows


if __name__ == "__main__":
    from benchmarks.carmen_cli import run_from_command_line

    run_from_command_line(run, __doc__)
