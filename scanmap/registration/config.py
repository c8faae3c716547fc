"""Settings of scan-to-map registration, with the reasoning behind each default.

Defaults suit the reference scanner: 0.3-4 m ranges, floor to 1 m height, about
20,000 points per 360 deg scan, indoor robot on a flat floor.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from scanmap_driver.errors import RegistrationError


@dataclass(frozen=True)
class RegistrationConfig:
    """How a scan is prepared, matched against the local map and judged.

    planar: estimate (x, y, yaw) only (flat floor); False estimates full SE(3).
    voxel_size: source downsampling (m): one mean point per voxel. 0.1 m keeps walls,
      door jambs and box faces while cutting 20,000 points to about 2,000.
    map_voxel_size: edge (m) of the local map's plane-fitting voxels.
    flatness: a voxel is a plane (line) when its thickness variance is at most this
      fraction of its spread's; min_plane_points: points needed to judge a voxel.
    scans_2d: the points come from a 2-D laser (all at one height, e.g. CARMEN logs):
      a straight footprint is a wall. Otherwise (3-D scans) a wall is a near-vertical
      plane, which a sliver of a table top cut by the voxel grid is not.
    min_range, max_range: horizontal distance (m) from the scanner axis kept.
    floor_band: planar mode drops points within this height (m) of the floor: it
      constrains only z, roll and pitch, which planar mode does not estimate. Points
      farther below stay: a hole's, a pit's or a step down's walls fix x and y as walls
      do, where a corridor's own walls leave its axis to odometry (rendered random rooms
      1-6 and mixed rooms 1-10: ATE summed over the 16 rooms 14.3 -> 13.4 cm, the mixed
      rooms' worst 3.1 cm as before). SE(3) mode keeps them all.
    map_radius: the local map forgets voxels farther than this (m) from the robot.
    map_max_count: points' worth of statistics a map voxel keeps (older ones fade).
    max_normal_angle: a match's map normal must agree with the source normal within this
      (rad), or it is another surface.
    max_iterations, tolerance: Gauss-Newton stops when a step is below tolerance
      (m, and rad times 1 m).
    initial_threshold: correspondence distance (m) until the adaptive threshold has
      seen enough scans; min_threshold, max_threshold bound the adaptive one.
    sigma_floor: model error (m) added in quadrature to each point's range sigma (map
      planes and sampling are not exact).
    default_range_sigma: range sigma (m) of points that carry none.
    min_constraint: a direction is degenerate when the geometry constrains it less
      than this many well-aligned points would.
    min_points: fewer source points than this: too few to register.
    min_fitness: fewer inliers than this fraction after all attempts: no overlap.
    recovery_fitness: below this inlier fraction, a coarse (x, y, yaw) search around
      the guess looks for a better start (large initial errors).
    recovery_drop: the coarse search also runs below this fraction of the median fitness
      of the last ten registered scans. Successive scans see mostly the same scene, so a
      fitness that halves says the guess was far off (a turn on the spot whose odometry
      slipped by 8 deg, in a place where a fitness of 0.46 is above recovery_fitness).
      Over three start scans of the seven CARMEN logs, 1 m relative error 51.3 -> 50.5 mm
      on average (Belgioioso 36.0 -> 29.7, Intel 45.8 -> 45.3, Freiburg's first start
      36.8 -> 36.3; FHW's second start 53.3 -> 56.2; the others within 0.2 mm). Never
      above recovery_fitness for the 3-D scanner (0.5): there it changes nothing.
      2-D scans use 0.8 (`for_2d_scans`): with blobs matched, a wrong turn can keep a
      fitness of 0.51 (Belgioioso, scan 143: 12.9 deg off). A search's alignment
      replaces ICP's from the guess only if its fitness is higher and the map's
      likelihood prefers it; searches run on 10-18% of the scans, about 6 ms each
      (`recovery`).
    search_radius, search_angle: half-width of that search (m, rad).
    max_correction, max_rotation: a result moved farther than this from the guess
      (m, rad) is called diverged.
    consistency_level: the self-check against the prior. A correction (guess to result)
      whose Mahalanobis distance under the prior's covariance lies beyond this quantile
      of the chi-square distribution disagrees with odometry; the scan then keeps the
      prior (status INCONSISTENT) unless the map clearly fits the matched pose better
      than the prior's (the coarse search's likelihood score, by the margin that search
      needs to move a start). 1 turns the check off.
    restart_after: after this many failed scans in a row the map is stale (the robot was
      carried away, or the scene changed): it restarts from the next scan at its guess.
    match_blobs: with `scans_2d`, also match points that are no line (posts, corners)
      point-to-distribution (see `icp`); without, only walls count.
    """

    planar: bool = True
    voxel_size: float = 0.1
    map_voxel_size: float = 0.1
    flatness: float = 0.1
    min_plane_points: int = 4
    scans_2d: bool = False
    min_range: float = 0.3
    max_range: float = 4.0
    floor_band: float = 0.05
    map_radius: float = 6.0
    map_max_count: int = 30
    max_normal_angle: float = 0.5
    max_iterations: int = 20
    tolerance: float = 1e-4
    initial_threshold: float = 0.2
    min_threshold: float = 0.05
    max_threshold: float = 0.3
    sigma_floor: float = 0.01
    default_range_sigma: float = 0.01
    min_constraint: float = 10.0
    min_points: int = 20
    min_fitness: float = 0.25
    recovery_fitness: float = 0.5
    recovery_drop: float = 0.5
    search_radius: float = 0.5
    search_angle: float = 0.5
    max_correction: float = 1.0
    max_rotation: float = 0.8
    consistency_level: float = 0.999
    restart_after: int = 3
    match_blobs: bool = True

    @classmethod
    def for_2d_scans(cls, max_range: float = 12.0, **changes: float | bool) -> RegistrationConfig:
        """Settings for a 2-D laser scanner (e.g. CARMEN logs: 180 beams at one height).

        Walls are lines of the single scan plane (`scans_2d`), and what is no line (a
        post, a corner, clutter) is matched point-to-distribution (see `icp`); a scan has
        ~150 usable points, so one well-aligned point already counts (min_constraint 1) and a scan
        sees much the map has not (min_fitness 0.1, coarse search below 0.3); ranges to
        `max_range` and a map as wide. The voxels stay 0.1 m: of (0.05, 0.1, 0.15) m
        for source and map, (0.1, 0.1) did best over the Intel and ACES logs together.
        flatness 0.3: a far wall's voxel holds a few beams 1 deg apart, whose thickness
        the range-noise test already bounds; the stricter 0.1 drops such walls. Over
        five start scans, 1 m relative error went from 47.2 +- 1.9 to 44.1 +- 1.6 mm
        (Intel) and 55.5 +- 2.2 to 53.4 +- 1.3 mm (ACES); 0.2 to 0.5 all do as well.
        """
        settings = {"scans_2d": True, "min_range": 0.1, "max_range": max_range,
                    "flatness": 0.3, "floor_band": 0.0, "map_radius": max_range,
                    "min_constraint": 1.0, "min_fitness": 0.1, "recovery_fitness": 0.3,
                    "recovery_drop": 0.8, "max_threshold": 0.5}
        return cls(**{**settings, **changes})

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("planar", "scans_2d", "match_blobs"):
                continue
            if not isinstance(value, (int, float)) or not value >= 0:
                raise RegistrationError(f"RegistrationConfig.{f.name}: expected a number >= 0, "
                                        f"got {value!r}")
        if not (self.voxel_size > 0 and self.map_voxel_size > 0):
            raise RegistrationError("RegistrationConfig: voxel sizes must be positive")
        if not self.min_range < self.max_range:
            raise RegistrationError(f"RegistrationConfig: min_range {self.min_range} must be "
                                    f"below max_range {self.max_range}")
        if not self.consistency_level <= 1:
            raise RegistrationError("RegistrationConfig.consistency_level: a probability, "
                                    f"got {self.consistency_level}")
        if not self.min_threshold <= self.max_threshold:
            raise RegistrationError("RegistrationConfig: min_threshold > max_threshold")
