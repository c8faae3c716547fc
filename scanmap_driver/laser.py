"""Laser stripe extraction: one subpixel peak per image line across the stripe.

The paper finds laser pixels by colour: in the dark `r > t, g < t, b < t` (its eq. 1);
in bright rooms a narrow Gaussian convolution of each channel along the image lines,
keeping a strong red response that is absent in green and blue. Here, in four passes:

1. Evidence per pixel: `dark` keeps `r` where eq. 1 holds, else 0; `bright` takes the
   signed red excess `r - max(g, b)`. The ridge filter below is linear, so filtering the
   excess is filtering red minus the stronger of green and blue, the paper's test in one
   filter instead of three. A clipped white core has no excess, but its red flanks do,
   and the filter spans the core, so it is still found by its colour.
2. Ridge response along each line: the evidence smoothed by a narrow triangle kernel (a
   Gaussian approximation computed with running sums, O(1) per pixel) minus the larger
   of the two side means. A stripe stands above both sides; a wide red object has no
   ridge, and at its edges one side is as high as the centre, so red objects are not
   taken for the laser. The response is at most the centre's own mean: the stripe is
   red, and a line less blue than the blue around it stands above its sides but not
   above zero. The best response per line is kept; separate runs above the noise
   threshold are counted (MULTIPLE when two or more). Where the stripe's width is not
   given, lines where nothing reaches the noise threshold near a sign of a wider stripe
   are tried again with windows WIDE_FACTOR (2.5) times as wide: a core clipped over a
   long stretch, or widened by its glow on a white surface, has no ridge in windows sized
   for the frame's typical stripe (on the real bust frame, 22% of the laser's rows); such
   a line is kept only where it continues the stripe (pass 4).
3. Subpixel peak on a fit channel (red by default, luma which keeps full resolution under
   MJPG chroma subsampling, or the evidence) with the chosen estimator; a clipped,
   flat-topped core is located from its flanks (half-height edges, or a Gaussian fit of
   the unclipped samples; a core clipped wider than the fit window, e.g. white over 8 px
   and red over 19, from the level crossings of its flanks up to 32 px away). An
   unclipped line's samples are first blended with its two neighbouring lines' (weights
   1, 2, 1) where the stripe runs straight and evenly through the three: the fit becomes
   2-D, as the usual detectors' Gaussian blur is, without blurring depth or reflectance
   edges (`_laser_kernels._blend_across_lines`). On the real flat board it removes the
   outlier the 1-D fit had over the simple detector (876 rows on the line, 2 outliers,
   like it), and on the simulator's office, corridor and hazards frames the RMS error
   of the lines within 1.5 px goes from 0.244 to 0.239 px. Where the scene steps from
   bright to dark under the stripe (its two side means on the fit channel differ by
   more than half the peak's height: a black surface's edge beside the stripe), the
   bright side's own light pulled the centroid 1-4 px towards it; such a line is fitted
   on the evidence, which holds the laser's light alone, unless green or blue rise at
   its core (a white core, where the evidence dips: the real flat board's stripe at its
   dark seam). On 19 rendered recordings (seeds 4000-4007 of the mixed and random rooms,
   three approach rooms) points more than 5 cm off every lit point of their image column
   (`scanmap map`'s report, `errors.range_m.gross`) 1318 -> 1031.
4. Lines whose ridge is under the threshold but above the noise part of it are kept
   when a run of peaks on consecutive lines links them to the stripe (hysteresis along
   the stripe); on such a line the ridge maximum near the stripe of the line before (or
   after) is taken when something elsewhere on it responds more (`follow_stripe`, before
   pass 3). Lone peaks without neighbours along the stripe are dropped.

Method "auto" (the default), per frame: the bright method, unless its threshold is set
by noise (the noise part, noise_factor x evidence noise, above min_threshold and not
below the relative part: green and blue noise of a dark, gained-up camera) and eq. 1
passes at most DARK_PASSES (10) pixels per line, sampled on every 4th line (only the
laser passes it: a dark room); then the dark method, whose mask removes that noise. A
lit or red-lit scene, or a clean one, stays with the bright method; the dark method's
extra pass runs only on noisy frames.

Automatic thresholds follow the frame: the ridge threshold is the largest of a floor, a
multiple of the evidence noise (mean |difference| of neighbouring samples) and a fraction
of the typical stripe contrast; the dark method's `t` lies midway between the scene's
mean red and the median of the lines' red maxima (the laser's level).

Lines across the stripe are image columns for the scanner (camera on its side: one line
per column u, the peak is the row v) or rows (`axis="rows"`, e.g. a turntable scanner);
the kernels (`_laser_kernels`) stream along the positions and vectorise across the lines,
and rows are transposed once, in the evidence pass.

Default estimator, by measurement (benchmarks/bench_laser.py; sigma 1.5 px stripes): the
half-height centroid ("com") matches Blais-Rioux under MJPG (0.18 px RMS; bright room
0.24 px), which is what webcams send, and on the simulator's frames (motion, defocus,
gamma, speckle) it is better (0.29-0.31 against 0.32-0.38 px) with several times fewer
gross errors; Blais-Rioux and the least-squares Gaussian win on clean, uncompressed
Gaussians (0.02 px). The Gaussian fit costs about twice the whole extraction.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import _laser_kernels as lk
from .errors import ScanError


class Flag(enum.IntFlag):
    """Per-line quality bits of a `StripeResult` (0 = a clean peak)."""

    NONE_FOUND = lk.NONE_FOUND  # no candidate above the threshold on this line
    SATURATED = lk.SATURATED  # the red channel is clipped at the peak
    MULTIPLE = lk.MULTIPLE  # more than one candidate above the noise; the best was kept
    AT_EDGE = lk.AT_EDGE  # the fit window was cut by the end of the line
    SKIPPED = lk.SKIPPED  # the line lies outside `line_range`
    FIT_FAILED = lk.FIT_FAILED  # the estimator failed; the integer peak was kept
    ISOLATED = lk.ISOLATED  # a peak without enough neighbours along the stripe: dropped
    NOT_RED = lk.NOT_RED  # a clipped white peak without red flanks (lamp, window): dropped


ESTIMATORS = ("max", "gauss3", "blais_rioux", "lsq", "com")
FIT_CHANNELS = ("red", "luma", "evidence")
METHODS = ("auto", "dark", "bright")
AXES = ("columns", "rows")


@dataclass(frozen=True)
class LaserConfig:
    """Configures laser stripe extraction: how evidence, ridge, threshold and subpixel fit
    find one peak per image line across the stripe.

    method: "auto" (chosen per frame, see the module doc), "dark" (paper eq. 1) or
        "bright" (red excess with ridge test).
    threshold: minimum ridge response (evidence units, 0-255) or "auto".
    colour_threshold: the `t` of eq. 1 for the dark method, or "auto".
    estimator: subpixel estimator, one of ESTIMATORS.
    fit_channel: channel the peak is fitted on, one of FIT_CHANNELS.
    axis: "columns" when each line across the stripe is an image column (the scanner's
        side-mounted camera), "rows" when it is an image row.
    stripe_width: expected full width at half maximum of the stripe (px), which sets the
        filter, side and fit windows; None measures it on each frame (`frame_stripe_width`).
    line_range: (start, stop) of the lines to process, e.g. to skip the encoder disk.
    saturation: level (0-255) from which a channel counts as clipped.
    noise_factor, min_threshold, relative_threshold: the automatic ridge threshold is
        max(min_threshold, noise_factor * evidence noise, relative_threshold * typical
        stripe contrast), the last being the 75th percentile of the lines' best responses
        (the stripe crosses most lines; noise and lone red objects do not).
    support: a peak is kept only if at least this many of the `support` lines either
        side have a peak within 2 * stripe_width per line of separation (the stripe is
        continuous; camera noise gives lone dots). 0 keeps every peak.
    image_size: (width, height) the frames must have, or None to accept any size.
    """

    method: str = "auto"
    threshold: float | str = "auto"
    colour_threshold: float | str = "auto"
    estimator: str = "com"
    fit_channel: str = "red"
    axis: str = "columns"
    stripe_width: float | None = None
    line_range: tuple[int, int] | None = None
    saturation: int = 250
    noise_factor: float = 6.0
    min_threshold: float = 12.0
    relative_threshold: float = 0.25
    support: int = 2
    image_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        for name, allowed in (("method", METHODS), ("estimator", ESTIMATORS),
                              ("fit_channel", FIT_CHANNELS), ("axis", AXES)):
            if getattr(self, name) not in allowed:
                raise ScanError(f"LaserConfig.{name}: expected one of {allowed}, "
                                f"got {getattr(self, name)!r}")
        for name in ("threshold", "colour_threshold"):
            value = getattr(self, name)
            if value != "auto" and not (isinstance(value, (int, float)) and 0 <= value <= 255):
                raise ScanError(f"LaserConfig.{name}: expected 'auto' or a level in "
                                f"0..255, got {value!r}")
        if self.stripe_width is not None and not 1.0 <= self.stripe_width <= 10.0:
            raise ScanError(f"LaserConfig.stripe_width: expected 1..10 px, got "
                            f"{self.stripe_width}")
        if not (isinstance(self.support, int) and self.support >= 0):
            raise ScanError(f"LaserConfig.support: expected an integer >= 0, got "
                            f"{self.support!r}")
        if not 1 <= self.saturation <= 255:
            raise ScanError(f"LaserConfig.saturation: expected 1..255, got {self.saturation}")
        if self.line_range is not None and not (
                len(self.line_range) == 2 and 0 <= self.line_range[0] < self.line_range[1]):
            raise ScanError(f"LaserConfig.line_range: expected (start, stop) with "
                            f"0 <= start < stop, got {self.line_range}")


MIN_WIDTH, DEFAULT_WIDTH, MAX_WIDTH = 1.0, 3.5, 10.0  # stripe FWHM (px)
WIDTH_SAMPLE_STEP = 8  # the stripe width is measured on every 8th line
WIDTH_TOLERANCE = 1.5  # a measured width within this factor of DEFAULT_WIDTH keeps it
WIDTH_SPREAD = 0.25  # largest interquartile range of the lines' widths, relative
STATISTICS_STEP = 4  # the frame's red statistics and eq. 1 passes on every 4th line
DARK_PASSES = MAX_WIDTH  # most eq. 1 pixels per line of a dark room: the laser's alone
WIDE_FACTOR = 2.5  # the second, wide ridge scale on lines the first found nothing on
WIDE_SIGN = 1.5  # a stripe this many times the frame's width is a sign of a wide stretch
WIDE_REACH = 16  # lines from such a sign on which the wide scale is tried
WIDE_LEVEL = 4.0  # a sampled line's wide evidence is a sign from this times the threshold


def filter_windows(fwhm: float) -> tuple[int, int, int, int]:
    """(triangle half-size m, side offset d, side width w, fit half-width) in px for a
    stripe of full width at half maximum `fwhm`."""
    m = max(2, round(0.85 * fwhm))
    offset = max(m, round(0.9 * fwhm))
    width = max(4, round(1.2 * fwhm))
    fit = max(3, math.ceil(1.3 * fwhm))
    return m, offset, width, fit


def frame_stripe_width(widths: np.ndarray) -> float:
    """The stripe's width from its `widths` on every WIDTH_SAMPLE_STEP-th line of the
    evidence plane: the median of the width of each line's strongest evidence
    (`_laser_kernels.evidence_widths`),
    within MIN_WIDTH..MAX_WIDTH. DEFAULT_WIDTH when no line has a peak, when the lines
    disagree (interquartile range above WIDTH_SPREAD of the median: noise and objects, not
    one stripe), or when the measure is within WIDTH_TOLERANCE of it: the filter holds
    such widths, and MJPG's halved chroma widens the red excess a little, so only a stripe
    that clearly misfits resizes it. The stripe crosses most lines: the median is its
    width."""
    q25, measured, q75 = lk.quartiles(widths)
    if not math.isfinite(measured):
        return DEFAULT_WIDTH
    if (q75 - q25 > WIDTH_SPREAD * measured
            or DEFAULT_WIDTH / WIDTH_TOLERANCE <= measured <= DEFAULT_WIDTH * WIDTH_TOLERANCE):
        return DEFAULT_WIDTH
    return float(np.clip(measured, MIN_WIDTH, MAX_WIDTH))


@dataclass(frozen=True)
class StripeResult:
    """One entry per image line across the stripe (per column u for the scanner).

    peak: subpixel position along the line (row v for axis "columns"), NaN if none.
    strength: peak height above the local background on the fit channel (0-255).
    width: full width at half maximum of the peak (px).
    contrast: ridge response of the winning candidate (evidence units).
    candidates: number of separate ridge runs above the noise part of the threshold
        (`noise_factor * noise`, or the manual threshold); MULTIPLE when two or more.
    flags: `Flag` bits.
    threshold, colour_threshold: the levels used (after "auto").
    method: the method used, "dark" or "bright" (chosen per frame for "auto").
    """

    peak: np.ndarray
    strength: np.ndarray
    width: np.ndarray
    contrast: np.ndarray
    candidates: np.ndarray
    flags: np.ndarray
    threshold: float
    colour_threshold: float
    method: str

    @property
    def found(self) -> np.ndarray:
        """Lines with a peak."""
        return np.isfinite(self.peak)


def automatic_colour_threshold(flat: np.ndarray, height: int, width: int,
                               by_rows: bool) -> float:
    """Eq. 1's `t`: midway between the scene's mean red and the laser's level (the median
    of the lines' red maxima), on every STATISTICS_STEP-th line. Red objects brighter
    than the laser pass it too; the ridge test rejects them unless they are as narrow as
    the stripe."""
    mean, laser_level = lk.red_statistics(flat, height, width, by_rows, STATISTICS_STEP)
    return float(np.clip(0.5 * (mean + laser_level), 40.0, 250.0))


def colour_threshold(s: LaserConfig, flat: np.ndarray, height: int, width: int,
                     by_rows: bool) -> float:
    """Eq. 1's `t`: the configured level, or `automatic_colour_threshold`."""
    if s.colour_threshold == "auto":
        return automatic_colour_threshold(flat, height, width, by_rows)
    return float(s.colour_threshold)


def eq1_keeps_only_the_laser(flat: np.ndarray, height: int, width: int, by_rows: bool,
                             t: float, saturation: int) -> bool:
    """True when eq. 1 with threshold `t` passes at most DARK_PASSES pixels per line
    (sampled on every STATISTICS_STEP-th line): the laser's few and nothing of the scene,
    a dark room. Not so in a lit or red-lit scene, nor with a core clipped wider than a
    stripe."""
    passes = lk.eq1_passes(flat, height, width, by_rows, STATISTICS_STEP,
                           np.uint8(round(t)), np.uint8(saturation))
    return passes <= DARK_PASSES


def check_frame(image: np.ndarray, image_size: tuple[int, int] | None = None,
                what: str = "frame") -> None:
    """Raise ScanError unless `image` is an HxWx3 uint8 BGR array (of `image_size` = (W, H))."""
    if not isinstance(image, np.ndarray):
        raise ScanError(f"{what}: expected a numpy BGR image, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ScanError(f"{what}: expected dtype uint8 (BGR as OpenCV delivers it), got "
                        f"{image.dtype}")
    if image.ndim != 3 or image.shape[2] != 3:
        raise ScanError(f"{what}: expected shape (height, width, 3), got {image.shape}")
    if image_size is not None and (image.shape[1], image.shape[0]) != tuple(image_size):
        raise ScanError(f"{what}: expected {image_size[0]}x{image_size[1]} pixels (width x "
                        f"height), got {image.shape[1]}x{image.shape[0]}")


class _Ridges(NamedTuple):
    e: np.ndarray  # evidence plane (positions + 2 pad, lines)
    fwhm: float
    widths: np.ndarray  # the evidence's width on every WIDTH_SAMPLE_STEP-th line (px)
    noise: float
    noise_thr: float  # the noise part of the ridge threshold
    thr: float  # the whole ridge threshold
    unit: int  # the ridge response of a unit evidence step
    best: np.ndarray
    best_pos: np.ndarray
    count: np.ndarray


def _ridges(flat: np.ndarray, height: int, width: int, by_rows: bool, dark: bool, t: float,
            s: LaserConfig, pad: int, lo: int, hi: int) -> _Ridges:
    """Passes 1 and 2 with one method: evidence, stripe width, noise, ridge and threshold."""
    n_lines, n_pos = (height, width) if by_rows else (width, height)
    e = np.empty((n_pos + 2 * pad, n_lines), np.int16)
    e[:pad] = 0
    e[pad + n_pos:] = 0
    lk.evidence_kernel(flat, height, width, by_rows, dark, np.uint8(round(t)),
                       np.uint8(s.saturation), pad, e)
    widths = lk.evidence_widths(e, pad, n_pos, WIDTH_SAMPLE_STEP)
    fwhm = frame_stripe_width(widths) if s.stripe_width is None else s.stripe_width
    m, offset, side, _ = filter_windows(fwhm)
    noise = lk.evidence_noise(e, pad, n_pos, 4)
    noise_thr = (max(s.min_threshold, s.noise_factor * noise) if s.threshold == "auto"
                 else float(s.threshold))
    unit = m * m * side
    noise_int = max(1, round(noise_thr * unit))
    small = 2 * 255 * unit < 2**15 and n_pos < 2**15
    kind = np.int16 if small else np.int32
    best = np.empty(n_lines, kind)
    best_pos = np.empty(n_lines, kind)
    count = np.empty(n_lines, kind)
    lk.ridge_kernel(e, n_pos, pad, m, offset, side, min(noise_int, 2**15 - 1),
                    min(noise_int // 2, 2**15 - 1), best, best_pos, count)
    # The passes after the ridge take int32, as the wide pass's do: one specialisation
    # of each kernel to compile, cache and load, not one per type (fit_kernel: 15 ms).
    best, best_pos, count = (a.astype(np.int32, copy=False) for a in (best, best_pos, count))
    thr = noise_thr
    if s.threshold == "auto" and hi > lo:
        rank = (3 * (hi - lo - 1)) // 4
        typical = float(np.partition(best[lo:hi], rank)[rank])
        thr = max(thr, s.relative_threshold * typical / unit)
    return _Ridges(e, fwhm, widths, noise, noise_thr, thr, unit, best, best_pos, count)


def _wide_stripe_lines(r: _Ridges, lo: int, hi: int, fit: tuple, colour: tuple,
                       found: tuple) -> bool:
    """Pass 2 again at WIDE_FACTOR times the frame's stripe width on the lines where it
    found nothing: where the core clips over a long stretch, or a glow widens the stripe,
    windows sized for the frame's typical stripe lie inside it and see no ridge. Only
    lines within WIDE_REACH of a sign of such a stripe are tried (`_laser_kernels.
    wide_lines`: a found peak WIDE_SIGN times wider than the frame's stripe, or a sampled
    line's evidence that wide and reaching WIDE_LEVEL times the threshold). A line
    whose wide ridge reaches the frame's threshold, with both side
    windows inside the line (the padding beyond its ends is no side), is fitted with the
    wide windows; its contrast stays the narrow one, below the threshold, so it is kept
    only when it continues the stripe (`keep_continued`, which the caller runs when this
    returns True).
    """
    peak, _, line_width, contrast, flags = found
    width = min(WIDE_FACTOR * r.fwhm, MAX_WIDTH)
    if width <= r.fwhm:
        return False
    pad, n_pos = fit[2], fit[3]
    lines = lk.wide_lines(peak, line_width, flags, r.e, pad, n_pos, r.widths,
                          WIDTH_SAMPLE_STEP, WIDE_SIGN * r.fwhm, WIDE_LEVEL * r.thr,
                          WIDE_REACH, lo, hi)
    if lines.size == 0:
        return False
    m, offset, side, half = filter_windows(width)
    unit = m * m * side
    best = np.empty(lines.size, np.int32)
    best_pos = np.empty(lines.size, np.int32)
    count = np.empty(lines.size, np.int32)
    noise_int = max(1, round(r.noise_thr * unit))
    lk.ridge_kernel(lk.gather_lines(r.e, lines), n_pos, pad, m, offset, side, noise_int,
                    noise_int // 2, best, best_pos, count)
    clear = offset + side  # both side windows inside the line, not in its zero padding
    strong = np.flatnonzero((best >= r.thr * unit) & (best_pos >= clear)
                            & (best_pos < n_pos - clear))
    if strong.size == 0:
        return False
    lines = lines[strong]
    narrow = contrast[lines]
    flags[lines] = 0
    lk.fit_kernel(*fit, lines, best[strong], best_pos[strong], count[strong],
                  max(1, round(r.thr * unit)), 1.0 / unit, m, offset, side, half, *colour,
                  *found)
    contrast[lines] = narrow
    return True


def extract_stripe(image_bgr: np.ndarray, settings: LaserConfig | None = None) -> StripeResult:
    """The laser stripe's subpixel peak on every image line across it (see module doc)."""
    s = settings or LaserConfig()
    check_frame(image_bgr, s.image_size)
    image = np.ascontiguousarray(image_bgr)
    height, width = image.shape[:2]
    by_rows = s.axis == "rows"
    n_lines, n_pos = (height, width) if by_rows else (width, height)
    m, offset, side, half = filter_windows(s.stripe_width or MAX_WIDTH)
    pad = max(m, offset + side)  # the widest windows the frame may need
    if n_pos < 2 * pad + 1:
        raise ScanError(f"frame: lines of {n_pos} px are too short for a stripe width of "
                        f"{s.stripe_width or MAX_WIDTH} px")
    lo, hi = (0, n_lines) if s.line_range is None else (
        min(s.line_range[0], n_lines), min(s.line_range[1], n_lines))
    flat = image.reshape(-1)
    dark = s.method == "dark"
    t = colour_threshold(s, flat, height, width, by_rows) if dark else 0.0
    r = _ridges(flat, height, width, by_rows, dark, t, s, pad, lo, hi)
    if s.method == "auto" and r.thr <= r.noise_thr and s.noise_factor * r.noise > s.min_threshold:
        t = colour_threshold(s, flat, height, width, by_rows)
        dark = eq1_keeps_only_the_laser(flat, height, width, by_rows, t, s.saturation)
        if dark:
            r = _ridges(flat, height, width, by_rows, True, t, s, pad, lo, hi)
        else:
            t = 0.0
    e, fwhm, _, noise, noise_thr, thr, unit, best, best_pos, count = r
    m, offset, side, half = filter_windows(fwhm)
    thr_int = max(1, round(noise_thr * unit))  # weaker lines: `keep_continued` below
    peak = np.full(n_lines, np.nan)
    strength = np.full(n_lines, np.nan, np.float32)
    line_width = np.full(n_lines, np.nan, np.float32)
    contrast = np.full(n_lines, np.nan, np.float32)
    flags = np.zeros(n_lines, np.uint8)
    flags[:lo] = lk.SKIPPED
    flags[hi:] = lk.SKIPPED
    line_stride, pos_stride = (width, 1) if by_rows else (1, width)
    if thr > noise_thr:
        lk.follow_stripe(e, pad, n_pos, m, offset, side, lo, hi, thr * unit, thr_int,
                         2.0 * fwhm, best, best_pos)
    fit = (flat, e, pad, n_pos, line_stride, pos_stride)
    found = (peak, strength, line_width, contrast, flags)
    colour = (ESTIMATORS.index(s.estimator), FIT_CHANNELS.index(s.fit_channel),
              float(s.saturation), max(s.min_threshold, s.noise_factor * noise))
    lk.fit_kernel(*fit, np.arange(lo, hi), best[lo:hi], best_pos[lo:hi], count[lo:hi],
                  thr_int, 1.0 / unit, m, offset, side, half, *colour, *found)
    wide = s.stripe_width is None and _wide_stripe_lines(r, lo, hi, fit, colour, found)
    if thr > noise_thr or wide:
        lk.keep_continued(peak, contrast, flags, lo, hi, thr, 2.0 * fwhm)
    if s.support > 0:
        lk.drop_isolated(peak, flags, lo, hi, s.support, 2.0 * fwhm)
    return StripeResult(peak=peak, strength=strength, width=line_width, contrast=contrast,
                        candidates=np.minimum(count, 255).astype(np.uint8), flags=flags,
                        threshold=thr, colour_threshold=t,
                        method="dark" if dark else "bright")
