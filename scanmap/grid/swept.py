"""Levels the laser plane swept in view and did not light: the space a person left.

The camera, 1 m up, passes 0.7 m over a cell r away only on its rays to the floor
r / 0.3 away, and it sees the floor from 1.49 to 3.99 m: so only for r within 0.45-1.2
m. Farther, no camera ray crosses the heights a person's body left there, and the
laser's rays through them (from 0.5 m up) reach the floor past its range: on `people`,
781 of the 1124 cell-scans still an obstacle three scans after a person left held a
level 0.46-0.80 m up, most of them never passed. The laser's plane sweeps them every
scan though, and a surface the plane crosses in the camera's view shows the stripe: each
image line looks along one line of the plane (`scanmap.grid.unlit`). So a frame whose
plane passes within SWEEP_TOLERANCE of a level's mean hit, where the camera sees it
(inside the image, between the scanner's least range and REACH), is evidence that
nothing is there, unless:

- the level's image line returned a point no farther from the camera than the level
  (plus OUTSHINE_MARGIN): one peak is kept per line, the strongest, so a nearer surface
  lit on the same line hides it (a person in front of a wall);
- a level this scan hit, or a static one, lies on the camera's or the emitter's line to
  it (outside the 3 x 3 cells round it): hidden or in shadow;
- this scan hit the level, or a level beside it at its height (NEAR_Z): a face on a
  cell's edge puts its hits either side of it;
- the level is static (hit in `static_scans` scans: walls, furniture), or a
  neighbouring cell holds a static level at its heights (a face's rim or end, seen in
  fewer scans: a cabinet's top edge, lit only at grazing incidence, lost 20 cell-scans
  in people room 17 before), or its mean hit lies below ABOVE (the floor, which the
  laser's lines hit only where they fall, and feet merged with it).

Each such frame costs the level MISSES misses, within the grid's `max_misses` a scan;
DARK_MISSES (half as many) where its line and the two beside it returned nothing at all
and the level lies farther than DARK_REACH. The stripe fades with range: on the rendered
frames the floor returns on 96-98 % of the lines out to 1.75 m (DARK_REACH), at most
85 % beyond, so there a dark line may hide a lit surface. At two misses such a frame
took a wall above a cabinet 2.1 m off, seen in one scan, on the next's dark lines (9
wall cell-scans of the rendered `people` eroded); counted not at all, it left most of
a person seen in one scan 1.5-2.5 m off, whose body no camera ray crosses. At one miss
a level seen in one scan (log-odds 0.85) is still an obstacle after one dark frame
(0.45, `FloorConfig.min_logodds` 0.2) and goes after two. Farther than REACH the
plane's lines lie far apart too. On `people` (`python -m
benchmarks.bench_hazards`) the ghost cell-scans went 1124 -> 770 of 42,922 (764 -> 500
with the dark frames at one miss), through its rendered frames 817 -> 545
(`--rendered-people`; 573 -> 450), the walls unchanged; see docs/hazards.md. The frames
are not kept with a scan for loop-closure rebuilds (`scanmap.mapping.rebuild`): a
rebuilt grid holds what the rays alone leave.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from scanmap.grid import _swept_kernels as sk
from scanmap.grid.unlit import LineReturns, line_returns
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel
from scanmap_driver.transforms import invert_pose

SWEEP_TOLERANCE = 0.025  # m: half a cell; the plane this near a level's mean hit lights it
REACH = 3.0  # m from the head's axis (see the module)
DARK_REACH = 1.75  # m: farther, a line without any return may be a faded stripe
ABOVE = 0.1  # m, map z: lower mean hits are the floor's, or a foot's merged with it
NEAR_Z = 0.05  # m: a hit this near a level's height in or beside its cell keeps it
OUTSHINE_MARGIN = 0.1  # m: a return this little farther may still have outshone it
BLOCK_Z = 0.02  # m: a level this near a sight line's heights blocks it
MISSES = 2  # per frame that swept a level unlit
DARK_MISSES = 1  # per such frame whose line and those beside it, past DARK_REACH, were dark


@dataclass(frozen=True)
class SweptFrames:
    """A scan's frames as `HeightGrid.insert(swept=...)` reads them (see the module).

    to_head: (F, 4, 4) T_head_map of each frame; cameras, emitters: (F, 3) the camera
    centre and the laser's emitter in map; nearest: (F, W) per image line the least
    distance (m) from the camera of its returns (inf: none); optics: the camera, laser and
    limits, packed for the kernel (`_swept_kernels.O_*`); box: (x0, y0, x1, y1) in map,
    the cells within REACH of the head's axis at the frames.
    """

    to_head: np.ndarray
    cameras: np.ndarray
    emitters: np.ndarray
    nearest: np.ndarray
    optics: np.ndarray
    box: np.ndarray


def swept_frames(scan: Scan, model: ScannerModel, pose: np.ndarray | None = None,
                 returns: LineReturns | None = None) -> SweptFrames:
    """The frames of `scan` at `pose` (4x4 map <- base_link, or (F, 4, 4) one per frame
    indexed by its frame_index, as `scan_rays` takes it) that returned a point on the
    laser plane; `returns`: `line_returns(scan, model)` when already at hand."""
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
    returns = returns or line_returns(scan, model)
    keep = ~returns.foreign
    frames = returns.frames[keep]
    headings = scan.heading[returns.first[keep]]
    base = pose if pose.ndim == 2 else pose[frames]
    heads = base @ model.head_poses(headings)
    cameras = heads[:, :3, :3] @ np.array(model.camera_mount.position) + heads[:, :3, 3]
    emitters = heads[:, :3, :3] @ np.array(model.laser.origin) + heads[:, :3, 3]
    box = np.zeros(4)
    if len(heads):
        box = np.concatenate([heads[:, :2, 3].min(axis=0) - REACH,
                              heads[:, :2, 3].max(axis=0) + REACH])
    return SweptFrames(invert_pose(heads), cameras, emitters,
                       np.ascontiguousarray(returns.nearest[keep]), _optics(model).copy(), box)


@functools.lru_cache(maxsize=32)
def _optics(model: ScannerModel) -> np.ndarray:
    """`SweptFrames.optics` of the model (cached, as models are frozen: built each scan,
    from the model's matrices, it took half of `swept_frames`' time)."""
    cam = model.camera
    optics = np.zeros(sk.N_OPTICS)
    optics[sk.O_CAMERA:sk.O_CAMERA + 3] = model.camera_mount.position
    optics[sk.O_TO_CAMERA:sk.O_TO_CAMERA + 9] = model.camera_mount.rotation.T.ravel()
    optics[sk.O_INTRINSICS:sk.O_INTRINSICS + 4] = (cam.fx, cam.fy, cam.cx, cam.cy)
    optics[sk.O_DIST:sk.O_DIST + 5] = cam.dist_coeffs
    optics[sk.O_LASER:sk.O_LASER + 6] = (*model.laser.origin, *model.laser.normal)
    optics[[sk.O_MIN_RANGE, sk.O_REACH, sk.O_WIDTH, sk.O_HEIGHT, sk.O_TOLERANCE, sk.O_ABOVE,
            sk.O_NEAR_Z, sk.O_OUTSHINE, sk.O_BLOCK_Z, sk.O_MISSES, sk.O_DARK_REACH,
            sk.O_DARK_MISSES]] = (
        model.min_range, min(REACH, model.max_range), cam.width, cam.height,
        SWEEP_TOLERANCE, ABOVE, NEAR_Z, OUTSHINE_MARGIN, BLOCK_Z, MISSES, DARK_REACH,
        DARK_MISSES)
    return optics
