"""The laser stripe's exact geometry: on each image column, where the laser plane meets the
scene, whether the camera sees it there, and whether the laser reaches it (or it lies in
the laser's shadow).

A stripe point of column u is a row v where the laser-plane point of pixel (u, v) (the
point `triangulation` would return) lies on the surface the camera sees through that
pixel. For a scene plane n . x = d (in `head`) and the laser plane n_l . x = d_l, with
camera centre C and the pixel's ray r scaled to unit depth,

    h(v) = (d_l - n_l . C) (n . r) - (d - n . C) (n_l . r)

vanishes exactly there; h is linear in v for a pinhole camera (one secant step) and nearly
so with distortion. Candidates come from a rendered hit map (sign changes of the depth
against the laser plane's depth along a column) or from a fan of rays cast from the laser
aperture; every candidate is solved on its plane and then verified by casting the camera
ray (visible?) and the laser ray (lit?). The camera rays come from
`triangulation.pixel_rays`, so the renderer and the triangulation agree exactly.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..scanner_model import ScannerModel
from ..triangulation import pixel_rays, project_head_points
from .geometry import NO_HIT, World, transform_per_frame

TOLERANCE = 1e-7  # relative distance mismatch (of 1 + distance) still counted as the same point
SOLVE_ITERATIONS = 12
FAN_RAYS = 1600  # rays per frame from the laser aperture (ideal mode)


@dataclass(frozen=True)
class CameraRays:
    """Every pixel centre's ray in `head` and its distance to the laser plane (inf: none)."""

    centre: np.ndarray  # (3,)
    directions: np.ndarray  # (H, W, 3) unit
    laser_t: np.ndarray  # (H, W)


@functools.lru_cache(maxsize=4)
def camera_rays(model: ScannerModel) -> CameraRays:
    """The camera's pixel rays (cached per model)."""
    cam = model.camera
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    centre, directions = pixel_rays(model, u.ravel().astype(np.float64),
                                    v.ravel().astype(np.float64))
    normal = np.array(model.laser.normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (normal @ (np.array(model.laser.origin) - centre)) / (directions @ normal)
    t[~(t > 0.0)] = np.inf
    return CameraRays(centre, directions.reshape(cam.height, cam.width, 3),
                      t.reshape(cam.height, cam.width))


@dataclass(frozen=True)
class StripePoints:
    """Stripe points of a batch of frames: one row per (frame, column, surface) found.

    u is the image column (integer valued), v the subpixel row of the stripe's centre.
    strength: laser irradiance times the surface's red albedo and laser reflectance,
    relative to albedo 1 at 1 m and normal incidence (0 where shadowed or where the
    surface returns no laser light: black carpet, a mirror).
    """

    frame: np.ndarray  # (M,) int
    u: np.ndarray
    v: np.ndarray
    heading: np.ndarray
    plane: np.ndarray  # (M,) world plane id
    head: np.ndarray  # (M, 3)
    base: np.ndarray
    map: np.ndarray
    lit: np.ndarray  # (M,) bool
    strength: np.ndarray

    def __len__(self) -> int:
        return int(self.u.shape[0])

    def select(self, mask: np.ndarray) -> StripePoints:
        """The rows where `mask` holds."""
        return StripePoints(**{name: getattr(self, name)[mask]
                               for name in self.__dataclass_fields__})

    def strongest_per_column(self) -> np.ndarray:
        """Mask of the lit point with the highest strength in each (frame, column); a
        point that returns no light (strength 0) is never one."""
        mask = np.zeros(len(self), dtype=bool)
        lit = np.flatnonzero(self.lit & (self.strength > 0.0))
        if lit.size:
            order = lit[np.lexsort((-self.strength[lit], self.u[lit], self.frame[lit]))]
            key = self.frame[order] * 1_000_000 + self.u[order].astype(np.int64)
            first = np.ones(order.size, dtype=bool)
            first[1:] = key[1:] != key[:-1]
            mask[order[first]] = True
        return mask


def head_poses(model: ScannerModel, base_poses: np.ndarray,
               headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T_map_head, T_base_head), each (N, 4, 4), from T_map_base (N, 4, 4) and headings."""
    base_head = model.head_poses(headings)
    return np.asarray(base_poses) @ base_head, base_head


def planes_in_head(planes_map: np.ndarray, poses_map_head: np.ndarray) -> np.ndarray:
    """(N, 4) planes (n, d) in `head` from planes in `map` and T_map_head (N, 4, 4)."""
    rotation = poses_map_head[:, :3, :3]
    normal = np.einsum("nji,nj->ni", rotation, planes_map[:, :3])
    offset = planes_map[:, 3] - np.einsum("ni,ni->n", planes_map[:, :3],
                                          poses_map_head[:, :3, 3])
    return np.column_stack([normal, offset])


def _h(model: ScannerModel, u: np.ndarray, v: np.ndarray, planes: np.ndarray) -> np.ndarray:
    centre, rays = pixel_rays(model, u, v)
    rays /= (rays @ model.camera_mount.rotation[:, 2])[:, None]
    normal = np.array(model.laser.normal)
    k = normal @ (np.array(model.laser.origin) - centre)
    return k * np.einsum("ij,ij->i", planes[:, :3], rays) \
        - (planes[:, 3] - planes[:, :3] @ centre) * (rays @ normal)


def solve_rows(model: ScannerModel, u: np.ndarray, v0: np.ndarray, v1: np.ndarray,
               planes_head: np.ndarray) -> np.ndarray:
    """Rows v on columns u where the laser plane meets the given planes (secant from v0, v1).

    NaN where the iteration fails (the two planes are parallel along that column).
    """
    u = np.asarray(u, dtype=np.float64)
    a, b = np.asarray(v0, dtype=np.float64).copy(), np.asarray(v1, dtype=np.float64).copy()
    ha, hb = _h(model, u, a, planes_head), _h(model, u, b, planes_head)
    active = np.ones(u.shape[0], dtype=bool)
    for _ in range(SOLVE_ITERATIONS):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        denom = hb[idx] - ha[idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            step = hb[idx] * (b[idx] - a[idx]) / denom
        nxt = b[idx] - step
        a[idx], ha[idx] = b[idx], hb[idx]
        b[idx] = nxt
        done = ~np.isfinite(nxt) | (np.abs(step) < 1e-10) | (denom == 0.0)
        live = idx[~done]
        hb[live] = _h(model, u[live], b[live], planes_head[live])
        active[idx[done]] = False
    b[active | ~np.isfinite(b)] = np.nan
    return b


def stripe_points(world: World, model: ScannerModel, frame: np.ndarray, u: np.ndarray,
                  v: np.ndarray, plane: np.ndarray, base_poses: np.ndarray,
                  headings: np.ndarray, threads: int = 0) -> StripePoints:
    """Verified stripe points from solved rows: keep those the camera sees; test the laser.

    frame indexes base_poses (F, 4, 4, T_map_base) and headings (F,).
    """
    keep = np.isfinite(v) & (v >= -0.5) & (v <= model.camera.height - 0.5)
    frame, u, v, plane = _unique(frame[keep], u[keep], v[keep], plane[keep])
    map_head, base_head = head_poses(model, base_poses, headings)
    centre, rays = pixel_rays(model, u, v)
    normal = np.array(model.laser.normal)
    aperture = np.array(model.laser.origin)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (normal @ (aperture - centre)) / (rays @ normal)
    head = centre + t[:, None] * rays
    # Visible: the camera ray's first hit is the point itself.
    _, hit_t, disk_t = world.first_hits(centre, rays, frame, map_head, base_head, threads)
    slack = TOLERANCE * (1.0 + t)
    visible = (np.abs(hit_t - t) <= slack) & (disk_t >= t - slack) & (t > 0.0)
    # Lit: the ray from the laser aperture reaches the point.
    to_point = head - aperture
    distance = np.linalg.norm(to_point, axis=1)
    direction = to_point / np.where(distance > 0.0, distance, 1.0)[:, None]
    _, laser_t, laser_disk_t = world.first_hits(aperture, direction, frame, map_head,
                                                base_head, threads)
    slack = TOLERANCE * (1.0 + distance)
    lit = (laser_t >= distance - slack) & (laser_disk_t >= distance - slack)
    direction_map = transform_per_frame(map_head, frame, direction, False)
    cos_incidence = np.abs(np.einsum("ij,ij->i", world.world.planes.planes[plane, :3],
                                     direction_map))
    strength = np.where(lit, world.plane_albedo[plane, 0] * world.plane_reflectance[plane]
                        * cos_incidence
                        / np.maximum(distance, 1e-3) ** 2, 0.0)
    points = StripePoints(frame, u, v, headings[frame], plane, head,
                          transform_per_frame(base_head, frame, head, True),
                          transform_per_frame(map_head, frame, head, True), lit, strength)
    return points.select(visible)


def _unique(frame, u, v, plane):
    """Drop duplicate solutions (same frame and column, rows within 1e-6 px)."""
    order = np.lexsort((v, u, frame))
    frame, u, v, plane = frame[order], u[order], v[order], plane[order]
    keep = np.ones(order.size, dtype=bool)
    keep[1:] = (frame[1:] != frame[:-1]) | (u[1:] != u[:-1]) | (np.abs(np.diff(v)) > 1e-6)
    return frame[keep], u[keep], v[keep], plane[keep]


def points_from_hit_map(world: World, model: ScannerModel, plane_map: np.ndarray,
                        t_map: np.ndarray, rows: np.ndarray, base_pose: np.ndarray,
                        heading: float, threads: int = 0) -> StripePoints:
    """Stripe points of one rendered frame from its scene hit map: plane ids and distances
    (R, W) of the image rows `rows` (all rows, or every n-th)."""
    laser_t = camera_rays(model).laser_t[rows]
    valid = (plane_map != NO_HIT) & np.isfinite(laser_t)
    above = t_map >= laser_t
    # A sign change of depth against the laser plane's depth, or an edge between two
    # planes (the stripe may end within half a pixel of a silhouette).
    change = valid[:-1] & valid[1:] & ((above[:-1] != above[1:])
                                       | (plane_map[:-1] != plane_map[1:]))
    index, cols = np.nonzero(change)
    first, second = plane_map[index, cols], plane_map[index + 1, cols]
    other = first != second
    cols = np.concatenate([cols, cols[other]])
    index = np.concatenate([index, index[other]])
    plane = np.concatenate([first, second[other]])
    return _solve_and_verify(world, model, np.zeros(cols.size, dtype=np.int64),
                             cols.astype(np.float64), rows[index].astype(np.float64),
                             rows[index + 1].astype(np.float64), plane, base_pose[None],
                             np.array([heading]), threads)


def _solve_and_verify(world, model, frame, u, v0, v1, plane, base_poses, headings, threads):
    map_head, _ = head_poses(model, base_poses, headings)
    planes = planes_in_head(world.world.planes.planes[plane], map_head[frame])
    v = solve_rows(model, u, v0, v1, planes)
    return stripe_points(world, model, frame, u, v, plane, base_poses, headings, threads)


@functools.lru_cache(maxsize=4)
def laser_fan(model: ScannerModel) -> np.ndarray:
    """(FAN_RAYS, 3) unit directions in `head`, in the laser plane, covering what the camera sees.

    The fan spans the directions from the aperture to the laser-plane points of the
    image (closer than 4 times the maximum range), with a small margin.
    """
    rays = camera_rays(model)
    t = rays.laser_t[::4, ::4]
    seen = t <= 4.0 * model.max_range
    points = rays.centre + t[seen][:, None] * rays.directions[::4, ::4][seen]
    normal = np.array(model.laser.normal)
    forward = np.array([1.0, 0.0, 0.0]) - normal * normal[0]
    forward /= np.linalg.norm(forward)
    side = np.cross(normal, forward)
    offsets = points - np.array(model.laser.origin)
    angles = np.arctan2(offsets @ side, offsets @ forward)
    margin = np.radians(1.0)
    fan = np.linspace(angles.min() - margin, angles.max() + margin, FAN_RAYS)
    return np.cos(fan)[:, None] * forward + np.sin(fan)[:, None] * side


def points_from_fan(world: World, model: ScannerModel, base_poses: np.ndarray,
                    headings: np.ndarray, threads: int = 0) -> StripePoints:
    """Lit, visible stripe points of frames (T_map_base (F, 4, 4), headings (F,)) by casting
    the laser fan: what the scanner can measure, without rendering images."""
    fan = laser_fan(model)
    frames, rays = headings.shape[0], fan.shape[0]
    map_head, base_head = head_poses(model, base_poses, headings)
    aperture = np.array(model.laser.origin)
    ray_frame = np.repeat(np.arange(frames), rays)
    directions = np.tile(fan, (frames, 1))
    plane, t, disk_t = world.first_hits(aperture, directions, ray_frame, map_head, base_head,
                                        threads)
    plane[disk_t < t] = NO_HIT
    pixels = project_head_points(
        model, aperture + np.where(np.isfinite(t), t, 0.0)[:, None] * directions)
    plane = plane.reshape(frames, rays)
    u = pixels[:, 0].reshape(frames, rays)
    v = pixels[:, 1].reshape(frames, rays)
    ok = (plane != NO_HIT) & np.isfinite(u) & np.isfinite(v)
    f, k = np.nonzero(ok[:, :-1] & ok[:, 1:])
    u0, u1, v0, v1 = u[f, k], u[f, k + 1], v[f, k], v[f, k + 1]
    lo = np.maximum(np.ceil(np.minimum(u0, u1)), 0.0)
    hi = np.minimum(np.floor(np.maximum(u0, u1)), model.camera.width - 1.0)
    count = np.maximum(hi - lo + 1.0, 0.0).astype(np.int64)
    rep = np.repeat(np.arange(f.size), count)
    cols = lo[rep] + (np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count))
    du = u1[rep] - u0[rep]
    frac = np.where(du != 0.0, (cols - u0[rep]) / np.where(du != 0.0, du, 1.0), 0.0)
    rows = v0[rep] + frac * (v1[rep] - v0[rep])
    first, second = plane[f, k][rep], plane[f, k + 1][rep]
    other = first != second
    frame = np.concatenate([f[rep], f[rep][other]])
    cols = np.concatenate([cols, cols[other]])
    rows = np.concatenate([rows, rows[other]])
    return _solve_and_verify(world, model, frame, cols, rows, rows + 0.5,
                             np.concatenate([first, second[other]]), base_poses, headings,
                             threads)


def rows_at(world: World, model: ScannerModel, points: StripePoints, base_poses: np.ndarray,
            headings: np.ndarray) -> np.ndarray:
    """Rows of the same stripe points (same column and plane) at other headings and poses
    (one per point), e.g. when the shutter opens and closes. Not verified."""
    map_head, _ = head_poses(model, base_poses, headings)
    planes = planes_in_head(world.world.planes.planes[points.plane], map_head)
    return solve_rows(model, points.u, points.v, points.v + 0.5, planes)
