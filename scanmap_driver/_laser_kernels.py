"""Numba kernels of the laser stripe extraction (`laser.extract_stripe`, which documents
the method): the evidence plane, the ridge response, the subpixel peak estimators, the
per-line peak fit and the removal of lone peaks. Each has a plain-numpy reference in
tests/scanmap_driver/test_laser.py.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# per-line quality bits of a StripeResult (named by `laser.Flag`)
NONE_FOUND, SATURATED, MULTIPLE, AT_EDGE, SKIPPED, FIT_FAILED, ISOLATED, NOT_RED = (
    1, 2, 4, 8, 16, 32, 64, 128)


# ---------------------------------------------------------------------------------
# Pass 1: evidence plane (int16), laid out (positions + 2 pad, lines), zero padded.
# Only subtractions and comparisons of the raw uint8 values, which LLVM can vectorise
# (numba widens integer arithmetic to int64; a clamp would defeat the narrowing).


WHITE_CAP = 127  # a clipped-red pixel's green and blue count at most this much against it


@njit(cache=True, nogil=True)
def _evidence_rows(flat: np.ndarray, n: int, dark: bool, t: np.uint8, sat: np.uint8,
                   out: np.ndarray) -> None:
    cap = np.uint8(WHITE_CAP)
    if dark:
        for i in range(n):
            b, g, r = flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]
            hit = ((r > t) & (g < t) & (b < t)) | (r >= sat)
            out[i] = np.int16(r) if hit else np.int16(0)
    else:
        for i in range(n):
            b, g, r = flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]
            m = g if g > b else b
            m = cap if (r >= sat) & (m > cap) else m
            out[i] = np.int16(r) - np.int16(m)


@njit(cache=True, nogil=True)
def evidence_kernel(flat: np.ndarray, height: int, width: int, by_rows: bool, dark: bool,
                    t: np.uint8, sat: np.uint8, pad: int, out: np.ndarray) -> None:
    """Fill `out` (positions + 2 pad, lines) with the per-pixel laser evidence.

    flat: the BGR image raveled. by_rows: lines are image rows (else columns).
    bright: r - max(g, b) (signed); dark: r where eq. 1 holds, else 0. A pixel whose red
    is clipped (>= sat) is a possible white laser core: in the bright method its green
    and blue count at most WHITE_CAP, in the dark method it passes. Such a core is only
    accepted with red flanks (see `fit_kernel`).
    """
    if not by_rows:
        n = height * width
        _evidence_rows(flat, n, dark, t, sat, out.reshape(-1)[pad * width:pad * width + n])
        return
    row = np.empty(width, np.int16)
    for v in range(height):
        _evidence_rows(flat[3 * v * width:3 * (v + 1) * width], width, dark, t, sat, row)
        for u in range(width):
            out[pad + u, v] = row[u]


@njit(cache=True, nogil=True)
def evidence_noise(e: np.ndarray, pad: int, n_pos: int, step: int) -> float:
    """Mean |difference| between neighbouring evidence samples along the lines.

    Sampled every `step` positions; the laser covers a few pixels per line, so this
    measures the scene's texture and noise, which the ridge threshold must clear.
    """
    n_lines = e.shape[1]
    total = 0
    count = 0
    for p in range(0, n_pos - 1, step):
        a = e[pad + p]
        b = e[pad + p + 1]
        acc = 0
        for u in range(n_lines):
            d = np.int32(a[u]) - np.int32(b[u])
            acc += d if d >= 0 else -d
        total += acc
        count += n_lines
    return total / max(count, 1)


@njit(cache=True, nogil=True)
def red_statistics(flat: np.ndarray, height: int, width: int, by_rows: bool,
                   step: int) -> tuple[float, float]:
    """(mean, median over lines of the line's maximum) of the red channel, on every
    `step`-th line."""
    lines = np.arange(0, height if by_rows else width, step)
    line_max = np.zeros(lines.size, np.uint8)
    total = 0
    if by_rows:
        for k in range(lines.size):
            top = np.uint8(0)
            for u in range(width):
                r = flat[3 * (lines[k] * width + u) + 2]
                total += np.int32(r)
                top = r if r > top else top
            line_max[k] = top
    else:
        for v in range(height):
            for k in range(lines.size):
                r = flat[3 * (v * width + lines[k]) + 2]
                total += np.int32(r)
                line_max[k] = r if r > line_max[k] else line_max[k]
    return total / (lines.size * (width if by_rows else height)), float(np.median(line_max))


@njit(cache=True, nogil=True)
def eq1_passes(flat: np.ndarray, height: int, width: int, by_rows: bool, step: int,
               t: np.uint8, sat: np.uint8) -> float:
    """Mean number of pixels per line, over every `step`-th line, that pass eq. 1
    (r > t, g < t, b < t) or whose red is clipped (>= sat): the dark method's evidence."""
    n_lines = height if by_rows else width
    count = 0
    for v in range(0, height, step if by_rows else 1):
        for u in range(0, width, 1 if by_rows else step):
            i = 3 * (v * width + u)
            b, g, r = flat[i], flat[i + 1], flat[i + 2]
            count += ((r > t) & (g < t) & (b < t)) | (r >= sat)
    return count / ((n_lines + step - 1) // step)


@njit(cache=True, nogil=True)
def evidence_widths(e: np.ndarray, pad: int, n_pos: int, step: int) -> np.ndarray:
    """Width (px) of the evidence peak on every `step`-th line: between the interpolated
    crossings, around the line's maximum, of the midpoint between that maximum and the
    line's mean (the scene, which the stripe barely moves). NaN for a line without a peak
    above its mean.
    """
    lines = np.arange(0, e.shape[1], step)
    out = np.full(lines.size, np.nan)
    tops = np.full(lines.size, pad)
    highest = e[pad, lines].astype(np.int32)
    totals = np.zeros(lines.size, np.int64)
    for x in range(pad, pad + n_pos):  # along the positions: rows of e, read in order
        row = e[x]
        for k in range(lines.size):
            value = np.int32(row[lines[k]])
            totals[k] += value
            if value > highest[k]:
                highest[k] = value
                tops[k] = x
    for k in range(lines.size):
        u = lines[k]
        top = tops[k]
        total = totals[k]
        level = 0.5 * (e[top, u] + total / n_pos)
        if not e[top, u] > level:
            continue
        a = top
        while a > pad and e[a - 1, u] > level:
            a -= 1
        b = top
        while b < pad + n_pos - 1 and e[b + 1, u] > level:
            b += 1
        lo = a - (e[a, u] - level) / (e[a, u] - e[a - 1, u]) if a > pad else a
        hi = b + (e[b, u] - level) / (e[b, u] - e[b + 1, u]) if b < pad + n_pos - 1 else b
        out[k] = hi - lo
    return out


@njit(cache=True, nogil=True)
def quartiles(values: np.ndarray) -> tuple[float, float, float]:
    """(25th, 50th, 75th percentile) of the finite values, interpolated as numpy's
    default; NaNs without any (np.percentile costs tens of microseconds a call)."""
    finite = np.sort(values[np.isfinite(values)])
    n = finite.size
    if n == 0:
        return np.nan, np.nan, np.nan
    out = np.empty(3)
    for k in range(3):
        rank = 0.25 * (k + 1) * (n - 1)
        i = min(int(rank), n - 2) if n > 1 else 0
        frac = rank - i
        out[k] = finite[i] + frac * (finite[i + 1] - finite[i]) if n > 1 else finite[0]
    return out[0], out[1], out[2]


# ---------------------------------------------------------------------------------
# Pass 2: ridge response, streamed along the positions, vectorised across the lines.
# Each loop writes few arrays: LLVM gives up vectorising when the aliasing checks
# between many written arrays exceed its limit.


@njit(cache=True, nogil=True)
def _slide(acc: np.ndarray, add: np.ndarray, drop: np.ndarray) -> None:
    for u in range(acc.shape[0]):
        acc[u] += add[u] - drop[u]


@njit(cache=True, nogil=True)
def _triangle(tri: np.ndarray, slot: np.ndarray, box: np.ndarray) -> None:
    for u in range(tri.shape[0]):
        tri[u] += box[u] - slot[u]
        slot[u] = box[u]


@njit(cache=True, nogil=True)
def _response(s: np.ndarray, tri: np.ndarray, left: np.ndarray, right: np.ndarray,
              ws: np.int16, wc: np.int16) -> None:
    zero = left.dtype.type(0)
    for u in range(s.shape[0]):
        sides = max(left[u], right[u], zero)  # min(centre - sides, centre), in int16
        s[u] = tri[u] * ws - sides * wc


@njit(cache=True, nogil=True)
def _track(s: np.ndarray, best: np.ndarray, best_pos: np.ndarray, runs: np.ndarray,
           p: int, levels: np.ndarray) -> None:
    """Keep the best response and its position; count hysteresis runs (runs = 2 count + state).

    levels holds (start, end) of a run, 1, 0 and 0, in the arrays' integer type: every
    operation stays in that type, which keeps both loops vectorised.
    """
    hi, lo, one, zero = levels[0], levels[1], levels[2], levels[3]
    pos = levels[4] * zero + p
    for u in range(s.shape[0]):
        v = s[u]
        b = best[u]
        best_pos[u] = pos if v > b else best_pos[u]
        best[u] = v if v > b else b
    for u in range(s.shape[0]):
        v = s[u]
        r = runs[u]
        state = r & one
        above = one if v >= hi else zero
        keep = one if v >= lo else zero
        runs[u] = r - state + (above & (one - state)) * (one + one) + ((state | above) & keep)


@njit(cache=True, nogil=True)
def ridge_kernel(e: np.ndarray, n_pos: int, pad: int, m: int, offset: int, side: int,
                 thr_hi: int, thr_lo: int, best: np.ndarray, best_pos: np.ndarray,
                 count: np.ndarray) -> None:
    """Best ridge response per line, its position, and the number of runs above threshold.

    The response at x is min(T(x) * side - max(L(x), R(x)) * m^2, T(x) * side), i.e.
    (m^2 * side) times the triangle-weighted mean (weights m - |k|, |k| < m) minus the
    larger side mean, and at most that mean itself, where L sums
    e[x-offset-side+1 .. x-offset] and R sums e[x+offset .. x+offset+side-1]. The stripe is
    red at its centre: a line less blue than the blue around it (a dip of negative
    evidence) stands above its sides, but not above zero.
    T is a running sum of running box sums B(y) = e[y] + ... + e[y+m-1], so every filter
    costs O(1) per pixel. Runs start at >= thr_hi and end below thr_lo (hysteresis).
    best, best_pos and count share one integer type, int16 when the response fits it
    (twice the lanes per vector).
    """
    n_lines = e.shape[1]
    ring = np.zeros((m, n_lines), np.int16)
    tri = np.zeros(n_lines, np.int16)
    box = np.zeros(n_lines, np.int16)
    left = np.zeros(n_lines, np.int16)
    right = np.zeros(n_lines, np.int16)
    s = np.empty(n_lines, best.dtype)
    levels = np.array([thr_hi, thr_lo, 1, 0, 0]).astype(best.dtype)
    x = pad
    for y in range(x - m + 1, x + 1):
        slot = ring[y % m]
        for i in range(y, y + m):
            slot += e[i]
        tri += slot
    box[:] = ring[x % m]
    for i in range(x - offset - side + 1, x - offset + 1):
        left += e[i]
    for i in range(x + offset, x + offset + side):
        right += e[i]
    best[:] = np.iinfo(best.dtype).min
    best_pos[:] = -1
    count[:] = 0
    wc = s.dtype.type(m * m)
    ws = s.dtype.type(side)
    for p in range(n_pos):
        x = pad + p
        if p > 0:
            _slide(box, e[x + m - 1], e[x - 1])
            _triangle(tri, ring[x % m], box)
            _slide(left, e[x - offset], e[x - offset - side])
            _slide(right, e[x + offset + side - 1], e[x + offset - 1])
        _response(s, tri, left, right, ws, wc)
        _track(s, best, best_pos, count, p, levels)
    for u in range(n_lines):
        count[u] >>= 1


@njit(cache=True, nogil=True)
def ridge_at(e: np.ndarray, pad: int, line: int, x: int, m: int, offset: int,
             side: int) -> int:
    """The ridge response of `ridge_kernel` at position x of one line."""
    tri = 0
    for k in range(-m + 1, m):
        tri += (m - abs(k)) * np.int64(e[pad + x + k, line])
    left = 0
    right = 0
    for i in range(x - offset - side + 1, x - offset + 1):
        left += np.int64(e[pad + i, line])
    for i in range(x + offset, x + offset + side):
        right += np.int64(e[pad + i, line])
    return tri * side - max(left, right, 0) * m * m


@njit(cache=True, nogil=True)
def _nearest_ridge(e: np.ndarray, pad: int, n_pos: int, line: int, centre: int, reach: int,
                   m: int, offset: int, side: int) -> tuple[int, int]:
    """(response, position) of the strongest local maximum of the ridge response of one
    line within `reach` of `centre` (response -1 without an inner maximum)."""
    a = max(0, centre - reach)
    b = min(n_pos - 1, centre + reach)
    best, pos = -1, -1
    prev = ridge_at(e, pad, line, a, m, offset, side)
    here = ridge_at(e, pad, line, a + 1, m, offset, side) if a + 1 <= b else prev
    for x in range(a + 1, b):
        nxt = ridge_at(e, pad, line, x + 1, m, offset, side)
        if here > best and here >= prev and here >= nxt:
            best, pos = here, x
        prev, here = here, nxt
    return best, pos


@njit(cache=True, nogil=True)
def follow_stripe(e: np.ndarray, pad: int, n_pos: int, m: int, offset: int, side: int,
                  lo: int, hi: int, strong: float, weak: float, max_jump: float,
                  best: np.ndarray, best_pos: np.ndarray) -> None:
    """Hysteresis along the stripe in the ridge: on a line whose best response is under
    `strong` and not within max_jump of the stripe on the line before (then after), the
    strongest ridge maximum within max_jump of the stripe replaces it when it reaches
    `weak`. The stripe on such a line is weaker than something elsewhere on it."""
    reach = int(max_jump)
    linked = np.zeros(hi - lo, np.bool_)
    for i in range(lo, hi):
        linked[i - lo] = best[i] >= strong and best_pos[i] >= 0
    for step in (1, -1):
        start, stop = (lo + 1, hi) if step == 1 else (hi - 2, lo - 1)
        for i in range(start, stop, step):
            j = i - step
            if linked[i - lo] or not linked[j - lo]:
                continue
            if best[i] >= weak and abs(best_pos[i] - best_pos[j]) <= max_jump:
                linked[i - lo] = True
                continue
            value, pos = _nearest_ridge(e, pad, n_pos, i, best_pos[j], reach, m, offset,
                                        side)
            if value >= weak:
                best[i] = value
                best_pos[i] = pos
                linked[i - lo] = True


# ---------------------------------------------------------------------------------
# Pass 3: subpixel estimators on a background-free profile g (float64) around index i0.
# Each returns the offset from i0 (NaN on failure); `clipped` marks saturated samples.

EST_MAX, EST_GAUSS3, EST_BLAIS_RIOUX, EST_LSQ, EST_COM = range(5)  # laser.ESTIMATORS
COM_LEVEL = 0.5  # the centroid uses the peak above half its height
EVIDENCE = 2  # `_gather`'s channel number of the evidence
# A peak whose fit-channel sides differ by more than BACKGROUND_STEP of its height above
# the lower one is fitted on the evidence, unless green or blue rise at its core by more
# than CORE_RISE of that height (a white core: the evidence dips there)
BACKGROUND_STEP = 0.5
CORE_RISE = 0.25

# The per-line code passes whole buffers with a length n instead of slicing: a slice is a
# new array whose reference counting costs more than the estimators themselves.


@njit(cache=True, nogil=True, inline="always")
def offset_gauss3(g: np.ndarray, n: int, i0: int) -> float:
    """Three-point Gaussian: the vertex of the parabola through ln g at i0-1, i0, i0+1."""
    if i0 < 1 or i0 + 1 >= n:
        return np.nan
    a, b, c = g[i0 - 1], g[i0], g[i0 + 1]
    if a <= 0.0 or b <= 0.0 or c <= 0.0:
        return np.nan
    la, lb, lc = math.log(a), math.log(b), math.log(c)
    den = la - 2.0 * lb + lc
    if den >= 0.0:
        return np.nan
    d = 0.5 * (la - lc) / den
    return d if abs(d) <= 1.0 else np.nan


@njit(cache=True, nogil=True, inline="always")
def offset_blais_rioux(g: np.ndarray, n: int, i0: int) -> float:
    """Blais-Rioux: zero crossing of the filter h(i) = g(i-2) + g(i-1) - g(i+1) - g(i+2).

    h rises through zero at the peak (negative on the rising side, positive after it).
    """
    if i0 < 3 or i0 + 3 >= n:
        return np.nan
    hm = g[i0 - 3] + g[i0 - 2] - g[i0] - g[i0 + 1]
    h0 = g[i0 - 2] + g[i0 - 1] - g[i0 + 1] - g[i0 + 2]
    hp = g[i0 - 1] + g[i0] - g[i0 + 2] - g[i0 + 3]
    if h0 <= 0.0 < hp:
        return h0 / (h0 - hp)
    if hm <= 0.0 < h0:
        return -1.0 + hm / (hm - h0)
    return np.nan


@njit(cache=True, nogil=True, inline="always")
def offset_com(g: np.ndarray, n: int, i0: int, half: int) -> float:
    """Centre of mass of g above COM_LEVEL of its height at i0, over the samples around i0
    that stay above that level (within +- half): the tails and the background, where
    noise and the scene's texture dominate, do not pull on it."""
    level = COM_LEVEL * g[i0]
    num = 0.0
    den = 0.0
    i = i0
    while i >= max(0, i0 - half) and g[i] > level:
        num += (g[i] - level) * (i - i0)
        den += g[i] - level
        i -= 1
    i = i0 + 1
    while i < min(n, i0 + half + 1) and g[i] > level:
        num += (g[i] - level) * (i - i0)
        den += g[i] - level
        i += 1
    return num / den if den > 0.0 else np.nan


@njit(cache=True, nogil=True, inline="always")
def _crossings(g: np.ndarray, n: int, i0: int, level: float) -> tuple[float, float]:
    """Interpolated positions where g, walking out from i0, first falls below `level` on
    each side (NaN if a side reaches the end of the profile)."""
    i = i0
    while i > 0 and g[i - 1] >= level:
        i -= 1
    j = i0
    while j < n - 1 and g[j + 1] >= level:
        j += 1
    if i == 0 or j == n - 1:
        return np.nan, np.nan
    lo = i - (g[i] - level) / (g[i] - g[i - 1])
    hi = j + (g[j] - level) / (g[j] - g[j + 1])
    return lo, hi


@njit(cache=True, nogil=True, inline="always")
def _half_crossings(g: np.ndarray, n: int, i0: int) -> tuple[float, float]:
    """Positions where g falls to half of g[i0] on each side (NaN if a side is cut)."""
    level = 0.5 * g[i0]
    if not level > 0.0:
        return np.nan, np.nan
    return _crossings(g, n, i0, level)


@njit(cache=True, nogil=True, inline="always")
def offset_edges(g: np.ndarray, n: int, i0: int) -> float:
    """Midpoint of the two half-height crossings (for clipped, flat-topped peaks)."""
    lo, hi = _half_crossings(g, n, i0)
    return 0.5 * (lo + hi) - i0


@njit(cache=True, nogil=True, inline="always")
def half_max_width(g: np.ndarray, n: int, i0: int) -> float:
    """Full width at half of g[i0] (NaN if a side is cut)."""
    lo, hi = _half_crossings(g, n, i0)
    return hi - lo


CLIP_REACH = 32  # px either side of a clipped peak searched for its flanks


@njit(cache=True, nogil=True, inline="always")
def clipped_centre(vals: np.ndarray, n: int, i0: int, sat: float) -> float:
    """Offset from i0 of the centre of the clipped (flat-topped) peak of vals[:n] at i0:
    the midpoint of the interpolated positions where the profile first falls below the
    level halfway between the clip level `sat` and the peak's foot (the higher of the two
    flanks' feet, where the descent from the clipped top stops). The flat top carries no
    position; a symmetric stripe's flanks cross any level symmetrically about its centre,
    however wide the clipped core. NaN when a flank does not descend within the profile."""
    if i0 < 1 or i0 >= n - 1:
        return np.nan
    i = i0
    while i > 0 and (vals[i - 1] >= sat or vals[i - 1] <= vals[i]):
        i -= 1
    j = i0
    while j < n - 1 and (vals[j + 1] >= sat or vals[j + 1] <= vals[j]):
        j += 1
    left, right = vals[i], vals[j]
    level = 0.5 * (sat + max(left, right))
    if not level < sat:
        return np.nan
    lo, hi = _crossings(vals, n, i0, level)
    return 0.5 * (lo + hi) - i0


@njit(cache=True, nogil=True)
def _gaussian_sums(g: np.ndarray, n: int, clipped: np.ndarray, amp: float, mu: float,
                   sig: float, normal: np.ndarray) -> float:
    """Cost of A exp(-(i-mu)^2 / 2 s^2) over unclipped samples; fills the normal equations.

    normal holds JtJ (a11 a12 a13 a22 a23 a33) then Jt r (b1 b2 b3) for (A, mu, s).
    The exponentials come from a recurrence: three exp calls per evaluation.
    """
    inv2 = 1.0 / (sig * sig)
    e = math.exp(-0.5 * mu * mu * inv2)
    q = math.exp(-(0.5 - mu) * inv2)
    qq = math.exp(-inv2)
    normal[:] = 0.0
    cost = 0.0
    for i in range(n):
        if not clipped[i]:
            d = i - mu
            j2 = amp * e * d * inv2
            j3 = j2 * d / sig
            r = g[i] - amp * e
            cost += r * r
            normal[0] += e * e
            normal[1] += e * j2
            normal[2] += e * j3
            normal[3] += j2 * j2
            normal[4] += j2 * j3
            normal[5] += j3 * j3
            normal[6] += e * r
            normal[7] += j2 * r
            normal[8] += j3 * r
        e *= q
        q *= qq
    return cost


@njit(cache=True, nogil=True)
def offset_lsq(g: np.ndarray, n: int, i0: int, clipped: np.ndarray, start: float,
               sigma0: float, work: np.ndarray) -> float:
    """Least-squares Gaussian A exp(-(i-mu)^2 / 2 s^2) over the unclipped samples.

    Gauss-Newton from offset `start` and width `sigma0`, each step halved until the cost
    falls, until the full step would move mu by less than 1e-3 px. Returns mu - i0, NaN with too few
    samples on either side. work: scratch of 18 floats.
    """
    used = 0
    left = False
    right = False
    for i in range(n):
        if not clipped[i]:
            used += 1
            left = left or i < i0 + start
            right = right or i > i0 + start
    if used < 4 or not (left and right):
        return np.nan
    mu = i0 + start
    # the amplitude that fits best at this centre, for each of a few widths: a clipped top
    # hides both, and a poor start stalls the fit
    amp, sig, best = 0.0, sigma0, np.inf
    for scale in (0.6, 0.8, 1.0, 1.25):
        trial_sig = sigma0 * scale
        num = 0.0
        den = 0.0
        for i in range(n):
            if not clipped[i]:
                e = math.exp(-0.5 * ((i - mu) / trial_sig) ** 2)
                num += g[i] * e
                den += e * e
        trial_amp = num / den if den > 0.0 else 0.0
        cost = _gaussian_sums(g, n, clipped, trial_amp, mu, trial_sig, work[:9])
        if trial_amp > 0.0 and cost < best:
            amp, sig, best = trial_amp, trial_sig, cost
    if not amp > 0.0:
        return np.nan
    normal = work[:9]
    trial = work[9:18]
    cost = _gaussian_sums(g, n, clipped, amp, mu, sig, normal)
    for _ in range(20):
        a11, a12, a13, a22, a23, a33, b1, b2, b3 = normal
        c1 = a22 * a33 - a23 * a23
        c2 = a12 * a33 - a23 * a13
        c3 = a12 * a23 - a22 * a13
        det = a11 * c1 - a12 * c2 + a13 * c3
        if not abs(det) > 0.0:
            return np.nan
        da = (b1 * c1 - a12 * (b2 * a33 - a23 * b3) + a13 * (b2 * a23 - a22 * b3)) / det
        dm = (a11 * (b2 * a33 - a23 * b3) - b1 * c2 + a13 * (a12 * b3 - b2 * a13)) / det
        ds = (a11 * (a22 * b3 - b2 * a23) - a12 * (a12 * b3 - b2 * a13) + b1 * c3) / det
        step = 1.0
        accepted = False
        for _ in range(10):
            na, nm, ns = amp + step * da, mu + step * dm, sig + step * ds
            if ns > 0.3 and abs(nm - i0) < 3.0:
                new_cost = _gaussian_sums(g, n, clipped, na, nm, ns, trial)
                if new_cost <= cost:
                    amp, mu, sig, cost = na, nm, ns, new_cost
                    normal[:] = trial
                    accepted = True
                    break
            step *= 0.5
        if not accepted or abs(dm) < 1e-3:
            break
    return mu - i0


@njit(cache=True, nogil=True, inline="always")
def peak_offset(g: np.ndarray, n: int, i0: int, clipped: np.ndarray, estimator: int,
                half: int, work: np.ndarray) -> float:
    """Subpixel offset of the peak of g[:n] from i0 with one estimator (NaN on failure);
    work: scratch for the Gaussian fit (18 floats).

    With two or more clipped samples the flat top carries no position: the Gaussian fit
    uses the unclipped flanks and the other estimators the half-height edges.
    """
    if estimator == EST_MAX:
        return 0.0
    n_clipped = 0
    for i in range(n):
        n_clipped += clipped[i]
    if n_clipped >= 2 and estimator != EST_LSQ:
        return offset_edges(g, n, i0)
    if estimator == EST_GAUSS3:
        return offset_gauss3(g, n, i0)
    if estimator == EST_BLAIS_RIOUX:
        return offset_blais_rioux(g, n, i0)
    if estimator == EST_COM:
        return offset_com(g, n, i0, half)
    start = offset_edges(g, n, i0) if n_clipped >= 2 else offset_gauss3(g, n, i0)
    if not math.isfinite(start):
        start = offset_com(g, n, i0, half)
    if not math.isfinite(start):
        return np.nan
    width = half_max_width(g, n, i0)
    sigma0 = width / 2.3548 if math.isfinite(width) and width > 0.7 else 1.5
    return offset_lsq(g, n, i0, clipped, start, sigma0, work)


@njit(cache=True, nogil=True, inline="always")
def _gather(flat: np.ndarray, e: np.ndarray, pad: int, line: int, base: int, pos_stride: int,
            channel: int, first: int, n: int, out: np.ndarray) -> None:
    """Fit-channel values of positions first .. first+n-1 of a line into out[:n]."""
    if channel == 0:
        for k in range(n):
            out[k] = flat[3 * (base + (first + k) * pos_stride) + 2]
    elif channel == 1:
        for k in range(n):
            i = 3 * (base + (first + k) * pos_stride)
            out[k] = 0.114 * flat[i] + 0.587 * flat[i + 1] + 0.299 * flat[i + 2]
    else:
        for k in range(n):
            out[k] = e[pad + first + k, line]


SMOOTH = np.exp(-0.5 * (np.arange(-3, 4) / 1.0) ** 2)  # Gaussian, sigma 1.0 px


@njit(cache=True, nogil=True, inline="always")
def smooth_profile(vals: np.ndarray, n: int, lo: int, hi: int, out: np.ndarray) -> None:
    """out[lo:hi] = vals[:n] convolved with SMOOTH there (renormalised where cut by the
    ends); the fit reads only the positions around the peak, a third of the buffer.

    Pixel-scale noise (sensor, laser speckle, MJPG blocks) moves the subpixel estimators,
    most of all the samples at the top that set the centroid's level; a symmetric kernel
    leaves a symmetric peak where it is. Inside the line the taps are fixed and their sum
    is added in the same order as at the ends, so each value is the same to the bit."""
    r = SMOOTH.size // 2
    total = 0.0
    for k in range(SMOOTH.size):
        total += SMOOTH[k]
    for i in range(lo, hi):
        acc = 0.0
        if r <= i < n - r:
            for k in range(SMOOTH.size):
                acc += SMOOTH[k] * vals[i - r + k]
            out[i] = acc / total
            continue
        wsum = 0.0
        for k in range(max(0, i - r), min(n, i + r + 1)):
            w = SMOOTH[k - i + r]
            acc += w * vals[k]
            wsum += w
        out[i] = acc / wsum


@njit(cache=True, nogil=True, inline="always")
def _background(vals: np.ndarray, n: int, k0: int, offset: int, side: int) -> float:
    """The lower of the two side means around k0 (a side cut by the line end is skipped)."""
    below, above = _side_means(vals, n, k0, offset, side)
    return min(below, above)


@njit(cache=True, nogil=True, inline="always")
def _side_means(vals: np.ndarray, n: int, k0: int, offset: int, side: int
                ) -> tuple[float, float]:
    """The means of the `side` samples from `offset` on below and above k0 (a side cut by
    the line end takes the other's; both 0 when both are)."""
    lo_sum = 0.0
    hi_sum = 0.0
    lo_n = 0
    hi_n = 0
    for j in range(offset, offset + side):
        if k0 - j >= 0:
            lo_sum += vals[k0 - j]
            lo_n += 1
        if k0 + j < n:
            hi_sum += vals[k0 + j]
            hi_n += 1
    if lo_n == 0 and hi_n == 0:
        return 0.0, 0.0
    if lo_n == 0:
        return hi_sum / hi_n, hi_sum / hi_n
    if hi_n == 0:
        return lo_sum / lo_n, lo_sum / lo_n
    return lo_sum / lo_n, hi_sum / hi_n


@njit(cache=True, nogil=True)
def _core_whitens(flat: np.ndarray, base: int, pos_stride: int, n_pos: int, lo: int,
                  hi: int, x0: int, reach: int, rise: float) -> bool:
    """Whether green or blue rise more than `rise` over positions lo..hi-1 of a line above
    their level `reach` either side of x0: the stripe's core turns white (a bright stripe
    on the sensor), where the evidence, red minus the stronger of green and blue, dips."""
    core = 0.0
    for x in range(lo, hi):
        i = 3 * (base + x * pos_stride)
        core = max(core, float(max(flat[i], flat[i + 1])))
    sides = 0.0
    for x in (x0 - reach, x0 + reach):
        if 0 <= x < n_pos:
            i = 3 * (base + x * pos_stride)
            sides = max(sides, float(max(flat[i], flat[i + 1])))
    return core > sides + rise


@njit(cache=True, nogil=True, inline="always")
def _integer_peak(vals: np.ndarray, n: int, c: int, m: int, sat: float) -> int:
    """The highest sample within m-1 of c, or the middle of its clipped plateau (which may
    be wider than the ridge window)."""
    k0 = c
    for k in range(max(0, c - m + 1), min(n, c + m)):
        if vals[k] > vals[k0]:
            k0 = k
    if vals[k0] >= sat:
        a = k0
        b = k0
        while a > 0 and vals[a - 1] >= sat:
            a -= 1
        while b < n - 1 and vals[b + 1] >= sat:
            b += 1
        k0 = (a + b) // 2
    return k0


ACROSS_BEND = 0.25  # px: how far a line's peak may lie off the chord of its neighbours'
ACROSS_RATIO = 1.5  # how much brighter or dimmer than the line a neighbour's peak may be


@njit(cache=True, nogil=True, inline="always")
def _quick_peak(vals: np.ndarray, n: int, k0: int, m: int) -> tuple[float, float]:
    """(position, height) of a line's peak near k0, quickly: the vertex of the parabola
    through the highest sample within m of k0 and its two neighbours (that sample itself
    at a line end or a flat top), and how far that sample stands above the lowest there."""
    j = k0
    low = vals[k0]
    for k in range(max(0, k0 - m), min(n, k0 + m + 1)):
        if vals[k] > vals[j]:
            j = k
        low = min(low, vals[k])
    height = vals[j] - low
    if j == 0 or j == n - 1:
        return float(j), height
    curvature = vals[j - 1] - 2.0 * vals[j] + vals[j + 1]
    if curvature >= 0.0:
        return float(j), height
    return j + 0.5 * (vals[j - 1] - vals[j + 1]) / curvature, height


@njit(cache=True, nogil=True, inline="always")
def _blend_across_lines(flat: np.ndarray, e: np.ndarray, pad: int, line: int, n_lines: int,
                        base: int, line_stride: int, pos_stride: int, channel: int,
                        first: int, n: int, k0: int, m: int, vals: np.ndarray,
                        before: np.ndarray, after: np.ndarray) -> None:
    """vals[:n] = (before + 2 vals + after) / 4: the line's samples smoothed across the
    stripe with its two neighbouring lines at the same positions, where the stripe runs
    straight and evenly through the three: the line's quick peak (`_quick_peak`) lies
    within ACROSS_BEND px of the mean of its neighbours', whose heights are within
    ACROSS_RATIO of its own.

    The stripe on a surface is continuous, so its neighbours carry nearly the same centre,
    while sensor noise and the scene's texture (a chessboard square's edge under the
    stripe) move each line's centroid on its own. The weights are symmetric, so a slanted
    straight stripe keeps its centre; both neighbours or neither (one alone would pull a
    slanted stripe towards it); neither where the stripe bends or jumps (a depth edge),
    which the blend would blur, nor where it brightens or dims (a reflectance edge across
    it), where the brighter neighbour would pull the centre towards its own."""
    if line < 1 or line >= n_lines - 1:
        return
    _gather(flat, e, pad, line - 1, base - line_stride, pos_stride, channel, first, n, before)
    _gather(flat, e, pad, line + 1, base + line_stride, pos_stride, channel, first, n, after)
    at, height = _quick_peak(vals, n, k0, m)
    at_before, height_before = _quick_peak(before, n, k0, m)
    at_after, height_after = _quick_peak(after, n, k0, m)
    if abs(at - 0.5 * (at_before + at_after)) > ACROSS_BEND \
            or max(height_before, height_after) > ACROSS_RATIO * height \
            or min(height_before, height_after) * ACROSS_RATIO < height:
        return
    for k in range(n):
        vals[k] = 0.25 * (before[k] + 2.0 * vals[k] + after[k])


@njit(cache=True, nogil=True)
def fit_kernel(flat: np.ndarray, e: np.ndarray, pad: int, n_pos: int, line_stride: int,
               pos_stride: int, lines: np.ndarray, best: np.ndarray, best_pos: np.ndarray,
               count: np.ndarray, thr: int, scale: float, m: int, offset: int, side: int,
               half: int, estimator: int, channel: int, sat: float, red_min: float,
               peak: np.ndarray, strength: np.ndarray, width: np.ndarray,
               contrast: np.ndarray, flags: np.ndarray) -> None:
    """Subpixel peak and quality figures for the image lines `lines` (see
    `laser.extract_stripe`), whose ridge results are best[k], best_pos[k] and count[k] for
    line lines[k]: the estimator runs on the fit channel smoothed across the stripe with
    the neighbouring lines where the core is not clipped (`_blend_across_lines`), then
    along the line (`smooth_profile`); strength and width are of the samples before the
    smoothing along the line.

    A white clipped peak needs a flank with a red excess of at least red_min; fitting on
    red, a core clipped in green or blue too is located on luma instead.
    """
    reach = max(offset + side, half) + m
    vals = np.empty(2 * reach + 1)
    wide = np.empty(2 * CLIP_REACH + 1)
    smooth = np.empty(2 * reach + 1)
    g = np.empty(2 * half + 1)
    g_raw = np.empty(2 * half + 1)
    clipped = np.zeros(2 * half + 1, np.bool_)
    work = np.empty(18)
    before = np.empty(2 * reach + 1)
    after = np.empty(2 * reach + 1)
    n_lines = flat.size // (3 * n_pos)
    for k in range(lines.size):
        line = lines[k]
        contrast[line] = best[k] * scale
        if best[k] < thr or best_pos[k] < 0:
            flags[line] |= NONE_FOUND
            continue
        if count[k] >= 2:
            flags[line] |= MULTIPLE
        first = max(0, best_pos[k] - reach)
        n_buf = min(n_pos, best_pos[k] + reach + 1) - first
        base = line * line_stride
        fit_channel = channel
        _gather(flat, e, pad, line, base, pos_stride, channel, first, n_buf, vals)
        k0 = _integer_peak(vals, n_buf, best_pos[k] - first, m, sat)
        centre = 3 * (base + (first + k0) * pos_stride)
        if flat[centre + 2] < sat:
            _blend_across_lines(flat, e, pad, line, n_lines, base, line_stride, pos_stride,
                                fit_channel, first, n_buf, k0, m, vals, before, after)
            k0 = _integer_peak(vals, n_buf, k0, m, sat)
            centre = 3 * (base + (first + k0) * pos_stride)
        if flat[centre + 2] >= sat:
            flags[line] |= SATURATED
            if max(flat[centre], flat[centre + 1]) > WHITE_CAP:
                if not _red_flank(flat, base, pos_stride, n_pos, first + k0, offset + side,
                                  sat, red_min):
                    flags[line] |= NOT_RED
                    continue
                if channel == 0 and max(flat[centre], flat[centre + 1]) >= sat:
                    # a clipped white core: the red is flat over a wider band whose edges
                    # lie on the scene's red; green and blue (luma) draw the core
                    fit_channel = 1
                    _gather(flat, e, pad, line, base, pos_stride, 1, first, n_buf, vals)
                    k0 = _integer_peak(vals, n_buf, k0, m, sat)
        bg_raw = _background(vals, n_buf, k0, offset, side)
        w0 = max(0, k0 - half)
        n_win = min(n_buf, k0 + half + 1) - w0
        if n_win < 2 * half + 1:
            flags[line] |= AT_EDGE
        n_clipped = 0
        for k in range(n_win):
            g_raw[k] = vals[w0 + k] - bg_raw
            clipped[k] = vals[w0 + k] >= sat
            n_clipped += clipped[k]
        if n_clipped >= 2:  # the flat top's half-height edges: smoothing adds nothing
            d = peak_offset(g_raw, n_win, k0 - w0, clipped, estimator, half, work)
            if not math.isfinite(d) and vals[k0] >= sat:  # a core wider than the window
                x0 = first + k0
                w_first = max(0, x0 - CLIP_REACH)
                n_wide = min(n_pos, x0 + CLIP_REACH + 1) - w_first
                _gather(flat, e, pad, line, base, pos_stride, fit_channel, w_first, n_wide,
                        wide)
                d = clipped_centre(wide, n_wide, x0 - w_first, sat)
        else:
            below, above = _side_means(vals, n_buf, k0, offset, side)
            if fit_channel != EVIDENCE \
                    and abs(above - below) > BACKGROUND_STEP * g_raw[k0 - w0] \
                    and not _core_whitens(flat, base, pos_stride, n_pos,
                                          first + max(0, k0 - half),
                                          first + min(n_buf, k0 + half + 1), first + k0,
                                          offset + side - 1, CORE_RISE * g_raw[k0 - w0]):
                # the scene steps from bright to dark under the stripe (a black surface's
                # edge beside it): the fit channel's bright side stood above the dark
                # side's level and pulled the centroid up to 2 px towards it (8 cm along
                # a floor 2 m off); the evidence holds the laser's light alone
                _gather(flat, e, pad, line, base, pos_stride, EVIDENCE, first, n_buf, vals)
            reach_fit = max(offset + side - 1, half)  # what _background and g read
            smooth_profile(vals, n_buf, max(0, k0 - reach_fit),
                           min(n_buf, k0 + reach_fit + 1), smooth)
            bg = _background(smooth, n_buf, k0, offset, side)
            for k in range(n_win):
                g[k] = smooth[w0 + k] - bg
            d = peak_offset(g, n_win, k0 - w0, clipped, estimator, half, work)
        if not math.isfinite(d) or abs(d) > half:
            d = 0.0
            flags[line] |= FIT_FAILED
        peak[line] = first + k0 + d
        strength[line] = g_raw[k0 - w0]
        width[line] = half_max_width(g_raw, n_win, k0 - w0)


@njit(cache=True, nogil=True)
def _red_flank(flat: np.ndarray, base: int, pos_stride: int, n_pos: int, x0: int, reach: int,
               sat: float, level: float) -> bool:
    """True if, beside the white core at x0, one of the first two pixels on either side
    within `reach` whose green and blue are not clipped has a red excess r - max(g, b) of
    at least `level`."""
    for direction in (-1, 1):
        x = x0 + direction
        seen = 0
        while 0 <= x < n_pos and abs(x - x0) <= reach and seen < 2:
            i = 3 * (base + x * pos_stride)
            other = max(flat[i], flat[i + 1])
            if other < sat:
                if float(flat[i + 2]) - other >= level:
                    return True
                seen += 1
            x += direction
    return False


@njit(cache=True, nogil=True)
def wide_lines(peak: np.ndarray, width: np.ndarray, flags: np.ndarray, e: np.ndarray,
               pad: int, n_pos: int, widths: np.ndarray, step: int, sign_width: float,
               sign_level: float, reach: int, lo: int, hi: int) -> np.ndarray:
    """The lines lo..hi-1 where nothing was found (flags NONE_FOUND alone) that lie within
    `reach` lines of a sign of a wide stripe: a found peak wider than `sign_width`, or a
    sampled line (every `step`-th; `widths` from `evidence_widths`) whose strongest
    evidence is that wide and reaches `sign_level` (not the scene's weaker colours)."""
    n = peak.size
    sign = np.zeros(n + 1, np.int64)  # prefix counts of the signs
    for line in range(n):
        wide = math.isfinite(peak[line]) and width[line] > sign_width
        if not wide and line % step == 0 and widths[line // step] > sign_width:
            top = e[pad, line]
            for x in range(pad + 1, pad + n_pos):
                top = max(top, e[x, line])
            wide = top >= sign_level
        sign[line + 1] = sign[line] + (1 if wide else 0)
    out = np.empty(hi - lo, np.int64)
    count = 0
    for line in range(lo, hi):
        if flags[line] == NONE_FOUND \
                and sign[min(line + reach + 1, n)] > sign[max(line - reach, 0)]:
            out[count] = line
            count += 1
    return out[:count]


@njit(cache=True, nogil=True)
def gather_lines(e: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """The columns `lines` of the evidence plane, contiguous (positions + pad, len(lines))."""
    out = np.empty((e.shape[0], lines.size), e.dtype)
    for x in range(e.shape[0]):
        for k in range(lines.size):
            out[x, k] = e[x, lines[k]]
    return out


@njit(cache=True, nogil=True)
def keep_continued(peak: np.ndarray, contrast: np.ndarray, flags: np.ndarray, lo: int, hi: int,
                   thr: float, max_jump: float) -> None:
    """Hysteresis along the stripe: a peak of lines lo..hi-1 whose contrast is below `thr`
    is kept only if a run of peaks on consecutive lines, each within max_jump of the
    last, links it to a peak at or above `thr`; the others are removed (NONE_FOUND). A
    stripe fading on a dark or oblique surface stays continuous; weak ridges elsewhere
    do not pass."""
    linked = np.zeros(hi - lo, np.bool_)
    for i in range(lo, hi):
        linked[i - lo] = math.isfinite(peak[i]) and contrast[i] >= thr
    for i in range(lo + 1, hi):
        linked[i - lo] |= (linked[i - 1 - lo] and math.isfinite(peak[i])
                           and abs(peak[i] - peak[i - 1]) <= max_jump)
    for i in range(hi - 2, lo - 1, -1):
        linked[i - lo] |= (linked[i + 1 - lo] and math.isfinite(peak[i])
                           and abs(peak[i] - peak[i + 1]) <= max_jump)
    for i in range(lo, hi):
        if math.isfinite(peak[i]) and not linked[i - lo]:
            peak[i] = np.nan
            flags[i] = NONE_FOUND


@njit(cache=True, nogil=True)
def drop_isolated(peak: np.ndarray, flags: np.ndarray, lo: int, hi: int, support: int,
                  max_jump: float) -> None:
    """NaN (and flag ISOLATED) the peaks of lines lo..hi-1 that lack `support` neighbours.

    A neighbour is a peak on one of the `support` lines either side whose position is
    within max_jump per line of separation: the stripe is continuous across lines, camera
    noise is not. Counting neighbours rather than unbroken runs keeps two stripes whose
    best peaks alternate from line to line.
    """
    keep = np.zeros(hi - lo, np.bool_)
    for i in range(lo, hi):
        if not math.isfinite(peak[i]):
            continue
        count = 0
        for j in range(max(lo, i - support), min(hi, i + support + 1)):
            if j != i and abs(peak[j] - peak[i]) <= max_jump * abs(j - i):
                count += 1
        keep[i - lo] = count >= support
    for i in range(lo, hi):
        if math.isfinite(peak[i]) and not keep[i - lo]:
            peak[i] = np.nan
            flags[i] |= ISOLATED


@njit(cache=True, nogil=True)
def colour_beside(image: np.ndarray, u: np.ndarray, v: np.ndarray, offset: float,
                  out: np.ndarray) -> None:
    """RGB of the pixel `offset` px either side of each peak (u, v) along its column, rows
    clipped to the image: the side with the smaller red excess r - max(b, g) (the first
    on a tie), into out (n, 3) uint8."""
    height = image.shape[0]
    for i in range(u.shape[0]):
        col = int(u[i])
        best = 0
        for side in range(2):
            row = min(max(int(np.rint(v[i] + (2 * side - 1) * offset)), 0), height - 1)
            b, g, r = np.int64(image[row, col, 0]), np.int64(image[row, col, 1]), \
                np.int64(image[row, col, 2])
            excess = r - max(b, g)
            if side == 0 or excess < best:
                best = excess
                out[i, 0], out[i, 1], out[i, 2] = r, g, b
