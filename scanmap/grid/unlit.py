"""Floor the laser should have lit and the camera saw nothing on: a dark patch, not a gap.

Each image line u of a frame looks along one line of the laser plane (the plane through
the camera centre and the image line meets the laser plane there). Where that line
reaches the floor (z = 0 of `base_link`) inside the image, the range limits and clear of
the encoder disk, the floor must show the stripe on line u unless something nearer in
the plane returned first. A line without any return there is dark floor (black carpet,
a black-lined hole) or floor hidden from the camera, never a gap between the laser's
lines: no ray was aimed into those.

A line is counted only inside a run of MIN_RUN or more lines without a return whose two
neighbouring lines returned the floor (within FLOOR_TOLERANCE of z = 0) MIN_SPAN or more
apart, where its frame's other lines returned the floor at the run's ranges and up to
LIT_REACH nearer (LIT_SHARE of them, between the frame's first and last floor return:
past them the laser's fan ends, on image lines 560-602 of every rendered frame) and so
did the whole scan's (per RANGE_BIN): the floor beyond (the run's far neighbour) and
around shows the stripe was bright enough there. Lines farther out are not judged: the
stripe fades with range, and on the rendered frames their gaps had kept a black-lined
hole 1.6-2 m off from ever counting (mixed_room(2): 21 cells FREE inside it). A stripe
that fades with range (floor far off, lit at grazing incidence) drops out here and there
all along the line: the rendered corridor has 672 such runs in 20 scans from 1.8 m out,
and in the rendered corridor and `hazards` room the floor returns on 96-98 % of the
lines out to 1.75 m and on at most 85 % beyond, against 97-99 % at every range in ideal
scans.

A dark patch the fan's near end falls in shows no floor on its near side: its lines run
without a return from the frame's nearest floor return to where the fan ends. They are
counted too (`fan_end_lines`) if MIN_RUN or more span MIN_SPAN or more and each is one
the scan lit (`_lit_lines`: FAN_SHARE of the frames that returned the floor or nothing
on it returned the floor, and half the frames did either; a frame facing an object
nearby returns the object there). A black-lined hole 0.3 m across seen only with the
rendered fan's end (1.63 m) inside it was otherwise never found: rendered
mixed_room(5), 14 cells FREE inside it. The fan's lines are told by a looser share than
a stripe's range (LIT_SHARE): a dark patch darkens the lines it lies on in the frames
that face it, and at 0.9 a black-lined hole 0.5 m across, 1.5-1.8 m off (the rendered
frames show the floor from 1.5 to 1.8 m), put 15 % of a scan's frames dark on the
lines it lay on, which then counted as past the fan's end, and none of it was found
(rendered mixed_room(4003): 22 cells FREE more than a cell inside it, 55 of them in
all). The fan ends sharply (every frame dark one line on), and ranges where the
stripe fades stay unjudged (`_reliable_ranges`). Floor hidden from the camera there
(under a table top or a chair seat the laser passes beneath) counts as it does between
floor returns: the office's first 12 ideal scans 892 -> 1083 unlit points, its map's
states the same.

A missed peak spans a line or two, and a laser shadow behind an object ends at the
object, not the floor: none is taken for a dark patch. A frame whose points do not lie
on the laser plane (a scan from another sensor, read from a bag) shows nothing unlit.
The grid keeps the cells such lines reach (`HeightGrid.insert(unlit=...)`), and the
segmentation never fills a patch without hits near them as floor between samples.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from scanmap.grid._kernels import columns
from scanmap_driver.scan import Scan
from scanmap_driver.scanner_model import ScannerModel
from scanmap_driver.transforms import transform_points
from scanmap_driver.triangulation import pixel_rays

FLOOR_TOLERANCE = 0.05  # m: a return this near z = 0 of base_link is the floor
MIN_RUN = 3  # image lines: a shorter run without a return is a missed peak, not a patch
MIN_SPAN = 0.05  # m of floor between a run's two neighbours: narrower is a missed peak
LIT_REACH = 0.5  # m of range either side of a run over which its frame's floor is judged
LIT_SHARE = 0.9  # of those lines returning the floor: the stripe shows at that range
FAN_SHARE = 0.75  # of the frames returning the floor on an image line: the fan lights it
RANGE_BIN = 0.25  # m: and so do all the scan's frames, per range bin of this width
MIN_JUDGED = 100  # lines a bin needs to be judged (ideal scans return the floor on 97-99 %
# of them at every range; rendered ones on 96-98 % to 1.75 m and at most 85 % beyond)
PLANE_TOLERANCE = 0.01  # m: this scanner's points lie on its laser plane (triangulated)
OFF_PLANE_SHARE = 0.05  # a frame with more of its points off the plane is another sensor's


@functools.lru_cache(maxsize=8)
def _line_ends(model: ScannerModel) -> tuple[np.ndarray, np.ndarray]:
    """(W, 3) laser-plane points in `head` seen on each image line u at its highest and
    lowest pixel whose ray meets the plane ahead (v = 0 and v = height - 1 where the
    plane's horizon lies above the image); NaN where none does. Above its horizon a
    line's rays meet the plane behind the camera: taking the first pixel's point alone
    lost every line the horizon crosses, and the floor seen on them (the reference
    scanner's far floor on 34 of its 355 lines that return it, a camera 0.6 m up on 131
    of 487)."""
    cam = model.camera
    u = np.arange(cam.width, dtype=np.float64)
    v = np.arange(cam.height, dtype=np.float64)
    centre, rays = pixel_rays(model, np.tile(u, cam.height), np.repeat(v, cam.width))
    normal, origin = np.array(model.laser.normal), np.array(model.laser.origin)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((normal @ (origin - centre)) / (rays @ normal)).reshape(cam.height, cam.width)
    ahead = t > 0.0  # False for NaN
    lines = np.flatnonzero(ahead.any(axis=0))
    ends = []
    for row in (ahead.argmax(axis=0), cam.height - 1 - ahead[::-1].argmax(axis=0)):
        end = np.full((cam.width, 3), np.nan)
        index = row[lines] * cam.width + lines
        end[lines] = centre + t.reshape(-1)[index, None] * rays[index]
        ends.append(end)
    return ends[0], ends[1]


@njit(cache=True, nogil=True)
def _floor_crossings(headings: np.ndarray, mount: np.ndarray, end_a: np.ndarray,
                     end_b: np.ndarray, camera: np.ndarray, normal: np.ndarray,
                     limits: np.ndarray, crossing: np.ndarray, reach: np.ndarray,
                     ok: np.ndarray) -> None:
    """Per frame (its heading) and image line (its laser line from end_a to end_b, in
    `head`): crossing[f, u] the point in base_link where the line meets the floor,
    reach[f, u] its distance from the head's axis, ok[f, u] whether the camera can
    measure it there: inside the image, within the range limits and the ray-to-plane
    angle, not behind the encoder disk. limits: (min range, max range, sine of the least
    ray-to-plane angle, disk height, disk outer radius)."""
    for f in range(headings.shape[0]):
        c, s = np.cos(headings[f]), np.sin(headings[f])
        head = np.empty((3, 4))
        for r in range(3):  # mount @ Rz(heading)
            head[r, 0] = mount[r, 0] * c + mount[r, 1] * s
            head[r, 1] = mount[r, 1] * c - mount[r, 0] * s
            head[r, 2], head[r, 3] = mount[r, 2], mount[r, 3]
        cam = np.empty(3)
        nrm = np.empty(3)
        for r in range(3):
            cam[r] = head[r, 0] * camera[0] + head[r, 1] * camera[1] \
                + head[r, 2] * camera[2] + head[r, 3]
            nrm[r] = head[r, 0] * normal[0] + head[r, 1] * normal[1] + head[r, 2] * normal[2]
        for u in range(end_a.shape[0]):
            za = head[2, 0] * end_a[u, 0] + head[2, 1] * end_a[u, 1] \
                + head[2, 2] * end_a[u, 2] + head[2, 3]
            zb = head[2, 0] * end_b[u, 0] + head[2, 1] * end_b[u, 1] \
                + head[2, 2] * end_b[u, 2] + head[2, 3]
            t = za / (za - zb) if za != zb else np.nan
            ok[f, u] = False
            if not 0.0 <= t <= 1.0:  # beyond the image's lines, or NaN
                continue
            for r in range(2):
                pa = head[r, 0] * end_a[u, 0] + head[r, 1] * end_a[u, 1] \
                    + head[r, 2] * end_a[u, 2] + head[r, 3]
                pb = head[r, 0] * end_b[u, 0] + head[r, 1] * end_b[u, 1] \
                    + head[r, 2] * end_b[u, 2] + head[r, 3]
                crossing[f, u, r] = pa + t * (pb - pa)
            crossing[f, u, 2] = 0.0
            reach[f, u] = np.hypot(crossing[f, u, 0] - mount[0, 3],
                                   crossing[f, u, 1] - mount[1, 3])
            rx, ry, rz = crossing[f, u, 0] - cam[0], crossing[f, u, 1] - cam[1], -cam[2]
            sine = abs(rx * nrm[0] + ry * nrm[1] + rz * nrm[2]) / np.sqrt(
                rx * rx + ry * ry + rz * rz)
            k = (limits[3] - cam[2]) / rz  # where the camera's ray passes the disk's face
            hidden = 0.0 < k < 1.0 and np.hypot(cam[0] + k * rx, cam[1] + k * ry) <= limits[4]
            ok[f, u] = limits[0] <= reach[f, u] <= limits[1] and sine >= limits[2] \
                and not hidden


@njit(cache=True, nogil=True, inline="always")
def project_to_image(x: float, y: float, z: float, to_camera: np.ndarray,
                     intrinsics: np.ndarray, dist: np.ndarray) -> tuple[float, float, bool]:
    """Pixel (u, v) of a point (x, y, z) from the camera centre in `head`, with OpenCV's
    distortion model (`project_head_points` without its arrays); False behind the camera.
    to_camera: the head-to-camera rotation, row-major (9,) or (3, 3) flattened."""
    depth = to_camera[6] * x + to_camera[7] * y + to_camera[8] * z
    ahead = depth > 0.0
    # computed for every point and then chosen, with no early return: the loops that
    # inline this then vectorise (`_project_lines` 3.4 times as fast)
    depth = depth if ahead else 1.0
    xn = (to_camera[0] * x + to_camera[1] * y + to_camera[2] * z) / depth
    yn = (to_camera[3] * x + to_camera[4] * y + to_camera[5] * z) / depth
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    r2 = xn * xn + yn * yn
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * radial + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
    u, v = intrinsics[0] * xd + intrinsics[2], intrinsics[1] * yd + intrinsics[3]
    return (u if ahead else np.nan), (v if ahead else np.nan), ahead


@njit(cache=True, nogil=True)
def _line_returns(points: np.ndarray, headings: np.ndarray, slot: np.ndarray,
                  mount_inverse: np.ndarray, to_camera: np.ndarray, camera: np.ndarray,
                  intrinsics: np.ndarray, dist: np.ndarray, laser: np.ndarray,
                  nearest: np.ndarray, floor: np.ndarray, off_plane: np.ndarray,
                  counts: np.ndarray) -> None:
    """Keep in nearest[slot, u] the least distance from the camera of the points on image
    line u (base_link, each seen at its heading; `project_to_image`; inf stays where
    none), mark floor[slot, u] where one lies within FLOOR_TOLERANCE of z = 0, and count
    in off_plane[slot] the points farther than PLANE_TOLERANCE from the laser plane
    (origin, normal: laser), in counts[slot] all. The points are projected first, by
    columns, in a loop of their own that vectorises (`_project_lines`), then gathered by
    line."""
    n = points.shape[0]
    cosines, sines = np.empty(n), np.empty(n)
    last, c, s = np.nan, 1.0, 0.0
    for i in range(n):  # the heading's turn, once per frame
        if headings[i] != last:
            last = headings[i]
            c, s = np.cos(last), np.sin(last)
        cosines[i], sines[i] = c, s
    lines, ranges, off = np.empty(n), np.empty(n), np.empty(n, np.bool_)
    xyz = columns(points)
    _project_lines(xyz[0], xyz[1], xyz[2], cosines, sines, mount_inverse,
                   to_camera.ravel(), camera, intrinsics, dist, laser, lines, ranges, off)
    width = nearest.shape[1]
    for i in range(n):
        counts[slot[i]] += 1
        if off[i]:
            off_plane[slot[i]] += 1
        if 0.0 <= lines[i] < width:
            line = int(lines[i])
            nearest[slot[i], line] = min(nearest[slot[i], line], ranges[i])
            if abs(points[i, 2]) <= FLOOR_TOLERANCE:
                floor[slot[i], line] = True


@njit(cache=True, nogil=True, error_model="numpy")
def _project_lines(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, cosines: np.ndarray,
                   sines: np.ndarray, mount_inverse: np.ndarray, rotation: np.ndarray,
                   camera: np.ndarray, intrinsics: np.ndarray, dist: np.ndarray,
                   laser: np.ndarray, lines: np.ndarray, ranges: np.ndarray,
                   off: np.ndarray) -> None:
    """`_line_returns`' projections of the points (xs, ys, zs: by columns, whose loads
    vectorise where the rows' interleaved x, y, z were gathered: 166 -> 86 us for 20,000
    points, `columns`): each point's image line (rounded; -1 behind the camera), its distance from
    the camera and whether it lies off the laser plane (no branch, the projection's
    included: the loop vectorises, with NumPy's error model, which divides by zero
    without a check; 0.32 -> 0.09 ms since `project_to_image` has no early return)."""
    m = mount_inverse
    for i in range(xs.shape[0]):
        px, py, pz = xs[i], ys[i], zs[i]
        mx = m[0, 0] * px + m[0, 1] * py + m[0, 2] * pz + m[0, 3]
        my = m[1, 0] * px + m[1, 1] * py + m[1, 2] * pz + m[1, 3]
        mz = m[2, 0] * px + m[2, 1] * py + m[2, 2] * pz + m[2, 3]
        hx, hy = cosines[i] * mx + sines[i] * my, cosines[i] * my - sines[i] * mx
        off[i] = abs((hx - laser[0]) * laser[3] + (hy - laser[1]) * laser[4]
                     + (mz - laser[2]) * laser[5]) > PLANE_TOLERANCE
        hx, hy, hz = hx - camera[0], hy - camera[1], mz - camera[2]
        u, _, ahead = project_to_image(hx, hy, hz, rotation, intrinsics, dist)
        lines[i] = np.rint(u) if ahead else -1.0
        ranges[i] = np.sqrt(hx * hx + hy * hy + hz * hz)


@njit(cache=True, nogil=True)
def _floor_runs(returned: np.ndarray, floor: np.ndarray, foreign: np.ndarray,
                lit: np.ndarray) -> bool:
    """Whether a frame not `foreign` has MIN_RUN or more lines without a return between
    two that returned the floor, or next to its first or last floor return on lines the
    scan lit (`lit`, `_lit_lines`): what `unlit_lines` and `fan_end_lines` then judge."""
    for f in range(returned.shape[0]):
        if foreign[f]:
            continue
        last = -1
        for u in range(returned.shape[1]):
            if returned[f, u]:
                if last >= 0 and u - last - 1 >= MIN_RUN and floor[f, last] and floor[f, u]:
                    return True
                last = u
        first, last = _floor_ends(returned, floor, f)
        if first >= 0 and max(_lit_run(returned, lit, f, first, -1),
                              _lit_run(returned, lit, f, last, 1)) >= MIN_RUN:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _floor_ends(returned: np.ndarray, floor: np.ndarray, f: int) -> tuple[int, int]:
    """The first and the last image line on which frame f returned the floor (-1, -1
    without any)."""
    first, last = -1, -1
    for u in range(returned.shape[1]):
        if returned[f, u] and floor[f, u]:
            first, last = (u if first < 0 else first), u
    return first, last


@njit(cache=True, nogil=True)
def _lit_run(returned: np.ndarray, lit: np.ndarray, f: int, u: int, step: int) -> int:
    """How many lines on from line u of frame f (in the direction `step`) are `lit` by
    the scan and returned nothing on f, up to the first that is not (none if that one
    returned something: the run is then not at the end of the lit lines)."""
    v = u + step
    while 0 <= v < returned.shape[1] and lit[v] and not returned[f, v]:
        v += step
    if 0 <= v < returned.shape[1] and returned[f, v]:
        return 0
    return abs(v - u) - 1


@njit(cache=True, nogil=True)
def unlit_lines(returned: np.ndarray, floor: np.ndarray, crossing: np.ndarray,
                reach: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(F, W) bool: per frame, the measurable image lines (ok) without a return inside a
    run of such lines (see the module): MIN_RUN lines or more, whose neighbours on both
    sides returned the floor MIN_SPAN or more apart, on a frame whose other lines at the
    run's ranges and up to LIT_REACH nearer, between its first and last floor return,
    returned the floor at least LIT_SHARE of the time.
    returned, floor, ok: (F, W) bool per image line; crossing (F, W, 3), reach (F, W)
    from `_floor_crossings`."""
    out = np.zeros(returned.shape, np.bool_)
    for f in range(returned.shape[0]):
        first_lit, last_lit = _floor_ends(returned, floor, f)
        last = -1
        for u in range(returned.shape[1]):
            if not returned[f, u]:
                continue
            a, last = last, u
            if a < 0 or u - a - 1 < MIN_RUN or not (floor[f, a] and floor[f, u]
                                                     and ok[f, a] and ok[f, u]):
                continue
            if np.hypot(crossing[f, u, 0] - crossing[f, a, 0],
                        crossing[f, u, 1] - crossing[f, a, 1]) < MIN_SPAN:
                continue
            near = min(reach[f, a], reach[f, u]) - LIT_REACH
            far = max(reach[f, a], reach[f, u])
            lit = unlit = 0
            for v in range(first_lit, last_lit + 1):
                if (a < v < u) or not ok[f, v] or not near <= reach[f, v] <= far:
                    continue
                if not returned[f, v]:
                    unlit += 1
                elif floor[f, v]:
                    lit += 1
            if lit >= LIT_SHARE * (lit + unlit):
                out[f, a + 1:u] = ok[f, a + 1:u]
    return out


@njit(cache=True, nogil=True)
def fan_end_lines(returned: np.ndarray, floor: np.ndarray, crossing: np.ndarray,
                  reach: np.ndarray, ok: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """(F, W) bool: per frame, the measurable lines without a return on from its nearest
    floor return towards the robot, up to the end of the lines the scan lit (`lit`,
    `_lit_lines`: where the laser's fan ends), MIN_RUN or more spanning MIN_SPAN or more
    (see the module). Nearer than the frame's first floor return `unlit_lines` judges
    nothing: no lit floor bounds the run there."""
    out = np.zeros(returned.shape, np.bool_)
    for f in range(returned.shape[0]):
        first, last = _floor_ends(returned, floor, f)
        if first < 0:
            continue
        for a, step in ((first, -1), (last, 1)):
            count = _lit_run(returned, lit, f, a, step)
            b = a + step * count  # the run's last line
            low, high = min(a + step, b), max(a + step, b) + 1
            if count < MIN_RUN or not ok[f, a] or not ok[f, low:high].all() \
                    or reach[f, b] >= reach[f, a] or np.hypot(
                        crossing[f, b, 0] - crossing[f, a, 0],
                        crossing[f, b, 1] - crossing[f, a, 1]) < MIN_SPAN:
                continue
            out[f, low:high] = True
    return out


def _lit_lines(returned: np.ndarray, floor: np.ndarray, foreign: np.ndarray) -> np.ndarray:
    """(W,) bool: image lines on which FAN_SHARE of the frames that returned the floor or
    nothing there returned the floor, and at least half of the scan's frames did either:
    the laser's fan lights the floor on them."""
    judged = (floor | ~returned) & ~foreign[:, None]
    total = judged.sum(axis=0)
    return (total >= 0.5 * (~foreign).sum()) & ((judged & returned).sum(axis=0)
                                                 >= FAN_SHARE * total) & (total > 0)


def _reliable_ranges(returned: np.ndarray, floor: np.ndarray, reach: np.ndarray,
                     ok: np.ndarray) -> np.ndarray:
    """(F, W) bool: lines whose range bin (RANGE_BIN) holds MIN_JUDGED or more
    measurable lines that returned the floor or nothing over the whole scan, LIT_SHARE of
    them the floor: this scan's stripe shows on the floor at that range. Lines past a
    frame's first or last floor return are not judged: the laser's fan ends there (the
    ideal scans light no floor nearer than image line 563), or the floor is out of
    sight."""
    index = np.minimum(reach / RANGE_BIN, 1e6).astype(np.int64)
    lit = floor & returned
    between = np.logical_or.accumulate(lit, axis=1) \
        & np.logical_or.accumulate(lit[:, ::-1], axis=1)[:, ::-1]
    judged = ok & (floor | ~returned) & between  # not past a frame's floor returns
    total = np.bincount(index[judged], minlength=index.max(initial=0) + 1)
    shown = np.bincount(index[judged & returned], minlength=len(total))
    return ((total >= MIN_JUDGED) & (shown >= LIT_SHARE * total))[index]


def frame_slots(frame_index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`np.unique(frame_index, return_index=True, return_inverse=True)`: the frames, the
    first point of each and each point's frame slot; without sorting when the points come
    frame by frame, as a scan's do (the sort was a third of `unlit_floor`), in one pass
    (`_slots_in_order`: the numpy passes took 0.11 ms of a 20,000-point scan)."""
    frame_index = np.asarray(frame_index)
    first, slot = _slots_in_order(frame_index)
    if first is None:
        return np.unique(frame_index, return_index=True, return_inverse=True)
    return frame_index[first], first, slot


@njit(cache=True, nogil=True)
def _slots_in_order(frame_index: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
    """(first point of each frame, each point's frame slot) of points that come frame by
    frame (non-decreasing `frame_index`); (None, empty) when they do not."""
    n = frame_index.shape[0]
    slot = np.empty(n, np.int64)
    first = np.empty(n, np.int64)
    frames = 0
    for i in range(n):
        if i == 0 or frame_index[i] != frame_index[i - 1]:
            if i > 0 and frame_index[i] < frame_index[i - 1]:
                return None, slot[:0]
            first[frames] = i
            frames += 1
        slot[i] = frames - 1
    return first[:frames], slot


@dataclass(frozen=True)
class LineReturns:
    """What each image line of a scan's frames returned, as `unlit_floor` and
    `scanmap.grid.swept` read it.

    frames: (F,) the frame indices with points, first: (F,) each one's first point,
    slot: (N,) each point's frame slot; returned, floor: (F, W) whether the line returned a
    point, and one on the floor; nearest: (F, W) the least distance (m) from the camera of
    the line's points (inf: none); foreign: (F,) frames whose points do not lie on the
    laser plane (another sensor's).
    """

    frames: np.ndarray
    first: np.ndarray
    slot: np.ndarray
    returned: np.ndarray
    floor: np.ndarray
    nearest: np.ndarray
    foreign: np.ndarray


def line_returns(scan: Scan, model: ScannerModel) -> LineReturns:
    """The image lines each frame of `scan` returned a point on (see `LineReturns`)."""
    frames, first, slot = frame_slots(scan.frame_index)
    cam = model.camera
    nearest = np.full((len(frames), cam.width), np.inf)
    floor = np.zeros(nearest.shape, bool)
    off_plane, counts = np.zeros(len(frames), np.int64), np.zeros(len(frames), np.int64)
    _line_returns(scan.points, scan.heading, slot.astype(np.int64, copy=False),
                  *_projection(model), nearest, floor, off_plane, counts)
    foreign = off_plane > OFF_PLANE_SHARE * counts
    return LineReturns(frames, first, slot, np.isfinite(nearest), floor, nearest, foreign)


@functools.lru_cache(maxsize=32)
def _projection(model: ScannerModel) -> tuple[np.ndarray, ...]:
    """`_line_returns`' arguments from the model (cached, as models are frozen: built
    each scan they took a fifth of its time): T_mount_base, the head-to-camera rotation,
    the camera centre in `head`, fx, fy, cx, cy, the distortion and the laser plane."""
    cam = model.camera
    return (np.linalg.inv(model.head_mount.pose), model.camera_mount.rotation.T.copy(),
            np.array(model.camera_mount.position), np.array([cam.fx, cam.fy, cam.cx, cam.cy]),
            cam.dist_coeffs, np.array([*model.laser.origin, *model.laser.normal]))


def floor_crossings(model: ScannerModel, headings: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per heading (F,) and image line u: where its laser line meets the floor (F, W, 3,
    base_link), that point's distance from the head's axis (F, W) and whether the camera
    can measure it there (F, W) (`_floor_crossings`)."""
    width = model.camera.width
    crossing = np.zeros((len(headings), width, 3))
    reach = np.zeros((len(headings), width))
    ok = np.zeros((len(headings), width), bool)
    end_a, end_b = _line_ends(model)
    disk = model.encoder
    _floor_crossings(np.ascontiguousarray(headings, np.float64), model.head_mount.pose,
                     end_a, end_b, np.array(model.camera_mount.position),
                     np.array(model.laser.normal),
                     np.array([model.min_range, model.max_range,
                               np.sin(model.min_ray_plane_angle), disk.height,
                               disk.outer_radius]), crossing, reach, ok)
    return crossing, reach, ok


def unlit_floor(scan: Scan, model: ScannerModel, pose: np.ndarray | None = None,
                returns: LineReturns | None = None) -> np.ndarray:
    """(M, 3) points in map (by `pose`, as `scan_rays` takes it) of the floor each frame of
    `scan` should have lit on an image line that returned nothing (see the module);
    `returns`: `line_returns(scan, model)` when already at hand."""
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
    if not len(scan):
        return np.zeros((0, 3))
    returns = returns or line_returns(scan, model)
    frames, first = returns.frames, returns.first
    returned, floor, foreign = returns.returned, returns.floor, returns.foreign
    lit = _lit_lines(returned, floor, foreign)
    if not _floor_runs(returned, floor, foreign, lit):  # most scans: skip the floor's geometry
        return np.zeros((0, 3))
    crossing, reach, ok = floor_crossings(model, scan.heading[first])
    dark = unlit_lines(returned, floor, crossing, reach, ok) \
        | fan_end_lines(returned, floor, crossing, reach, ok, lit)
    dark[foreign] = False
    dark &= _reliable_ranges(returned, floor, reach, ok)
    out = []
    for k in np.flatnonzero(dark.any(axis=1)):
        frame_pose = pose if pose.ndim == 2 else pose[frames[k]]
        out.append(transform_points(frame_pose, crossing[k, dark[k]]))
    return np.concatenate(out) if out else np.zeros((0, 3))
