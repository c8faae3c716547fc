"""Heading from the encoder disk seen at the bottom of every frame.

The disk is fixed to the scanner's base, perpendicular to the head's axis and centred on
it, its printed face at `base_link` height `encoder.height` on the axis; its angles are
measured in the mount frame (`base_link` for the default upright mount), so that a ring
point at disk angle alpha appears in `head` at angle alpha - theta.

Decoding (the paper intersects the pixel's ray with the disk plane, as for laser pixels):

1. Geometry, once per model: the ray of every pixel of the disk's band is intersected with
   the disk plane (in `head`); pixels that land on the code ring, clear of its edges,
   are binned by their disk angle phi in `head` into a 1-D angular profile.
2. Per frame: the profile of mean grey levels, turned back into linear light (webcams
   deliver sRGB; blur is symmetric only in linear light), then the normalised
   correlation with the rendered code, defocus-blurred, `value(phi + theta)`, over 8
   candidate headings per sector (coarse). Correlation stays absolute under blur where
   bit thresholding fails.
3. Refinement from the edges: each code edge in view is located where the profile
   crosses the middle between the dark and light levels (linear interpolation between
   bins); each edge gives theta = edge angle - observed phi, and their robust mean is
   the heading.

A rotationally symmetric code (e.g. alternating sectors) has equally good candidates one
period apart; it is tracked from the `previous` heading, as the paper offers. A frame is
`ok` only with enough contrast, a clear correlation peak (for absolute codes, a margin
over the best heading more than a sector away) and consistent edges; otherwise the
result says why, and never carries a heading.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from .errors import ScanError
from .laser import check_frame
from .scanner_model import ScannerModel
from .transforms import wrap_angle
from .triangulation import pixel_rays

COARSE_STEPS = 8  # candidate headings per sector in the coarse search
SEARCH_STEP = 8  # px between the pixels that locate the disk before the full-resolution pass


@dataclass(frozen=True)
class EncoderConfig:
    """Configures heading decoding from the encoder disk: profile binning, blur model
    and the acceptance limits of a decoded heading.

    bin_width: angular bin of the profile (rad).
    blur: defocus blur (px, Gaussian sigma) of the rendered code for the correlation.
    ring_margin: fraction of the ring's width dropped at each radial edge (blur there
        mixes in what lies beside the ring).
    min_contrast: least difference between light and dark sectors (linear grey, 0-255).
    min_score: least normalised correlation at the best heading.
    min_margin: least correlation margin over the best heading more than a sector away
        (absolute codes) or half a sector away (symmetric codes).
    max_spread: largest standard deviation of the per-edge headings (rad).
    pixel_step: use every n-th ring pixel (in raster order); 2 halves the time and, the
        bins averaging dozens of pixels each, leaves the error unchanged (bench_laser).
    srgb: frames are sRGB-encoded (webcams); grey levels are linearised before the edges
        are located. False for linear frames.
    """

    bin_width: float = math.radians(0.25)
    blur: float = 4.0
    ring_margin: float = 0.15
    min_contrast: float = 15.0
    min_score: float = 0.7
    min_margin: float = 0.15
    max_spread: float = math.radians(0.5)
    pixel_step: int = 2
    srgb: bool = True


@dataclass(frozen=True)
class HeadingResult:
    """The heading of one frame.

    heading: rad in [-pi, pi), NaN unless ok. sector: code sector under the head's x axis
    (-1 unless ok). score: normalised correlation at the best heading. margin: score
    minus the best score more than a sector away. contrast: light minus dark grey level.
    edges: code edges used in the refinement. spread: their standard deviation (rad; 0
    with a single edge, e.g. when a run of five equal sectors fills the view).
    ok: the heading can be trusted. reason: why not, or "ok".
    """

    heading: float
    sector: int
    score: float
    margin: float
    contrast: float
    edges: int
    spread: float
    ok: bool
    reason: str


@dataclass(frozen=True)
class RingGeometry:
    """Where the code ring appears in the image and how its pixels map to disk angles."""

    pixels: np.ndarray  # (N,) flat pixel index row * width + col
    bins: np.ndarray  # (N,) profile bin of each pixel
    bin_angle: np.ndarray  # (B,) mean head angle of each bin's pixels (rad)
    bin_count: np.ndarray  # (B,) pixels per bin
    candidates: np.ndarray  # (C,) coarse candidate headings (rad)
    templates: np.ndarray  # (B, C) blurred code per candidate (column), zero mean, unit norm
    bits: np.ndarray  # (S,) the code, float 0/1
    edges: np.ndarray  # (E,) disk angles of the code's edges (rad)
    rising: np.ndarray  # (E,) True where the code goes 0 -> 1 with increasing angle
    period: float  # rotational period of the code (2 pi for an absolute code)
    disk_lines: tuple[int, int]  # first and last image column u that sees the disk


def disk_lift(model: ScannerModel) -> float:
    """Height of the disk face along the head's axis, in `head` coordinates (m)."""
    mount = model.head_mount.pose
    if abs(mount[2, 2]) < 1e-6:
        raise ScanError("head_mount: the head's axis is horizontal; the disk cannot be seen")
    return float((model.encoder.height - mount[2, 3]) / mount[2, 2])


def code_period(code: str) -> int:
    """Smallest rotation (in sectors) that maps the code onto itself."""
    n = len(code)
    return next(p for p in range(1, n + 1) if n % p == 0 and code == code[p:] + code[:p])


def blurred_code(bits: np.ndarray, zero: float, angles: np.ndarray,
                 sigma: np.ndarray) -> np.ndarray:
    """The code at disk angles (rad) blurred by a Gaussian of width sigma (rad, per angle)."""
    n = bits.size
    step = 2.0 * math.pi / n
    reach = int(np.ceil(4.0 * np.max(sigma) / step)) + 1
    pos = (angles - zero) / step
    base = np.floor(pos).astype(np.int64)
    sigma = np.broadcast_to(sigma, np.broadcast(angles, sigma).shape)
    out = np.zeros(sigma.shape)
    for k in range(-reach, reach + 1):
        start = (base + k - pos) * step
        weight = normal_cdf((start + step) / sigma) - normal_cdf(start / sigma)
        out += bits[(base + k) % n] * weight
    return out


def normal_cdf(x: np.ndarray) -> np.ndarray:
    """The standard normal CDF of every element (scipy.special.ndtr without scipy.special,
    whose import costs 0.16 s of every command's start)."""
    x = np.asarray(x, dtype=np.float64)
    return _normal_cdf(np.ascontiguousarray(x).reshape(-1)).reshape(x.shape)


@njit(cache=True, nogil=True)
def _normal_cdf(x: np.ndarray) -> np.ndarray:
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = 0.5 * math.erfc(-x[i] / math.sqrt(2.0))
    return out


_RING_LOCK = threading.Lock()


def ring_geometry(model: ScannerModel, settings: EncoderConfig) -> RingGeometry:
    """Pixels of the code ring, their angular bins, and the coarse templates, computed
    once per (model, settings): threads that ask meanwhile wait for the first one."""
    with _RING_LOCK:
        return _cached_ring_geometry(model, settings)


def disk_region(model: ScannerModel, step: int = SEARCH_STEP) -> tuple[int, int, int, int]:
    """(first row, end row, first column, end column) of the image that hold every pixel
    seeing the disk, from a search on
    every `step`-th pixel and the image's last row and column, widened by `step` + 1 px;
    the whole image when the search finds no disk pixel (a disk too small for it)."""
    cam = model.camera
    u = np.unique(np.r_[np.arange(0, cam.width, step), cam.width - 1]).astype(np.float64)
    v = np.unique(np.r_[np.arange(0, cam.height, step), cam.height - 1]).astype(np.float64)
    radius, _, ahead = _disk_hits(model, *np.meshgrid(u, v))
    seen = ahead & (radius <= model.encoder.outer_radius)
    if not seen.any():
        return 0, cam.height, 0, cam.width
    rows, cols = v[seen.any(axis=1)], u[seen.any(axis=0)]
    pad = step + 1
    return (max(0, int(rows.min()) - pad), min(cam.height, int(rows.max()) + pad + 1),
            max(0, int(cols.min()) - pad), min(cam.width, int(cols.max()) + pad + 1))


def _disk_hits(model: ScannerModel, u: np.ndarray, v: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(radius, disk angle in `head`, hit ahead of the camera) where the rays of pixels
    (u, v) meet the disk plane; arrays of u's shape."""
    centre, rays = pixel_rays(model, u.ravel(), v.ravel())
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (disk_lift(model) - centre[2]) / rays[:, 2]
    hit = centre[:2] + t[:, None] * rays[:, :2]
    shape = np.shape(u)
    return (np.hypot(hit[:, 0], hit[:, 1]).reshape(shape),
            np.arctan2(hit[:, 1], hit[:, 0]).reshape(shape),
            (np.isfinite(t) & (t > 0)).reshape(shape))


@lru_cache(maxsize=8)
def _cached_ring_geometry(model: ScannerModel, settings: EncoderConfig,
                          region: tuple[int, int, int, int] | None = None) -> RingGeometry:
    """`ring_geometry` over `region` of the image (default: `disk_region`)."""
    cam, enc = model.camera, model.encoder
    row0, row1, col0, col1 = region or disk_region(model)
    u, v = np.meshgrid(np.arange(col0, col1, dtype=np.float64),
                       np.arange(row0, row1, dtype=np.float64))
    radius, angle, ahead = _disk_hits(model, u, v)
    on_disk = ahead & (radius <= enc.outer_radius)
    if not on_disk.any():
        raise ScanError(f"{model.name}: the encoder disk is not in the camera's view")
    cols = u[on_disk]
    width = enc.outer_radius - enc.inner_radius
    margin = settings.ring_margin * width
    ring = ahead & (radius >= enc.inner_radius + margin) & (radius <= enc.outer_radius - margin)
    inside = np.flatnonzero(ring)[::max(1, settings.pixel_step)]
    pixels = (v.ravel()[inside] * cam.width + u.ravel()[inside]).astype(np.int64)
    phi = angle.ravel()[inside]
    if np.ptp(phi) > math.pi:
        raise ScanError(f"{model.name}: the camera sees more than half of the encoder ring; "
                        "this geometry is not supported")
    lo = phi.min()
    bins = np.floor((phi - lo) / settings.bin_width).astype(np.int64)
    n_bins = int(bins.max()) + 1
    count = np.bincount(bins, minlength=n_bins)
    used = count > 0
    remap = np.cumsum(used) - 1
    bins = remap[bins]
    count = count[used]
    bin_angle = np.bincount(bins, weights=phi) / count
    # angular size of a pixel at each bin: the defocus blur in angle units
    grad = _angle_per_pixel(angle).ravel()[inside]
    bin_scale = np.bincount(bins, weights=grad) / count
    sector = enc.sector_angle
    candidates = np.arange(enc.sectors * COARSE_STEPS) * (sector / COARSE_STEPS)
    bits = enc.bits().astype(np.float64)
    templates = blurred_code(bits, enc.zero_offset, bin_angle[None, :] + candidates[:, None],
                             np.maximum(settings.blur * bin_scale, 1e-4)[None, :])
    templates -= templates.mean(axis=1, keepdims=True)
    norms = np.linalg.norm(templates, axis=1, keepdims=True)
    templates /= np.where(norms > 0, norms, 1.0)
    change = np.flatnonzero(bits != np.roll(bits, 1))
    return RingGeometry(
        pixels=pixels, bins=bins, bin_angle=bin_angle, bin_count=count,
        candidates=candidates, templates=np.ascontiguousarray(templates.T), bits=bits,
        edges=enc.zero_offset + change * sector, rising=bits[change] > 0,
        period=code_period(enc.code) * sector,
        disk_lines=(int(cols.min()), int(cols.max())))


def _angle_per_pixel(angle: np.ndarray) -> np.ndarray:
    """|grad angle| per pixel (rad/px) of an angle image, unwrapped locally."""
    du = np.diff(angle, axis=1, append=angle[:, -1:])
    dv = np.diff(angle, axis=0, append=angle[-1:, :])
    du = (du + math.pi) % (2 * math.pi) - math.pi
    dv = (dv + math.pi) % (2 * math.pi) - math.pi
    return np.hypot(du, dv)


def laser_line_range(model: ScannerModel) -> tuple[int, int]:
    """Image lines (columns u) free of the encoder disk, as `LaserConfig.line_range`."""
    first, last = ring_geometry(model, EncoderConfig()).disk_lines
    width = model.camera.width
    if last >= width - 1:
        return 0, first
    if first <= 0:
        return last + 1, width
    raise ScanError(f"{model.name}: the encoder disk is seen in the middle of the image "
                    f"(columns {first}..{last}); no single line range avoids it")


@njit(cache=True, nogil=True)
def ring_profile(flat: np.ndarray, pixels: np.ndarray, bins: np.ndarray,
                 count: np.ndarray, srgb: bool) -> np.ndarray:
    """Mean grey level (b + g + r) / 3 of each angular bin, 0..255.

    srgb: the frame is sRGB-encoded (as webcams deliver it): each bin's mean is turned
    back into linear light, where defocus and motion blur act symmetrically, so that an
    edge's middle level marks its position. (The pixels of a bin share one disk angle,
    so linearising their mean equals averaging them linearised, up to the noise.)
    """
    sums = np.zeros(count.shape[0])
    for k in range(pixels.shape[0]):
        i = 3 * pixels[k]
        sums[bins[k]] += np.int32(flat[i]) + np.int32(flat[i + 1]) + np.int32(flat[i + 2])
    for b in range(count.shape[0]):
        x = sums[b] / (3.0 * 255.0 * count[b])
        if srgb:
            x = x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4
        sums[b] = 255.0 * x
    return sums


@njit(cache=True, nogil=True)
def edge_headings(profile: np.ndarray, angle: np.ndarray, edges: np.ndarray,
                  rising: np.ndarray, theta: float, mid: float, reach: float,
                  out: np.ndarray) -> int:
    """Heading given by each code edge in view; returns how many were found.

    An edge at disk angle e is expected at head angle e - theta. The profile is searched
    within `reach` of it for a crossing of `mid` in the edge's direction, placed by
    linear interpolation between bins; the edge then says theta = e - crossing.
    """
    n = 0
    lo = angle[0]
    hi = angle[angle.shape[0] - 1]
    for k in range(edges.shape[0]):
        expect = edges[k] - theta
        expect = (expect + math.pi) % (2.0 * math.pi) - math.pi
        if expect - reach < lo or expect + reach > hi:
            continue
        best = np.inf
        found = np.nan
        for j in range(angle.shape[0] - 1):
            if abs(angle[j] - expect) > reach:
                continue
            a = profile[j] - mid
            b = profile[j + 1] - mid
            crosses = (a < 0.0 <= b) if rising[k] else (a >= 0.0 > b)
            if crosses:
                at = angle[j] + (angle[j + 1] - angle[j]) * a / (a - b)
                if abs(at - expect) < best:
                    best = abs(at - expect)
                    found = at
        if math.isfinite(found):
            d = edges[k] - found - theta
            out[n] = theta + (d + math.pi) % (2.0 * math.pi) - math.pi
            n += 1
    return n


@njit(cache=True, nogil=True)
def correlate(templates: np.ndarray, profile: np.ndarray) -> np.ndarray:
    """profile @ templates (bins, candidates) on this thread; BLAS would spread a product
    this small over every core and spin. The inner loop runs over the candidates, so it
    vectorises without reordering any sum."""
    out = np.zeros(templates.shape[1])
    for j in range(profile.shape[0]):
        row = templates[j]
        p = profile[j]
        for c in range(out.shape[0]):
            out[c] += row[c] * p
    return out


@njit(cache=True, nogil=True)
def code_levels(profile: np.ndarray, angle: np.ndarray, bits: np.ndarray, zero: float,
                theta: float, keep_out: float) -> tuple[float, float]:
    """(dark, light) grey levels: profile means over the bins at least keep_out (rad) from
    a sector edge, on dark and on light sectors at heading theta (NaN if none)."""
    n = bits.shape[0]
    step = 2.0 * math.pi / n
    sums = np.zeros(2)
    counts = np.zeros(2)
    for j in range(angle.shape[0]):
        pos = (angle[j] + theta - zero) / step
        cell = math.floor(pos)
        frac = pos - cell
        if min(frac, 1.0 - frac) * step >= keep_out:
            value = int(bits[int(cell) % n])
            sums[value] += profile[j]
            counts[value] += 1.0
    if counts[0] == 0.0 or counts[1] == 0.0:
        return np.nan, np.nan
    return sums[0] / counts[0], sums[1] / counts[1]


@njit(cache=True, nogil=True)
def correlation_peak(scores: np.ndarray, candidates: np.ndarray, period: float,
                     exclusion: float) -> tuple[int, float]:
    """Best candidate and its margin over the best one more than `exclusion` (rad) away,
    the distance taken modulo the code's rotational `period`."""
    best = int(np.argmax(scores))
    runner = -np.inf
    for c in range(scores.shape[0]):
        d = abs(candidates[c] - candidates[best]) % period
        if min(d, period - d) > exclusion + 1e-9:
            runner = max(runner, scores[c])
    return best, scores[best] - runner if math.isfinite(runner) else scores[best]


@njit(cache=True, nogil=True)
def refine_from_edges(profile: np.ndarray, angle: np.ndarray, edges: np.ndarray,
                      rising: np.ndarray, theta: float, mid: float, reach: float,
                      outlier: float) -> tuple[float, int, float]:
    """(heading, edges used, their standard deviation) from the code edges in view.

    Two rounds: the per-edge headings (see `edge_headings`) around the current heading,
    then the mean of those within `outlier` of their median. Edges: 0 when none found.
    """
    found = np.empty(edges.shape[0])
    used = 0
    spread = 0.0
    for _ in range(2):
        n = edge_headings(profile, angle, edges, rising, theta, mid, reach, found)
        if n == 0:
            return theta, 0, np.nan
        centre = np.median(found[:n])
        total = 0.0
        total2 = 0.0
        used = 0
        for k in range(n):
            if abs(found[k] - centre) < outlier:
                total += found[k]
                total2 += found[k] * found[k]
                used += 1
        theta = total / used
        spread = math.sqrt(max(total2 / used - theta * theta, 0.0)) if used >= 2 else 0.0
    return theta, used, spread


def _fail(reason: str, score: float = math.nan, margin: float = math.nan,
          contrast: float = math.nan) -> HeadingResult:
    return HeadingResult(heading=math.nan, sector=-1, score=score, margin=margin,
                         contrast=contrast, edges=0, spread=math.nan, ok=False, reason=reason)


def decode_heading(image_bgr: np.ndarray, model: ScannerModel, previous: float | None = None,
                   settings: EncoderConfig | None = None) -> HeadingResult:
    """The head's heading from the encoder disk in a frame (see the module docstring).

    previous: the last good heading (rad); needed for a rotationally symmetric code,
    ignored for an absolute one.
    """
    s = settings or EncoderConfig()
    cam = model.camera
    check_frame(image_bgr, (cam.width, cam.height))
    geo = ring_geometry(model, s)
    enc = model.encoder
    profile = ring_profile(np.ascontiguousarray(image_bgr).reshape(-1), geo.pixels, geo.bins,
                           geo.bin_count, s.srgb)
    centred = profile - profile.mean()
    norm = float(np.linalg.norm(centred))
    if not norm > 1e-9:
        return _fail("no contrast on the code ring (uniform, black or saturated)")
    scores = correlate(geo.templates, centred / norm)
    symmetric = geo.period < 2.0 * math.pi - 1e-9
    best, margin = correlation_peak(scores, geo.candidates, geo.period,
                                    enc.sector_angle * (0.5 if symmetric else 1.0))
    score = float(scores[best])
    theta = float(geo.candidates[best])
    if symmetric:
        if previous is None or not math.isfinite(previous):
            return _fail("rotationally symmetric code: the previous heading is needed",
                         score, margin)
        theta += round(float(wrap_angle(previous - theta)) / geo.period) * geo.period
    dark, light = code_levels(profile, geo.bin_angle, geo.bits, enc.zero_offset, theta,
                              0.3 * enc.sector_angle)
    contrast = light - dark
    if not contrast >= s.min_contrast:
        return _fail(f"contrast {contrast:.1f} below {s.min_contrast} grey levels", score,
                     margin, contrast)
    if score < s.min_score:
        return _fail(f"correlation {score:.2f} below {s.min_score}", score, margin, contrast)
    if margin < s.min_margin:
        return _fail(f"ambiguous: correlation margin {margin:.2f} below {s.min_margin}",
                     score, margin, contrast)
    theta, used, spread = refine_from_edges(profile, geo.bin_angle, geo.edges, geo.rising,
                                            theta, 0.5 * (dark + light),
                                            0.5 * enc.sector_angle, 4.0 * s.max_spread)
    if used == 0:
        return _fail("no code edge found where the correlation puts one", score, margin,
                     contrast)
    if not spread <= s.max_spread:
        return HeadingResult(heading=math.nan, sector=-1, score=score, margin=margin,
                             contrast=contrast, edges=used, spread=spread, ok=False,
                             reason=f"edges disagree (spread {math.degrees(spread):.2f} deg)")
    heading = float(wrap_angle(theta))
    sector = math.floor((heading - enc.zero_offset) / enc.sector_angle) % enc.sectors
    return HeadingResult(heading=heading, sector=sector, score=score, margin=margin,
                         contrast=contrast, edges=used, spread=spread, ok=True, reason="ok")


# ---------------------------------------------------------------------------------
# Sequences of headings


def fill_unreadable(headings: np.ndarray, ok: np.ndarray, times: np.ndarray,
                    max_gap: float = 0.5) -> np.ndarray:
    """Headings (rad, wrapped) with the unreadable frames interpolated from their neighbours.

    The motion is smooth: between the readable frames before and after a run of
    unreadable ones, the heading is interpolated linearly in time on the unwrapped angle,
    if those two frames are at most `max_gap` seconds apart (less than half a turn, so the
    unwrapping is sure). Frames before the first or after the last readable frame are
    extrapolated from the two nearest readable ones, up to `max_gap` from the nearest.
    Everything else stays NaN. The filled frames are the ones with `ok` False (or a NaN
    heading); the caller flags them.
    """
    headings = np.asarray(headings, dtype=np.float64)
    ok = np.asarray(ok, dtype=bool)
    times = np.asarray(times, dtype=np.float64)
    if not headings.shape == ok.shape == times.shape or headings.ndim != 1:
        raise ScanError(f"fill_unreadable: headings, ok and times must be 1-D of one length, "
                        f"got {headings.shape}, {ok.shape}, {times.shape}")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise ScanError("fill_unreadable: frame times must be finite and increasing")
    ok = ok & np.isfinite(headings)
    out = np.full(headings.shape, np.nan)
    known = np.flatnonzero(ok)
    if known.size == 0:
        return out
    unwrapped = np.unwrap(headings[known])
    out[known] = unwrapped
    t_known = times[known]
    for i in np.flatnonzero(~ok):
        after = int(np.searchsorted(t_known, times[i]))
        if 0 < after < known.size:
            a, b = after - 1, after
            if t_known[b] - t_known[a] <= max_gap:
                w = (times[i] - t_known[a]) / (t_known[b] - t_known[a])
                out[i] = unwrapped[a] + w * (unwrapped[b] - unwrapped[a])
        elif known.size >= 2:
            a, b = (0, 1) if after == 0 else (known.size - 2, known.size - 1)
            near = a if after == 0 else b
            if abs(times[i] - t_known[near]) <= max_gap:
                rate = (unwrapped[b] - unwrapped[a]) / (t_known[b] - t_known[a])
                out[i] = unwrapped[near] + rate * (times[i] - t_known[near])
    return wrap_angle(out)


@dataclass(frozen=True)
class Coverage:
    """How much of the circle a sequence of headings covers.

    covered: the full turn minus the gaps wider than max_gap (rad). complete: no such gap.
    largest_gap: widest angular gap between neighbouring headings (rad), starting at
    gap_start (rad). headings: how many finite headings were counted.
    """

    covered: float
    complete: bool
    largest_gap: float
    gap_start: float
    headings: int


def coverage(headings: np.ndarray, max_gap: float = math.radians(15.0)) -> Coverage:
    """Whether the headings cover 360 deg, with no gap wider than max_gap (NaN ignored)."""
    values = np.asarray(headings, dtype=np.float64).ravel()
    values = np.sort(np.mod(values[np.isfinite(values)], 2.0 * math.pi))
    if values.size == 0:
        return Coverage(covered=0.0, complete=False, largest_gap=2.0 * math.pi,
                        gap_start=0.0, headings=0)
    gaps = np.diff(np.append(values, values[0] + 2.0 * math.pi))
    widest = int(np.argmax(gaps))
    missing = float(gaps[gaps > max_gap].sum())
    return Coverage(covered=2.0 * math.pi - missing, complete=bool(missing == 0.0),
                    largest_gap=float(gaps[widest]), gap_start=float(values[widest]),
                    headings=int(values.size))
