"""The grid's geometry and sensor model (`GridConfig`): what a grid, a submap packed for
merging and a map file must agree on."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from scanmap_driver.errors import MapError


@dataclass(frozen=True)
class GridConfig:
    """Geometry and sensor model of a grid.

    resolution: cell side (m). tile_cells: cells per tile side (a power of 2).
    levels: K, the most height intervals a cell keeps. extent: half side (m) of the
    square around the map origin that the grid may cover. window: side (m) of the
    rolling window around the robot, or None for a map that keeps everything seen.
    z_min, mask_dz: bottom and bin height of the 64-bin observed-height mask.
    merge_gap: hits closer than this in height join one level (m).
    clear_margin: the last metres of a ray before its hit clear nothing.
    protect: a level hit in a scan keeps, in that scan, the space within this height of
    its hits from being cleared (m). Keep it below the robot's step height (5 cm by
    default) by more than the floor's noise: the floor where a person stood, merged with
    the foot into one level and hit on the floor in every scan, is cut down by later
    rays only to this scan's floor hits plus `protect`, and must end below the robot's
    band (at 5 cm such cells stayed obstacles for tens of scans in the people scene).
    static_scans, pass_radius: a level hit in at least `static_scans` scans (about 16 s
    at the scanner's 2 s a turn: a wall, furniture), or beside such a level at its
    heights in a neighbouring cell, is cleared only by rays that pass within
    `pass_radius` (m, x-y) of the level's mean hit. Where a face cuts a cell, rays
    through the cell's free part would otherwise clear the face; a level seen briefly (a
    person passing) clears from any pass through its cell. At 10 scans, a cabinet's end
    face seen only while the robot came towards it (8-9 scans) eroded in people rooms 10
    and 12 (60 cell-scans); at 8 (with `see_through`), over `people_rooms(12)`: eroded
    63 -> 3 cell-scans, ghost cells 5105 -> 5174, seen through 412 -> 449, `people` 1423
    -> 1426 and 38 -> 38. At 7 the floor level under a person who stood six scans turns
    static before later rays have trimmed the foot off it (test_grid's walking person:
    3 cells left, not 2); at 5, `people` 94 seen through. Beside a static level (a
    cabinet's end or corner next to its long face), over people rooms 1-6 and 13-30:
    eroded 431 -> 345 cell-scans, FREE 40 -> 13, ghost cell-scans 11741 -> 11973,
    seen through 1130 -> 1202; `people` 1426 -> 1445 and 38 -> 40. Nor does a ray near a
    static level's mean hit clear it where every static level in the cells round it lies
    on one side of the ray (two or more): it passed a corner, as at a turned cabinet's,
    whose two faces' mean hit lies within `pass_radius` of both. Over people rooms
    18000-18002 and 19000-19002: wall cell-scans FREE 23 -> 0, eroded 252 -> 229, ghost
    cell-scans 1460 -> 1467, seen through 105 -> 106; rooms 13-30: eroded 386 (none FREE)
    either way, ghost cell-scans 4950 -> 5020, seen through 420 -> 458 (a person who
    stood `static_scans` scans is a static blob whose rim cells rays pass on one side);
    `people` 500 -> 506 and 8 -> 8; the office's grid figures the same. The sides are
    read from the ray's own line, a neighbour's mean hit within half `pass_radius` of it
    on neither (rays within millimetres of a corner had its cell's mean hit on their far
    side): over people rooms 18000-18002, 19000-19002, 19400-19402 and 20000-20002 wall
    cell-scans eroded 261 -> 249, FREE 19 -> 7, ghost cell-scans 2884 -> 2907, seen
    through 269 -> 272; `people` 506 -> 508 and 8 -> 8.
    graze_angle: nor is such a level (or one hit in at least half `static_scans` scans)
    cleared by a ray within this angle (degrees, x-y; 0 turns the rule off) of the face's
    direction, read from the mean hits of the static levels in the 8 neighbouring cells:
    seen from nearly in its plane, the face's cells are crossed close to their mean hit,
    which lies on the face (a cabinet's end face in `people_room(6)`, crossed at 3-7 deg,
    eroded so). A person who stood for `static_scans` scans leaves such lines of cells
    too: larger angles keep them longer (over `people_rooms_run(6)`, ghost cells seen
    through 559 at 20 deg, 543 at 10, 541 without the rule).
    see_through: a level hit in one scan only is removed by one pass of a ray that goes
    on at least this far (m) beyond its cell (inf: never; such a pass is one miss), unless
    a neighbouring cell holds a level at its heights hit in two scans or more. One scan's
    hits weigh no more than one look through them: a person seen in one scan leaves thin
    levels that later scans cross with one frame's rays a scan or two, where three
    misses were needed. Nearer its hit a ray may graze the surface it hits (a wall first
    seen at range), and beside a surface seen longer the level may be its rarely hit rim
    (the office's table tops, hit in one or two of 24 scans at their edges: obstacle F1
    0.9954 -> 0.9928 without that exception); both take one miss. Over
    `people_rooms(12)`, with `static_scans` 10: ghost cells seen through 645 -> 412, all
    ghost cells 6608 -> 5105, wall cell-scans eroded 63 -> 63 (5 rooms, as before);
    `people` 65 -> 38 and 1684 -> 1423; the office's F1 unchanged. At 0.2 m about the
    same, at 0.5 m and 1 m fewer cleared; from any pass, 3 cells eroded in rooms 1-6
    against 1.
    max_range: rays longer than this are dropped (m).
    l_hit, l_miss, l_max: log-odds added per hit and removed per pass (once per scan and
    at most `max_misses` times per scan, respectively), and the clamp.
    bundle_run: a ray stops after this many cells in a row already updated by a ray from
    the same origin (0: trace every ray to its origin; see grid_kernels).
    """

    resolution: float = 0.05
    tile_cells: int = 64
    levels: int = 3
    extent: float = 1000.0
    window: float | None = None
    z_min: float = -0.35
    mask_dz: float = 0.025
    merge_gap: float = 0.10
    clear_margin: float = 0.1
    protect: float = 0.03
    pass_radius: float = 0.0175
    static_scans: int = 8
    graze_angle: float = 10.0
    see_through: float = 0.3
    max_range: float = 20.0
    l_hit: float = 0.85
    l_miss: float = 0.4
    l_max: float = 3.5
    max_misses: int = 5
    bundle_run: int = 3

    def __post_init__(self) -> None:
        positive = ("resolution", "extent", "mask_dz", "merge_gap", "max_range", "l_hit",
                    "l_miss", "l_max")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise MapError(f"GridConfig.{name}: expected a finite number > 0, got {value!r}")
        for name in ("clear_margin", "protect", "pass_radius"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise MapError(f"GridConfig.{name}: expected a finite number >= 0, got {value!r}")
        if not (isinstance(self.see_through, (int, float)) and self.see_through >= 0):
            raise MapError(f"GridConfig.see_through: expected metres >= 0 or inf, "
                           f"got {self.see_through!r}")
        if not (isinstance(self.graze_angle, (int, float)) and 0 <= self.graze_angle < 90):
            raise MapError(f"GridConfig.graze_angle: expected degrees in [0, 90), "
                           f"got {self.graze_angle!r}")
        if not math.isfinite(self.z_min):
            raise MapError(f"GridConfig.z_min: expected a finite number, got {self.z_min!r}")
        t = self.tile_cells
        if not (isinstance(t, int) and 8 <= t <= 1024 and t & (t - 1) == 0):
            raise MapError(f"GridConfig.tile_cells: expected a power of 2 in 8..1024, got {t!r}")
        if not (isinstance(self.levels, int) and 1 <= self.levels <= 16):
            raise MapError(f"GridConfig.levels: expected an integer 1..16, got {self.levels!r}")
        if not (isinstance(self.bundle_run, int) and self.bundle_run >= 0):
            raise MapError(f"GridConfig.bundle_run: expected an integer >= 0, "
                           f"got {self.bundle_run!r}")
        if not (isinstance(self.static_scans, int) and self.static_scans >= 1):
            raise MapError(f"GridConfig.static_scans: expected an integer >= 1, "
                           f"got {self.static_scans!r}")
        if not (isinstance(self.max_misses, int) and 1 <= self.max_misses <= 127):
            raise MapError(f"GridConfig.max_misses: expected 1..127, got {self.max_misses!r}")
        if self.window is not None and not (math.isfinite(self.window)
                                            and 0 < self.window <= 2 * self.extent):
            raise MapError(f"GridConfig.window: expected None or 0 < window <= 2*extent, "
                           f"got {self.window!r}")
        if self.tiles_per_side > 8192:
            raise MapError(f"GridConfig.extent: {self.extent} m needs {self.tiles_per_side} "
                           "tiles per side (max 8192); use larger tiles or cells")

    @property
    def tile_size(self) -> float:
        """Tile side in metres."""
        return self.tile_cells * self.resolution

    @property
    def tiles_per_side(self) -> int:
        """Tiles along each side of the extent."""
        return math.ceil(2.0 * self.extent / self.tile_size)

    @property
    def corner(self) -> float:
        """x and y (m) of the lower-left corner of tile (0, 0)."""
        return -0.5 * self.tiles_per_side * self.tile_size

    def to_dict(self) -> dict:
        """Plain values, for map files."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
