"""What the segmentation is told: the robot's shape and the rules' tuning."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from scanmap.grid.unlit import floor_crossings
from scanmap_driver.errors import MapError
from scanmap_driver.scanner_model import ScannerModel


@dataclass(frozen=True)
class RobotShape:
    """What the robot drives over (step_height), under (height) and its footprint radius."""

    step_height: float = 0.05
    height: float = 1.0
    radius: float = 0.25

    def __post_init__(self) -> None:
        for name in ("step_height", "height", "radius"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise MapError(f"RobotShape.{name}: expected a finite number > 0, got {value!r}")
        if self.step_height >= self.height:
            raise MapError(f"RobotShape: step_height {self.step_height} must be below height "
                           f"{self.height}")


SCANNER_FIELDS = ("blind_range", "view_range", "emitter_height")  # None: the scanner's
HEADINGS = 8  # over a turn, where a tilted or offset head sees the floor unevenly


@dataclass(frozen=True)
class FloorConfig:
    """Tuning of the segmentation.

    thickness: most vertical extent (m) of a level that can be floor; clearance: free
    height above it (m) that a floor cell needs.
    plane_tolerance: distance (m) of the floor plane's inliers (its hypotheses are scored
    within seed_tolerance, `ransac_plane`), and the floor's noise elsewhere: a
    surface lower than that below the floor is a sign of a hole (a gap's rim dipping so
    is no gap). max_slope: steepest floor plane (rad).
    min_plane_cells: support of a reported plane. min_seed_cells, seed_tolerance: the
    floor grows from the largest plane's inliers, but from a patch of fewer than
    min_seed_cells of them (8-connected) only where within seed_tolerance (m) of the
    plane. A lone inlier may be the foot of a wall, hit up to plane_tolerance off the
    floor beside a floor a step lower (a dock 6 cm down), from which the floor would grow
    down there; lone floor samples (far off, between furniture) lie closer.
    fill_radius: how far (m) the height of a floor cell is carried into cells without
    observed floor (the largest floor plane gives it beyond). detect: False for data
    that never see the floor (a 2-D laser: every point at one height), which then rely
    on the `fallback_floor` of `segment`.
    min_coverage: fraction of the robot band's height bins that rays must have seen free
    for a cell to be FREE (as Nav2's voxel layer tolerates unknown voxels in a column).
    This scanner rarely sees every bin of a column (rays at 0.7-1 m over a cell 2 m away
    end beyond 4 m, returning nothing), so 1.0 leaves most of a room unknown; below 1, a
    thin object hanging in unseen heights is caught by the suspect rules of
    `classify_band` instead.
    overhang_reach: how far (m) the heights of an overhanging board (a table top seen
    only at its rim: this scanner's laser, 0.5 m up, never lights a top above it) are
    assumed to extend over cells that never saw those heights: 1 m covers a desk seen at
    one end only (at 0.6 m, cells under the far end of the office's table, which rays
    reached only beneath its top, were FREE); overhang_thickness: the thickest level
    taken for such a board (a table top, a seat, a shelf).
    coverage_reach: on known floor, band heights seen free this far (m) from a cell count
    for its coverage (0: the cell alone); the cell itself must have seen one.
    slope_reach: radius (m) of the neighbourhood a cell's floor slope is fitted over;
    plane_noise: the RMS (m) within which its cells fit one plane for it to be one
    surface, without a crease (`_plane_kernels.local_slope`): 3 mm, below the 4.4 mm a
    16 deg ramp's first row leaves with the floor before it, noise-free.
    drop_reach: how far (m) a drop-off spreads from the cells that show it through cells
    without observed floor, no farther from the nearest place the robot stood than they
    (and half a cell), nearer by at most rim_shadow times their range (and a cell), and
    within half of max_gap and a cell of the line of sight through one of them and a
    cell of it on its other side, or between two of them (from the nearest place the
    robot stood, if at least blind_range off): rays
    reach step_height and a height bin or two below the floor (`below_floor`) about
    (step_height + 2 mask_dz) / camera height times the range past the rim, 0.1 for a
    camera 1 m up. max_hole: the largest patch without hits (m, each side of its
    bounding box) inside consistent floor that is taken as floor. max_gap: the widest
    opening (m) between two floor samples along a row, column or diagonal taken as floor,
    measured between where the floor hits of the cells at its ends lie (their mean: the
    hits nearest the opening lie no farther out), from the far edge of an end cell without
    floor hits (it may be lit on part of its width only), away from any drop-off, surface
    below the floor model, level reaching more than a step below it or level reaching more than
    plane_tolerance below the floor beside it (`_dips`) (the diagonal of a hole max_gap
    plus two cells wide, as wide as a hole without unobserved space wider than max_gap in
    it: turned to the lines, its far wall lies that far from its near corner) and from any such
    wider unobserved space (max_gap): this scanner's lines lie r * 2 pi / 53 apart on the
    floor at range r (0.19 m at 1.6 m, 0.3 m at 2.5 m), so a hole of max_gap seen from
    2.5 m or nearer is crossed by a line and shows itself (below the floor, or a
    drop-off) before its cells are filled.
    floor_probe: rays that passed this low (m) over a cell's floor should have lit it
    (the stripe runs along them); without a return there it is not FREE. Nor is a cell
    without a hit within max_gap of floor a laser line crossed without a return
    (`CellLayers.unlit`, `scanmap.grid.unlit`: black carpet, a black-lined hole), however
    small the patch: no gap between samples lies there.
    min_logodds: the log-odds a level in the robot's band needs to make its cell an
    OBSTACLE. Below it the level is as likely gone as there (a surface seen in one scan
    and seen through twice since: 0.85 - 2 x 0.4 = 0.05 with the grid's defaults, a
    person who walked on): its cell is UNKNOWN, neither an obstacle nor free. Between
    0.05 and one hit less one miss (0.45), so a surface seen once and through once stays.
    max_pinhole: the largest patch (m, each side) of UNKNOWN cells without any hit whose
    every neighbour is FREE that is taken as FREE: a pinhole between the laser's samples
    in floor seen free all round (a hole there shows its far wall as hits, which are not
    FREE). 0.15 m: three cells, the span `interpolated` fills between floor samples.
    blind_range, view_range, emitter_height: the scanner's geometry, None (the default)
    for the floor the scanner measures (`for_scanner`, `floor_seen`: the Mapper's scanner
    model; `segment` alone, the reference scanner's).
    blind_range: the nearest floor (m) the scanner sees from where it stands (1.495 m for
    the reference scanner, its camera 1 m up): a drop-off's spread keeps to the line of
    sight from the nearest place the robot stood through a cell showing it only where
    that place lies at least this far off. Nearer, it was seen from elsewhere: from one
    of the places the robot stood blind_range to view_range off (any), whose line of
    sight and ranges then bound it, the rim's shadow reaching nearer by d /
    (emitter_height + d) of the range of a cell showing the floor missing d deep (at
    least rim_shadow).
    view_range: the farthest floor (m) the scanner sees (3.997 m: the reference scanner's
    max_range). emitter_height: the laser emitter's height (m) over the floor (0.5 m on
    the reference scanner): its light over a rim reaches d below the floor at
    (emitter_height + d) / emitter_height times the rim's range.
    """

    thickness: float = 0.06
    clearance: float = 0.2
    plane_tolerance: float = 0.03
    max_slope: float = math.radians(15.0)
    min_plane_cells: int = 100
    min_seed_cells: int = 3
    seed_tolerance: float = 0.01
    max_planes: int = 4
    fill_radius: float = 1.0
    min_coverage: float = 0.5
    coverage_reach: float = 0.05
    overhang_reach: float = 1.0
    overhang_thickness: float = 0.1
    ransac_iterations: int = 200
    seed: int = 0
    detect: bool = True
    slope_reach: float = 0.1
    plane_noise: float = 0.003
    drop_reach: float = 0.5
    rim_shadow: float = 0.1
    max_hole: float = 0.3
    max_gap: float = 0.3
    floor_probe: float = 0.1
    min_logodds: float = 0.2
    max_pinhole: float = 0.15
    blind_range: float | None = None
    view_range: float | None = None
    emitter_height: float | None = None

    def __post_init__(self) -> None:
        for name in SCANNER_FIELDS:
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float))
                                          and math.isfinite(value) and value > 0):
                raise MapError(f"FloorConfig.{name}: expected a finite number > 0, or None "
                               f"for the scanner's own, got {value!r}")

    def for_scanner(self, model: ScannerModel) -> FloorConfig:
        """This config with those of blind_range, view_range and emitter_height left None
        taken from the floor `model` measures (`floor_seen`); MapError naming them when it
        measures none."""
        unset = [name for name in SCANNER_FIELDS if getattr(self, name) is None]
        if not unset:
            return self
        seen = floor_seen(model)
        if seen is None:
            raise MapError(f"FloorConfig: scanner {model.name!r} measures no floor (its laser "
                           f"lights none in its camera's view): set {', '.join(unset)}")
        return replace(self, **{name: seen[name] for name in unset})


@functools.lru_cache(maxsize=8)
def floor_seen(model: ScannerModel) -> dict[str, float] | None:
    """The floor `model` measures round the robot: the nearest and farthest (blind_range,
    view_range: m from base_link's z axis) at any of HEADINGS headings, where its laser's
    line meets the floor z = 0 in its camera's view (`unlit.floor_crossings`: inside the
    image, the range limits and the ray-to-plane angle, not behind the encoder disk), and
    its emitter's height over the floor over a turn (emitter_height); None when it
    measures none. The reference scanner, its camera 1 m up and tilted 18 deg, its emitter
    0.5 m up: 1.495-3.997 m (its simulator's flat floor: 1.493-4.000 m); a camera 0.6 m up
    and its emitter 0.3 m: 0.836-3.989 m."""
    headings = np.arange(HEADINGS) * (2.0 * math.pi / HEADINGS)
    crossing, _, measured = floor_crossings(model, headings)
    if not measured.any():
        return None
    ranges = np.hypot(crossing[measured][:, 0], crossing[measured][:, 1])
    emitters = model.head_poses(headings) @ np.array([*model.laser.origin, 1.0])
    return {"blind_range": float(ranges.min()), "view_range": float(ranges.max()),
            "emitter_height": float(emitters[:, 2].mean())}
