"""Scan-to-map odometry: register each new scan against a local map of the previous ones.

Per scan: predict the pose (odometry increment corrected for the scale and heading
drift measured so far, else constant velocity), prepare the scan (filter, de-skew with
the scan's own motion, downsample), register it against the local map with the
prediction as guess and weighted prior, then, if it registered, add its points to the
map and forget what is now far. A failed scan keeps the predicted
pose and stays out of the map; after `restart_after` failures in a row the map restarts.

Float precision: poses may be kilometres from the map origin. Everything inside is
relative to a local origin (the first pose, snapped to the voxel grid), in float64.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from scanmap.io.trajectory import Trajectory
from scanmap.registration.calibration import OdometryCalibration
from scanmap.registration.config import RegistrationConfig
from scanmap.registration.lie import pose_exp, pose_log, transport
from scanmap.registration.local_map import LocalMap
from scanmap.registration.matcher import register_scan
from scanmap.registration.preprocess import Source, prepare_source
from scanmap.registration.prior import OdometryNoiseConfig, Prior
from scanmap.registration.result import RegistrationResult, RegistrationStatus
from scanmap.registration.threshold import AdaptiveThreshold
from scanmap_driver.errors import RegistrationError
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import invert_pose, pose_to_se2, se2_to_pose

_UNKNOWN_SIGMA = 1.0  # m and rad: the first scans' guess without odometry
RECENT = 10  # registered scans whose median fitness a new scan is expected to reach


class ScanOdometry:
    """Registers a sequence of scans; `poses` and `results` grow with each call."""

    def __init__(self, config: RegistrationConfig | None = None,
                 noise: OdometryNoiseConfig | None = None,
                 initial_pose: np.ndarray | None = None) -> None:
        self.config = config or RegistrationConfig()
        self.noise = noise or OdometryNoiseConfig()
        self.initial_pose = np.eye(4) if initial_pose is None else \
            np.asarray(initial_pose, dtype=np.float64)
        self.threshold = AdaptiveThreshold(self.config)
        self.calibration = OdometryCalibration()
        self.local_map = self._new_map()
        self.origin = np.zeros(3)
        self.results: list[RegistrationResult] = []
        self.stamps: list[float] = []
        self._local: list[np.ndarray] = []  # map-local poses
        self._odometry: np.ndarray | None = None  # odometry at the last scan
        self._failures = 0
        self._carried = np.zeros((6, 6))  # uncertainty of the last pose the map did not fix

    def _new_map(self) -> LocalMap:
        c = self.config
        return LocalMap(voxel_size=c.map_voxel_size, radius=c.map_radius,
                        max_count=c.map_max_count, min_points=c.min_plane_points,
                        flatness=c.flatness, scans_2d=c.scans_2d)

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) poses in map of every scan so far."""
        out = np.array(self._local).reshape(-1, 4, 4)
        out[:, :3, 3] += self.origin
        return out

    def trajectory(self) -> Trajectory:
        """The poses so far with their scans' stamps."""
        return Trajectory(np.array(self.stamps), self.poses)

    def register(self, scan: Scan) -> RegistrationResult:
        """Register a Scan: its odom_start is the odometry prior, time and odom_end de-skew."""
        odometry = scan.odom_start if scan.has_odometry else None
        motion = invert_pose(scan.odom_start) @ scan.odom_end if scan.has_odometry else None
        return self.register_points(scan.points, stamp=scan.stamp, odometry=odometry,
                                    range_sigma=scan.range_sigma, times=scan.time,
                                    scan_motion=motion)

    def register_points(self, points: np.ndarray, *, stamp: float | None = None,
                        odometry: np.ndarray | None = None,
                        range_sigma: np.ndarray | None = None, times: np.ndarray | None = None,
                        scan_motion: np.ndarray | None = None) -> RegistrationResult:
        """Register (N, 3) base_link points taken at `stamp` with wheel `odometry` (4x4).

        times (N,) and scan_motion (base_link at the last point's time in base_link at the
        first's, from odometry) de-skew; without odometry the scan is taken as static.
        """
        stamp = float(len(self.stamps)) if stamp is None else float(stamp)
        if odometry is not None:
            odometry = np.asarray(odometry, dtype=np.float64)
            if odometry.shape != (4, 4) or not np.isfinite(odometry).all():
                raise RegistrationError(f"odometry: expected a finite 4x4 pose, got shape "
                                        f"{odometry.shape}")
        if not self._local:
            self.origin = self._snap(self.initial_pose[:3, 3])
        prior = self._predict(stamp, odometry)
        source = prepare_source(points, self.config, range_sigma, times, scan_motion)
        if not self._local:
            result = RegistrationResult(pose=prior.pose, covariance=np.zeros((6, 6)),
                                        status=RegistrationStatus.INITIALISED,
                                        num_points=len(source),
                                        message="first scan: the map starts here")
        else:
            result = register_scan(source, self.local_map, prior, self.threshold.value,
                                   self.config, self._expected_fitness())
        self._accept(result, prior, source, stamp, odometry)
        absolute = result.pose.copy()
        absolute[:3, 3] += self.origin
        result = replace(result, pose=absolute)
        self.results.append(result)
        return result

    def _snap(self, position: np.ndarray) -> np.ndarray:
        voxel = self.config.map_voxel_size
        origin = np.round(position / voxel) * voxel
        origin[2] = 0.0
        return origin

    def _predict(self, stamp: float, odometry: np.ndarray | None) -> Prior:
        """Guess and prior for the scan at `stamp` (map-local)."""
        if not self._local:
            pose = self.initial_pose.copy()
            pose[:3, 3] -= self.origin
            return Prior(pose, np.eye(6) * _UNKNOWN_SIGMA ** 2)
        last = self._local[-1]
        if odometry is not None and self._odometry is not None:
            step = self.calibration.correct(invert_pose(self._odometry) @ odometry)
            covariance = self.noise.odometry_covariance(step)
        elif len(self._local) >= 2:
            step = invert_pose(self._local[-2]) @ last
            gaps = np.diff(self.stamps[-2:] + [stamp])
            if gaps[0] > 0 and gaps[1] > 0:
                step = _scaled_motion(step, gaps[1] / gaps[0])
            covariance = self.noise.guess_covariance()
        else:
            step = np.eye(4)
            covariance = np.eye(6) * _UNKNOWN_SIGMA ** 2
        if self.config.planar:
            step = se2_to_pose(*pose_to_se2(step))
        # The last scan's pose is only its prior when it did not register: its uncertainty
        # carries into this one's (a wrong turn kept from odometry must stay correctable).
        return Prior(last @ step, covariance + transport(self._carried, step))

    def _accept(self, result: RegistrationResult, prior: Prior, source: Source,
                stamp: float, odometry: np.ndarray | None) -> None:
        """Record the pose; grow the map with a registered scan, or count a failure."""
        self._carried = np.zeros((6, 6)) if result.ok else prior.covariance
        if result.ok:
            self._failures = 0
            if self._local:
                motion = invert_pose(self._local[-1]) @ prior.pose
                self.threshold.update(invert_pose(prior.pose) @ result.pose, motion)
                if odometry is not None and self._odometry is not None and not result.degenerate:
                    self.calibration.update(invert_pose(self._odometry) @ odometry,
                                            invert_pose(self._local[-1]) @ result.pose)
            self._insert(result.pose, source)
        else:
            self._failures += 1
            if self._failures >= self.config.restart_after:
                self.local_map = self._new_map()
                self._insert(result.pose, source)
                self._failures = 0
                self._carried = np.zeros((6, 6))  # the new map starts at this pose
        self._local.append(result.pose)
        self.stamps.append(stamp)
        self._odometry = odometry

    def _expected_fitness(self) -> float:
        """Median fitness of the registered scans among the last RECENT (0 if none)."""
        recent = [r.fitness for r in self.results[-RECENT:] if r.ok and np.isfinite(r.fitness)]
        return float(np.median(recent)) if recent else 0.0

    def _insert(self, pose: np.ndarray, source: Source) -> None:
        self.local_map.insert(source.cloud, len(self._local) + 1, source.cloud_variance, pose)
        self.local_map.forget_far(pose[:3, 3])


def _scaled_motion(step: np.ndarray, factor: float) -> np.ndarray:
    """The motion `step` scaled by `factor` (constant velocity over a longer/shorter gap)."""
    return pose_exp(pose_log(step) * factor)
