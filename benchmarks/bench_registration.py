"""Registration against its peers, side by side on the same scans and the same odometry.

Sequences: the simulator's corridor and office (ideal scans; in the full run also scans
processed from rendered frames), and the real CARMEN logs (`carmen_logs`: the seven shared
ones and any other corrected log beside them; raw ODOM as the prior, the corrected FLASER
poses as reference; the quick run takes the first `QUICK_SCANS` scans of each of
`QUICK_LOGS`). Ours has one configuration for every log.

Methods, all single-threaded, all started from the same first pose:
* ours: `ScanOdometry` (scan-to-local-map point-to-plane ICP, planar, odometry prior).
* Open3D point-to-plane ICP and Open3D GICP: scan to previous scan, the odometry
  increment as initial guess, voxel v, normals from 3 v, correspondences up to d.
* small_gicp GICP: the same protocol, downsampling v, 20 neighbours.
  (v, d) is the best for the peers of those tried ((0.05, 0.2), (0.1, 0.3), (0.2, 0.5)
  m): (0.2, 0.5) on the simulator's stripes, (0.1, 0.3) on the 2-D logs.
* KISS-ICP: its own scan-to-map pipeline, configured for a 4 m sensor (voxel = max range
  / 100 as it recommends, initial threshold 0.3 m, no deskew for stop-and-scan), with the
  odometry increment fed as its motion prediction (`last_delta`).
Every peer runs in a process of its own with a time limit (`run_isolated`): a crash or
a hang is that peer's failure on that sequence, reported in its place.
For the 2-D logs the peers get each scan extruded into a 1 m wall (copies at four
heights) so that their normals and covariances exist; ours uses the 2-D points.

Errors: ATE RMSE after SE(2) alignment, mean translational error of 1 m relative motions,
and drift per metre; time per scan is the median wall time of one registration including
its preprocessing. On the real logs the full run registers each log from each of
`STARTS` (its first scans) and reports every method's mean over them: ours moves by a few
mm from one start to the next (1 m relative error on Acapulco 61.3-64.1 mm over seven
starts), small_gicp by less (64.5-65.8), so one start alone compares luck. A separate
row times ours on 20,000-point scans (the issue's budget).
On the real logs two more rows judge the reference itself: its own error
(`reference_noise`) and how well each trajectory lays the scans onto each other
(`scan_agreement`, no reference needed).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before Open3D loads: single-threaded peers

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from benchmarks.carmen_logs import carmen_logs, carmen_path
from benchmarks.isolation import PeerFailed, run_isolated
from benchmarks.timing import first_call_time
from scanmap.datasets.carmen import read_carmen
from scanmap.evaluation.trajectory_errors import ate_rmse, relative_errors, shared_error
from scanmap.registration import (
    LocalMap,
    Prior,
    RegistrationConfig,
    ScanOdometry,
    prepare_source,
    register_scan,
)
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose, se2_to_pose

EXTRUDE_HEIGHTS = (0.0, 0.1, 0.2, 0.3, 0.4)
QUICK_SCANS = 40  # scans per real log in the quick run (about 40 m each)
QUICK_LOGS = ("intel", "aces", "acapulco")  # the quick run: 180 and 181 beams
STARTS = (0, 7, 15, 23, 31, 40, 50)  # first scans of the full run's real-log registrations


@dataclass
class Sequence:
    """Scans with odometry and the reference poses, and how each side should read them."""

    name: str
    scans: list[Scan]
    reference: np.ndarray  # (N, 4, 4)
    config: RegistrationConfig = field(default_factory=RegistrationConfig)
    max_range: float = 4.0
    min_range: float = 0.3
    extrude: bool = False  # 2-D scans: peers get them as walls
    peer_voxel: float = 0.2
    peer_correspondence: float = 0.5

    def odometry_step(self, k: int) -> np.ndarray:
        """Odometry increment from scan k-1 to scan k."""
        return invert_pose(self.scans[k - 1].odom_start) @ self.scans[k].odom_start

    def odometry_poses(self) -> np.ndarray:
        """(N, 4, 4) the wheel odometry alone, started at the first reference pose."""
        start = self.reference[0] @ invert_pose(self.scans[0].odom_start)
        return np.array([start @ s.odom_start for s in self.scans])

    def peer_points(self, k: int) -> np.ndarray:
        """Scan k's points as the peers get them: in range, float64, extruded if 2-D."""
        points = self.scans[k].points.astype(np.float64)
        r = np.hypot(points[:, 0], points[:, 1])
        points = points[np.isfinite(points).all(axis=1) & (r >= self.min_range)
                        & (r <= self.max_range)]
        if self.extrude:
            points = np.vstack([points * [1, 1, 0] + [0, 0, h] for h in EXTRUDE_HEIGHTS])
        return points


def simulated(scene_name: str, count: int, seed: int = 0) -> Sequence:
    """Ideal scans of a built-in simulator scene."""
    from scanmap_driver.sim import builtin_scene, ideal_scans

    ideal = list(ideal_scans(builtin_scene(scene_name), seed=seed, scans=count))
    return Sequence(f"sim {scene_name}, ideal scans", [s.scan for s in ideal],
                    np.array([s.pose_start for s in ideal]))


def rendered(scene_name: str, count: int, seed: int = 0) -> Sequence:
    """Scans processed from rendered camera frames (laser extraction, encoder, triangulation)."""
    from scanmap_driver.assembly import ScanAssembler
    from scanmap_driver.scanner_model import reference_scanner
    from scanmap_driver.sim import builtin_scene, plan_scans
    from scanmap_driver.sim.render import Renderer

    model, scene = reference_scanner(), builtin_scene(scene_name)
    renderer = Renderer(scene, model)
    rng = np.random.default_rng(seed)
    scans, truth = [], []
    for plan in plan_scans(scene, model, seed, count):
        assembler = ScanAssembler(model)
        for frame, t in enumerate(plan.frame_times):
            assembler.add_frame(renderer.render(plan, frame, rng).image, t)
        scan, _ = assembler.finish(plan.index, se2_to_pose(*plan.odom_start),
                                   se2_to_pose(*plan.odom_end))
        scans.append(scan)
        truth.append(se2_to_pose(*plan.start_pose))
    return Sequence(f"sim {scene_name}, rendered frames", scans, np.array(truth))


def carmen(name: str, count: int | None) -> Sequence:
    """A real CARMEN log: FLASER scans with the raw odometry, corrected poses as reference."""
    log = read_carmen(carmen_path(name))
    count = len(log) if count is None else min(count, len(log))
    scans = []
    for i in range(count):
        points = log.scan_points(i)
        odom = se2_to_pose(*log.odometry[i])
        n = len(points)
        scans.append(Scan(points=points, colors=np.zeros((n, 3), np.uint8),
                          time=np.full(n, log.times[i]), heading=np.zeros(n),
                          frame_index=np.zeros(n, np.int32), range_sigma=np.full(n, 0.01),
                          index=i, stamp=float(log.times[i]), odom_start=odom, odom_end=odom))
    config = RegistrationConfig.for_2d_scans()
    return Sequence(f"real {name} (CARMEN)", scans,
                    np.array([se2_to_pose(*p) for p in log.poses[:count]]), config,
                    max_range=config.max_range, min_range=config.min_range, extrude=True,
                    peer_voxel=0.1, peer_correspondence=0.3)


# -- methods: each returns (poses (N, 4, 4), seconds per scan) ------------------------------

def run_ours(seq: Sequence) -> tuple[np.ndarray, list[float]]:
    registration = ScanOdometry(seq.config, initial_pose=seq.reference[0])
    seconds = []
    for scan in seq.scans:
        start = time.perf_counter()
        registration.register(scan)
        seconds.append(time.perf_counter() - start)
    return registration.poses, seconds


def reference_floor(seq: Sequence) -> np.ndarray:
    """Our matcher given the answer: each scan registered, from its reference pose, against
    a map of the previous scans placed at their reference poses (no prior pull).

    Its relative error is what the reference and the matcher disagree by when no drift
    is left: on a real log, whose reference is itself an estimate, a floor to read the
    others against.
    """
    c = seq.config
    local_map = LocalMap(voxel_size=c.map_voxel_size, radius=c.map_radius,
                         max_count=c.map_max_count, min_points=c.min_plane_points,
                         flatness=c.flatness, scans_2d=c.scans_2d)
    origin = seq.reference[0][:3, 3]
    poses = []
    for k, scan in enumerate(seq.scans):
        reference = seq.reference[k].copy()
        reference[:3, 3] -= origin
        source = prepare_source(scan.points, c, scan.range_sigma)
        pose = reference if k == 0 else register_scan(
            source, local_map, Prior(reference, np.eye(6)), c.initial_threshold, c).pose
        local_map.insert(source.cloud, k + 1, source.cloud_variance, reference)
        local_map.forget_far(reference[:3, 3])
        pose[:3, 3] += origin
        poses.append(pose)
    return np.array(poses)


def _scan_to_scan(seq: Sequence, prepare: Callable, align: Callable) -> tuple[np.ndarray, list]:
    """Chain of previous-scan registrations seeded with the odometry increment."""
    poses, seconds = [seq.reference[0]], []
    start = time.perf_counter()
    target = prepare(seq.peer_points(0))
    seconds.append(time.perf_counter() - start)
    for k in range(1, len(seq.scans)):
        start = time.perf_counter()
        source = prepare(seq.peer_points(k))
        step = align(source, target, seq.odometry_step(k))
        seconds.append(time.perf_counter() - start)
        poses.append(poses[-1] @ step)
        target = source
    return np.array(poses), seconds


def run_open3d(seq: Sequence, method: str) -> tuple[np.ndarray, list[float]]:
    import open3d as o3d

    reg = o3d.pipelines.registration
    criteria = reg.ICPConvergenceCriteria(max_iteration=30)

    def prepare(points):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        cloud = cloud.voxel_down_sample(seq.peer_voxel)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * seq.peer_voxel,
                                                                     max_nn=30))
        return cloud

    def align(source, target, guess):
        if method == "plane":
            result = reg.registration_icp(source, target, seq.peer_correspondence, guess,
                                          reg.TransformationEstimationPointToPlane(), criteria)
        else:
            result = reg.registration_generalized_icp(
                source, target, seq.peer_correspondence, guess,
                reg.TransformationEstimationForGeneralizedICP(), criteria)
        return np.asarray(result.transformation)

    return _scan_to_scan(seq, prepare, align)


def _gicp_prepare(seq: Sequence, points: np.ndarray):
    """small_gicp's downsampled cloud and KD-tree of `points`, single-threaded."""
    import small_gicp

    return small_gicp.preprocess_points(points, downsampling_resolution=seq.peer_voxel,
                                        num_neighbors=20, num_threads=1)


def _gicp_align(seq: Sequence, source, target, guess: np.ndarray) -> np.ndarray:
    """small_gicp GICP of a prepared `source` onto a prepared `target` from `guess`."""
    import small_gicp

    result = small_gicp.align(target[0], source[0], target[1], guess, registration_type="GICP",
                              max_correspondence_distance=seq.peer_correspondence,
                              num_threads=1)
    return np.asarray(result.T_target_source)


def run_small_gicp(seq: Sequence) -> tuple[np.ndarray, list[float]]:
    return _scan_to_scan(seq, lambda points: _gicp_prepare(seq, points),
                         lambda source, target, guess: _gicp_align(seq, source, target, guess))


def run_kiss(seq: Sequence) -> tuple[np.ndarray, list[float]]:
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    config = KISSConfig()
    config.data.max_range = seq.max_range
    config.data.min_range = seq.min_range
    config.data.deskew = False
    config.mapping.voxel_size = seq.max_range / 100.0
    config.registration.max_num_threads = 1
    config.adaptive_threshold.initial_threshold = 0.3
    kiss = KissICP(config)
    poses, seconds = [], []
    for k in range(len(seq.scans)):
        points = seq.peer_points(k)
        start = time.perf_counter()
        if k:
            kiss.last_delta = seq.odometry_step(k)  # odometry as its motion prediction
        kiss.register_frame(points, np.zeros(len(points)))
        seconds.append(time.perf_counter() - start)
        poses.append(seq.reference[0] @ kiss.last_pose)
    return np.array(poses), seconds


METHODS: dict[str, Callable[[Sequence], tuple[np.ndarray, list[float]]]] = {
    "Open3D point-to-plane ICP": partial(run_open3d, method="plane"),
    "Open3D GICP": partial(run_open3d, method="gicp"),
    "small_gicp GICP": run_small_gicp,
    "KISS-ICP": run_kiss,
}


def _scores(poses: np.ndarray, seconds: list[float], seq: Sequence) -> dict:
    relative = relative_errors(poses, seq.reference, 1.0)
    return {"median_s": float(np.median(seconds[1:] or seconds)),
            "ate_m": ate_rmse(poses, seq.reference, "se2"),
            "rel_1m_m": relative.mean_translation, "drift_per_m": relative.per_metre}


def _all_methods(seq: Sequence) -> tuple[dict, dict]:
    """(runs, failures): every method's (poses, seconds) on `seq`, and the peers that
    failed with the reason."""
    runs, failed = {"ours": run_ours(seq)}, {}
    for name, method in METHODS.items():
        try:
            runs[name] = run_isolated(method, seq)
        except PeerFailed as exc:  # a peer that fails is reported, not fatal
            failed[name] = {"failed": str(exc)}
    runs["odometry alone"] = (seq.odometry_poses(), [0.0])
    return runs, failed


def _starting_at(seq: Sequence, start: int) -> Sequence:
    """`seq` from scan `start` on."""
    return replace(seq, scans=seq.scans[start:], reference=seq.reference[start:])


def _mean_over_starts(seq: Sequence, runs: dict, starts: tuple[int, ...]) -> dict:
    """Every method's scores on `seq` started at each of `starts` (the first: `runs`),
    averaged: the figures, with each start's 1 m relative error (`rel_1m_by_start_m`)."""
    scores = {name: [_scores(*run, seq)] for name, run in runs.items()}
    for start in starts[1:]:
        later, _ = _all_methods(_starting_at(seq, start))
        for name, run in later.items():
            if name in scores:
                scores[name].append(_scores(*run, _starting_at(seq, start)))
    return {name: {**{key: float(np.mean([s[key] for s in values])) for key in values[0]},
                   "rel_1m_by_start_m": [s["rel_1m_m"] for s in values]}
            for name, values in scores.items()}


def compare(seq: Sequence, starts: tuple[int, ...] = (0,)) -> list[dict]:
    """Ours and every peer on `seq`: one row; on a real log also the rows that judge its
    reference (`reference_noise`, `scan_agreement`).

    starts: first scans the real logs are registered from; the figures are the means over
    them (ours changes by a few mm from one start to another, the scan-to-scan peers by
    less: one start compares luck)."""
    runs, failed = _all_methods(seq)
    real = seq.name.startswith("real")
    scores = _mean_over_starts(seq, runs, starts if real else (0,))
    ours = scores.pop("ours")
    peers = failed | scores
    key = "rel_1m_m" if real else "ate_m"
    for values in peers.values():
        if key in values:
            values["error"] = values[key]
    points = int(np.median([len(s) for s in seq.scans]))
    over = f", mean over {len(starts)} starts (scans {', '.join(map(str, starts))})" \
        if real and len(starts) > 1 else ""
    row = {"stage": "registration", "method": "ours: ScanOdometry (planar, scan-to-map)",
           "sequence": seq.name,
           "settings": f"{seq.name}, {len(seq.scans)} scans, {points} points/scan{over}",
           "median_s": ours["median_s"], "error": ours[key],
           "error_unit": "m, mean error of 1 m relative motions" if real
           else "m, ATE RMSE (SE(2)-aligned)",
           **{k: v for k, v in ours.items() if k != "median_s"}, "peers": peers}
    if not real:
        return [row]
    return [row, reference_noise(seq), scan_agreement({"reference poses": seq.reference}
                                                      | {n: r[0] for n, r in runs.items()}, seq)]


def reference_noise(seq: Sequence) -> dict:
    """How far a perfect estimate would score from this log's reference: its own error.

    Estimates err against the reference by their own error plus the reference's; what two
    of them share (`shared_error`) is the reference's, if their own errors are
    independent. Three estimates, in pairs: two matchers each started at the reference
    pose of every scan, against the previous scans placed at their reference poses (ours;
    small_gicp against the last 10 scans, in a process of its own), and the wheel
    odometry, a sensor the matchers' errors cannot share. The row's figure is the two
    matchers' share; if small_gicp fails, what ours and the odometry share.
    """
    estimates = {"ours": reference_floor(seq), "odometry": seq.odometry_poses()}
    peers = {}
    try:
        estimates["small_gicp"] = run_isolated(small_gicp_floor, seq)
    except PeerFailed as exc:
        peers["small_gicp from the reference poses"] = {"failed": str(exc)}
    errors = {name: relative_errors(poses, seq.reference, 1.0)
              for name, poses in estimates.items()}
    matchers = [name for name in ("ours", "small_gicp") if name in errors]
    peers |= {f"{name} from the reference poses": {"error": errors[name].mean_translation}
              for name in matchers}
    peers |= {f"shared by {name} and odometry": {"error": shared_error(errors[name],
                                                                        errors["odometry"])}
              for name in matchers}
    pair = ("ours", "small_gicp" if "small_gicp" in errors else "odometry")
    return {"stage": "registration", "method": "reference noise: error of a perfect estimate",
            "sequence": seq.name, "settings": f"{seq.name}: what {pair[0]} and {pair[1]} "
            "from the reference poses share", "median_s": None,
            "error": shared_error(errors[pair[0]], errors[pair[1]]),
            "error_unit": "m, mean error of 1 m relative motions", "peers": peers}


def small_gicp_floor(seq: Sequence, previous: int = 10) -> np.ndarray:
    """small_gicp GICP of each scan, from its reference pose, against the `previous` scans
    before it placed at their reference poses."""
    origin = seq.reference[0][:3, 3].copy()
    reference = seq.reference.copy()
    reference[:, :3, 3] -= origin
    world = [seq.peer_points(k) @ reference[k][:3, :3].T + reference[k][:3, 3]
             for k in range(len(seq.scans))]
    poses = [reference[0]]
    for k in range(1, len(seq.scans)):
        target = _gicp_prepare(seq, np.vstack(world[max(0, k - previous):k]))
        source = _gicp_prepare(seq, seq.peer_points(k))
        poses.append(_gicp_align(seq, source, target, reference[k]))
    poses = np.array(poses)
    poses[:, :3, 3] += origin
    return poses


def scan_agreement(trajectories: dict[str, np.ndarray], seq: Sequence, lag: int = 2) -> dict:
    """A measure without a reference: how well each trajectory lays scan k onto scan k-lag.

    Per scan, the median distance of its points to the line through their two nearest
    neighbours in scan k-lag (2-D, within 0.3 m); the row's figure is the median over
    the scans. Scans 2 apart are about 1.3 m apart on the logs: the 1 m scale.
    """
    from scipy.spatial import cKDTree

    clouds = [seq.peer_points(k)[:, :2] for k in range(len(seq.scans))]
    clouds = [np.unique(c, axis=0) for c in clouds]  # extruded copies share x, y

    def residual(poses: np.ndarray) -> float:
        xy = [c @ p[:2, :2].T + p[:2, 3] for c, p in zip(clouds, poses, strict=True)]
        medians = []
        for k in range(lag, len(xy)):
            distance, index = cKDTree(xy[k - lag]).query(xy[k], k=2, distance_upper_bound=0.3)
            near = np.isfinite(distance).all(axis=1)
            if near.sum() < 10:
                continue
            a, b = xy[k - lag][index[near, 0]], xy[k - lag][index[near, 1]]
            tangent = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), 1e-9)
            offset = xy[k][near] - a
            medians.append(np.median(np.abs(offset[:, 0] * tangent[:, 1]
                                            - offset[:, 1] * tangent[:, 0])))
        return float(np.median(medians))

    figures = {name: residual(poses) for name, poses in trajectories.items()}
    return {"stage": "registration", "method": "scan agreement (no reference needed)",
            "sequence": seq.name,
            "settings": f"{seq.name}: scan k on scan k-{lag}, median point-to-line distance",
            "median_s": None, "error": figures.pop("ours"),
            "error_unit": "m, median point-to-line distance",
            "peers": {name: {"error": value} for name, value in figures.items()}}


def timing_20k(seq: Sequence, quick: bool) -> dict:
    """Ours per scan of exactly 20,000 points (preprocessing included), compile time apart.

    Wall time (median_s) and this process's CPU time (cpu_s): on a shared machine the
    second is what the code costs, the first what the neighbours left of it.
    """
    rng = np.random.default_rng(0)
    scans = [s.select(np.sort(rng.choice(len(s), 20_000, replace=False)))
             for s in seq.scans if len(s) >= 20_000]
    registration = ScanOdometry(seq.config, initial_pose=seq.reference[0])
    compile_s = first_call_time(lambda: registration.register(scans[0]))
    wall, cpu = [], []
    for k in range(1, min(len(scans), 12 if quick else 40)):
        start, start_cpu = time.perf_counter(), time.process_time()
        registration.register(scans[k])
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return {"stage": "registration", "method": "ours: ScanOdometry per 20,000-point scan",
            "settings": f"{seq.name}, preprocessing + ICP + map update",
            "median_s": float(np.median(wall)), "cpu_s": float(np.median(cpu)),
            "error": None, "error_unit": "", "compile_s": compile_s, "budget_s": 0.010,
            "peers": {}}


def log_table(rows: list[dict]) -> str:
    """One line per real log: 1 m relative error (mm) of ours, each peer, the odometry
    alone and the reference-noise floor, and the median time per scan (ms)."""
    ours = {r["sequence"]: r for r in rows if r.get("sequence", "").startswith("real")
            and r["method"].startswith("ours")}
    floors = {r["sequence"]: r["error"] for r in rows if r.get("sequence") in ours
              and r["method"].startswith("reference noise")}
    lines = ["| log | ours mm (ms/scan) | " + " | ".join(f"{n} mm (ms/scan)" for n in METHODS)
             + " | odometry alone mm | reference noise mm |",
             "|---" * (len(METHODS) + 4) + "|"]
    for sequence, row in ours.items():
        cells = [f"{1e3 * row['error']:.1f} ({1e3 * row['median_s']:.1f})"]
        for name in METHODS:
            peer = row["peers"][name]
            cells.append(f"failed: {peer['failed']}" if "failed" in peer
                         else f"{1e3 * peer['error']:.1f} ({1e3 * peer['median_s']:.1f})")
        cells.append(f"{1e3 * row['peers']['odometry alone']['error']:.1f}")
        floor = floors.get(sequence)
        cells.append("-" if floor is None else f"{1e3 * floor:.1f}")
        lines.append(f"| {sequence} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run(quick: bool = False, only: str | None = None) -> list[dict]:
    """Rows for every sequence (fewer and shorter ones with `quick`).

    only: keep just the sequences whose key contains it ("intel", "real", "corridor";
    keys: sim-corridor, sim-office, real-<log> for each log of `carmen_logs`, rendered-office,
    rendered-corridor); the 20,000-point timing row comes with "timing" or no filter.
    """
    builders = {"sim-corridor": partial(simulated, "corridor", 13 if quick else None),
                "sim-office": partial(simulated, "office", 6 if quick else None)}
    logs = carmen_logs()
    builders |= {f"real-{name}": partial(carmen, name, QUICK_SCANS if quick else None)
                 for name in logs if not quick or name in QUICK_LOGS}
    if not quick:
        builders |= {"rendered-office": partial(rendered, "office", 6),
                     "rendered-corridor": partial(rendered, "corridor", 8)}
    rows, corridor = [], None
    if only is None or only in "timing":
        corridor = builders["sim-corridor"]()
        rows.append(timing_20k(corridor, quick))
    for key, build in builders.items():
        if only is None or only in key:
            rows += compare(corridor if key == "sim-corridor" and corridor else build(),
                            (0,) if quick else STARTS)
    return rows


if __name__ == "__main__":
    import argparse

    from benchmarks.report import markdown_table

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer and shorter sequences")
    parser.add_argument("--only", help="only sequences whose key contains this (e.g. real, "
                        "intel, aces, sim, rendered, timing)")
    args = parser.parse_args()
    rows = run(quick=args.quick, only=args.only)
    print(markdown_table(rows))
    print()
    print(log_table(rows))
