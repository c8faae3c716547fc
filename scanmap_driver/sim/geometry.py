"""Scene geometry for ray casting: triangle meshes with exact planes, in Open3D's RaycastingScene.

Two things are hit: the scene (floor, floor regions, boxes, cylinders) fixed in `map`,
cast with Open3D, and the robot's own encoder disk fixed in `base_link`, intersected
exactly. Every triangle of the scene belongs to a plane (a box face, a cylinder facet, a
cap, the floor, a floor region's surface or side) stored in float64 as (n, d) with
n . x = d; Open3D's float32 hits only say which plane a ray met, and exact points come
from the planes. The floor z = 0 is cut around the floor regions (`floor_pieces`); glass
objects and regions are left out (nothing hits them).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import open3d as o3d
from numba import njit

from ..encoder_disk import EncoderDisk
from .scene import Box, Cylinder, FloorRegion, Scene
from .texture import surface_axes

FLOOR_MARGIN = 60.0  # m of floor beyond the scene on every side
FACET_LENGTH = 0.02  # m: a cylinder gets a side per this much circumference
NO_HIT = -1


@dataclass(frozen=True)
class Planes:
    """Triangles grouped into planes: what a ray hit, exactly."""

    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32
    triangle_plane: np.ndarray  # (T,) int32
    planes: np.ndarray  # (P, 4) float64: unit normal (outward) and offset d, n . x = d
    plane_object: np.ndarray  # (P,) int32: index of the owning object (0 = floor)


class Raycaster:
    """Open3D ray casting over one `Planes` set, answering plane ids and exact distances."""

    def __init__(self, planes: Planes) -> None:
        self.planes = planes
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(planes.vertices.astype(np.float32)),
            o3d.core.Tensor(planes.triangles.astype(np.uint32)))

    def cast(self, origins: np.ndarray, directions: np.ndarray,
             threads: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Plane id (NO_HIT = -1) and exact float64 distance (inf) along unit `directions`.

        `origins` is (3,) for one common origin or (N, 3).
        """
        directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64),
                                                       directions.shape))
        rays = np.empty((directions.shape[0], 6), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = directions
        hits = self._scene.cast_rays(o3d.core.Tensor(rays), nthreads=threads)
        primitive = hits["primitive_ids"].numpy().astype(np.int64)
        hit = primitive != o3d.t.geometry.RaycastingScene.INVALID_ID
        plane = np.full(directions.shape[0], NO_HIT, dtype=np.int32)
        plane[hit] = self.planes.triangle_plane[primitive[hit]]
        return plane, plane_distance(self.planes.planes, plane, origins, directions)


@njit(cache=True, nogil=True)
def plane_distance(planes: np.ndarray, plane: np.ndarray, origins: np.ndarray,
                   directions: np.ndarray) -> np.ndarray:
    """Exact distance along each ray (N, 3) to its plane (inf where plane is NO_HIT)."""
    t = np.full(plane.shape[0], np.inf)
    for i in range(plane.shape[0]):
        p = plane[i]
        if p != NO_HIT:
            n = planes[p]
            t[i] = (n[3] - n[0] * origins[i, 0] - n[1] * origins[i, 1] - n[2] * origins[i, 2]) \
                / (n[0] * directions[i, 0] + n[1] * directions[i, 1] + n[2] * directions[i, 2])
    return t


class _Builder:
    """Accumulates triangles and planes."""

    def __init__(self) -> None:
        self.vertices: list[np.ndarray] = []
        self.triangles: list[np.ndarray] = []
        self.triangle_plane: list[np.ndarray] = []
        self.planes: list[np.ndarray] = []
        self.plane_object: list[int] = []
        self._count = 0

    def polygon(self, corners: np.ndarray, owner: int, outward: np.ndarray) -> None:
        """A planar convex polygon (corners in order) as a triangle fan, one plane."""
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        normal /= np.linalg.norm(normal)
        if normal @ outward < 0.0:
            normal = -normal
        self._add(corners, [[0, i, i + 1] for i in range(1, len(corners) - 1)],
                  normal, float(normal @ corners.mean(axis=0)), owner)

    def _add(self, corners, triangles, normal, offset, owner) -> None:
        plane_id = len(self.planes)
        self.vertices.append(np.asarray(corners, dtype=np.float64))
        tri = np.asarray(triangles, dtype=np.int32) + self._count
        self.triangles.append(tri)
        self.triangle_plane.append(np.full(len(tri), plane_id, dtype=np.int32))
        self.planes.append(np.array([*normal, offset]))
        self.plane_object.append(owner)
        self._count += len(corners)

    def build(self) -> Planes:
        return Planes(np.vstack(self.vertices), np.vstack(self.triangles),
                      np.concatenate(self.triangle_plane), np.vstack(self.planes),
                      np.array(self.plane_object, dtype=np.int32))


def box_corners(box: Box) -> np.ndarray:
    """(8, 3) corners: bottom four then top four, counter-clockwise."""
    hx, hy, hz = 0.5 * np.array(box.size)
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    xy = local @ np.array([[c, s], [-s, c]]) + np.array(box.center[:2])
    z0, z1 = box.center[2] - hz, box.center[2] + hz
    return np.vstack([np.column_stack([xy, np.full(4, z0)]),
                      np.column_stack([xy, np.full(4, z1)])])


def _add_box(builder: _Builder, box: Box, owner: int) -> None:
    corners = box_corners(box)
    middle = corners.mean(axis=0)
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    for face in faces:
        quad = corners[face]
        builder.polygon(quad, owner, quad.mean(axis=0) - middle)


def cylinder_sides(cylinder: Cylinder) -> int:
    """Number of flat sides the cylinder is built from."""
    return int(np.clip(math.ceil(2.0 * math.pi * cylinder.radius / FACET_LENGTH), 16, 96))


def _add_cylinder(builder: _Builder, cylinder: Cylinder, owner: int) -> None:
    n = cylinder_sides(cylinder)
    # Vertices on a circle of radius r / cos(pi/n): the flat sides touch the true circle.
    r = cylinder.radius / math.cos(math.pi / n)
    angles = 2.0 * math.pi * np.arange(n) / n
    cx, cy, cz = cylinder.center
    ring = np.column_stack([cx + r * np.cos(angles), cy + r * np.sin(angles)])
    z0, z1 = cz - 0.5 * cylinder.height, cz + 0.5 * cylinder.height
    for i in range(n):
        j = (i + 1) % n
        quad = np.array([[*ring[i], z0], [*ring[j], z0], [*ring[j], z1], [*ring[i], z1]])
        outward = np.append(0.5 * (ring[i] + ring[j]) - (cx, cy), 0.0)
        builder.polygon(quad, owner, outward)
    for z, up in ((z0, -1.0), (z1, 1.0)):
        cap = np.column_stack([ring, np.full(n, z)])
        builder.polygon(cap, owner, np.array([0.0, 0.0, up]))


def _distinct(corners: np.ndarray) -> np.ndarray:
    """The corners of a polygon without repeats of the previous corner (cyclically)."""
    keep = np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1) > 1e-12
    return corners[keep]


def _span(corners: np.ndarray, x: float) -> tuple[float, float]:
    """(lowest, highest) y of a convex polygon (K, 2) on the vertical line at x."""
    ys = []
    for (ax, ay), (bx, by) in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        if min(ax, bx) <= x <= max(ax, bx):
            ys.extend([ay, by] if ax == bx else [ay + (x - ax) * (by - ay) / (bx - ax)])
    return min(ys), max(ys)


def floor_pieces(x0: float, y0: float, x1: float, y1: float,
                 regions: tuple[FloorRegion, ...]) -> list[np.ndarray]:
    """Convex pieces (K, 2) covering the rectangle [x0, x1] x [y0, y1] outside the regions
    (convex, not overlapping): vertical slabs between the regions' corners, in which each
    region is a trapezoid, and the trapezoids between them."""
    polygons = [r.corners for r in regions]
    breaks = sorted({x0, x1, *(float(x) for c in polygons for x in c[:, 0])})
    pieces = []
    for xa, xb in itertools.pairwise(breaks):
        middle = 0.5 * (xa + xb)
        inside = [c for c in polygons if c[:, 0].min() < middle < c[:, 0].max()]
        spans = sorted(((_span(c, xa), _span(c, xb)) for c in inside),
                       key=lambda s: s[0][0] + s[1][0])
        low_a, low_b = y0, y0
        for (lo_a, hi_a), (lo_b, hi_b) in [*spans, ((y1, y1), (y1, y1))]:
            piece = _distinct(np.array([[xa, low_a], [xb, low_b], [xb, lo_b], [xa, lo_a]]))
            if len(piece) >= 3:
                pieces.append(piece)
            low_a, low_b = hi_a, hi_b
    return pieces


def _add_region(builder: _Builder, region: FloorRegion, owner: int,
                regions: tuple[FloorRegion, ...], first_owner: int) -> None:
    """A floor region's surface and the vertical faces joining it to what lies beyond each
    edge: the floor z = 0, or another region sharing part of that edge (a ramp going down
    into a lower area meets it without a face where their heights agree). `regions`: the
    scene's regions, owners first_owner, first_owner + 1, ...; a face between two regions
    is built once, by the one listed first."""
    corners = region.corners
    top = np.column_stack([corners, region.height_at(corners[:, 0], corners[:, 1])])
    builder.polygon(top, owner, np.array([0.0, 0.0, 1.0]))
    middle = corners.mean(axis=0)
    for i in range(len(corners)):
        a, b = corners[i], corners[(i + 1) % len(corners)]
        outward = 0.5 * (a + b) - middle
        for t0, t1 in itertools.pairwise(_edge_breaks(a, b, regions)):
            probe = a + 0.5 * (t0 + t1) * (b - a) + 1e-6 * outward / np.linalg.norm(outward)
            beyond = next((k for k, other in enumerate(regions)
                           if other is not region and other.contains(*probe)), None)
            if beyond is not None and first_owner + beyond < owner:
                continue  # that region builds the face
            ends = np.array([a + t0 * (b - a), a + t1 * (b - a)])
            inner = region.height_at(ends[:, 0], ends[:, 1])
            outer = np.zeros(2) if beyond is None \
                else regions[beyond].height_at(ends[:, 0], ends[:, 1])
            _add_edge_face(builder, ends, inner, outer, outward, owner)


def _edge_breaks(a: np.ndarray, b: np.ndarray, regions: tuple[FloorRegion, ...]
                 ) -> list[float]:
    """Sorted positions t in [0, 1] along the edge a -> b where what lies beyond it may
    change: its ends and the regions' corners lying on it."""
    direction = b - a
    length2 = float(direction @ direction)
    breaks = {0.0, 1.0}
    for other in regions:
        for corner in other.corners:
            t = float((corner - a) @ direction) / length2
            offset = corner - (a + t * direction)
            if 0.0 < t < 1.0 and offset @ offset <= 1e-18 + 1e-18 * length2:
                breaks.add(t)
    return sorted(breaks)


FACE_TOLERANCE = 1e-9  # m: surfaces closer than this at an edge meet there


def _add_edge_face(builder: _Builder, ends: np.ndarray, inner: np.ndarray,
                   outer: np.ndarray, outward: np.ndarray, owner: int) -> None:
    """The vertical face over the edge piece `ends` (2, 2) between the region's heights
    `inner` and those beyond it `outer` at its ends, facing the lower side; split where
    the two surfaces cross, none where they meet."""
    rise = np.where(np.abs(inner - outer) > FACE_TOLERANCE, inner - outer, 0.0)
    if not rise.any():
        return
    inner = outer + rise  # where they meet, one corner
    if rise[0] * rise[1] < 0.0:  # the surfaces cross along the piece: two triangles
        s = rise[0] / (rise[0] - rise[1])
        cross = ends[0] + s * (ends[1] - ends[0])
        z = inner[0] + s * (inner[1] - inner[0])
        for k in (0, 1):
            triangle = np.array([[*ends[k], outer[k]], [*ends[k], inner[k]], [*cross, z]])
            builder.polygon(triangle, owner, np.append(outward * np.sign(rise[k]), 0.0))
        return
    face = _distinct(np.array([[*ends[0], outer[0]], [*ends[1], outer[1]],
                               [*ends[1], inner[1]], [*ends[0], inner[0]]]))
    if len(face) >= 3:
        higher = 1.0 if rise[0] + rise[1] > 0.0 else -1.0  # seen from the lower side
        builder.polygon(face, owner, np.append(higher * outward, 0.0))


def scene_planes(scene: Scene) -> Planes:
    """The scene's floor, objects and floor regions as planes: object i of the scene is owner
    i + 1, region j owner len(objects) + j + 1, the floor 0. Glass is left out."""
    builder = _Builder()
    low, high = scene.bounds()
    x0, y0 = low - FLOOR_MARGIN
    x1, y1 = high + FLOOR_MARGIN
    for piece in floor_pieces(x0, y0, x1, y1, scene.floor_regions):
        builder.polygon(np.column_stack([piece, np.zeros(len(piece))]), 0,
                        np.array([0.0, 0.0, 1.0]))
    for index, obj in enumerate(scene.objects, start=1):
        if obj.material == "glass":
            continue
        if isinstance(obj, Box):
            _add_box(builder, obj, index)
        else:
            _add_cylinder(builder, obj, index)
    first = len(scene.objects) + 1
    for index, region in enumerate(scene.floor_regions, start=first):
        if region.material != "glass":
            _add_region(builder, region, index, scene.floor_regions, first)
    return builder.build()


def owner_reflectance(scene: Scene) -> np.ndarray:
    """Laser reflectance of each plane owner (floor, objects, regions): 0 for a mirror."""
    owners = (*scene.objects, *scene.floor_regions)
    return np.array([1.0, *(0.0 if o.material == "mirror" else o.reflectance for o in owners)])


def rotate(vectors: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(N, 3) vectors times rotation.T, without BLAS.

    OpenBLAS runs an (N, 3) x (3, 3) product on all cores and spins idle threads: twenty
    times the CPU time of this loop on a busy machine.
    """
    return np.einsum("ij,kj->ik", vectors, rotation)


@njit(cache=True, nogil=True)
def transform_per_frame(poses: np.ndarray, frame: np.ndarray, vectors: np.ndarray,
                        translate: bool) -> np.ndarray:
    """Apply pose `poses[frame[i]]` (F, 4, 4) to row i of `vectors` (N, 3).

    translate=False rotates directions only.
    """
    out = np.empty((vectors.shape[0], 3))
    for i in range(vectors.shape[0]):
        pose = poses[frame[i]]
        x, y, z = vectors[i, 0], vectors[i, 1], vectors[i, 2]
        for k in range(3):
            out[i, k] = pose[k, 0] * x + pose[k, 1] * y + pose[k, 2] * z
            if translate:
                out[i, k] += pose[k, 3]
    return out


class World:
    """The scene (in `map`) and the robot's encoder disk (in `base_link`) for ray casting,
    with each scene plane's colour."""

    def __init__(self, scene: Scene, disk: EncoderDisk) -> None:
        self.scene = scene
        self.disk = disk
        self.world = Raycaster(scene_planes(scene))
        colors = np.array([scene.floor_color, *(obj.color for obj in scene.objects),
                           *(region.color for region in scene.floor_regions)],
                          dtype=np.float64) / 255.0
        self.plane_albedo = colors[self.world.planes.plane_object]  # (P, 3) RGB 0..1
        # (P,) share of the laser light returned (0: no stripe)
        self.plane_reflectance = owner_reflectance(scene)[self.world.planes.plane_object]
        self.plane_axes = surface_axes(self.world.planes.planes[:, :3])  # (P, 2, 3) texture

    def first_hits(self, origins: np.ndarray, directions: np.ndarray, frame: np.ndarray,
                   map_from: np.ndarray, base_from: np.ndarray, threads: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Plane id and distance in the scene, and distance to the disk, for rays given in
        a frame that `map_from[frame]` and `base_from[frame]` (F, 4, 4) carry into `map`
        and `base_link` (rigidly, so distances are the same in all three)."""
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64),
                                                       directions.shape))
        directions = np.ascontiguousarray(directions, dtype=np.float64)
        plane, t = self.world.cast(transform_per_frame(map_from, frame, origins, True),
                                   transform_per_frame(map_from, frame, directions, False),
                                   threads)
        t_disk = self.disk.ray_distance(transform_per_frame(base_from, frame, origins, True),
                                        transform_per_frame(base_from, frame, directions,
                                                            False))
        return plane, t, t_disk
