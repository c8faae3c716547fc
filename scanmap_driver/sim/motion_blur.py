"""Motion blur (and rolling shutter) from the head's rotation during the exposure.

While the shutter is open the head turns by a few tenths of a degree to a few degrees, and
everything fixed in `map` or `base_link` sweeps across the image, mostly along the image
rows (v). `rotation_flow` gives each pixel's image motion per radian of heading, from the
3D point it sees (the camera sits off the axis, so near points move differently from far
ones). `blur_along_flow` averages each pixel over its path: the path is integrated exactly along
v with prefix sums (no ghosting however long the path), then shifted along u by its mean
drift. Rolling shutter is the same operation with heading offsets that differ per row.
"""

from __future__ import annotations

import cv2
import numpy as np
from numba import njit

MAX_DEPTH = 1e4  # m: rays that hit nothing move like points this far away
MIN_SWEEP = 0.25  # px: shorter paths are sampled, not integrated (float32 prefix sums)


@njit(cache=True, nogil=True)
def rotation_flow(t: np.ndarray, directions: np.ndarray, centre: np.ndarray,
                  rotation_head_camera: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """(H, W, 2) float32 image motion (du, dv) per radian of heading for the seen points.

    t: (H, W) distances along the unit `head` rays `directions` from the camera `centre`.
    A point fixed outside the head moves in `head` by (y, -x, 0) per radian of heading;
    the pinhole projection's derivative turns that into pixels (distortion neglected).
    """
    height, width = t.shape
    out = np.empty((height, width, 2), dtype=np.float32)
    r = rotation_head_camera
    for row in range(height):
        for col in range(width):
            depth = min(t[row, col], MAX_DEPTH)
            # the point relative to the camera, and in `head`
            px = depth * directions[row, col, 0]
            py = depth * directions[row, col, 1]
            pz = depth * directions[row, col, 2]
            x, y = centre[0] + px, centre[1] + py
            # camera coordinates of the point and of its motion (R^T v)
            cx = r[0, 0] * px + r[1, 0] * py + r[2, 0] * pz
            cy = r[0, 1] * px + r[1, 1] * py + r[2, 1] * pz
            cz = r[0, 2] * px + r[1, 2] * py + r[2, 2] * pz
            mx = r[0, 0] * y - r[1, 0] * x
            my = r[0, 1] * y - r[1, 1] * x
            mz = r[0, 2] * y - r[1, 2] * x
            out[row, col, 0] = fx * (mx * cz - cx * mz) / (cz * cz)
            out[row, col, 1] = fy * (my * cz - cy * mz) / (cz * cz)
    return out


@njit(cache=True, nogil=True)
def box_along_rows(image: np.ndarray, flow_v: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Average each pixel of `image` (H, W, C) over its path along v during the exposure.

    flow_v: (H, W) dv per radian; offsets: (H, K + 1) heading offsets (rad, relative to
    the rendered heading) at the K + 1 boundaries of the exposure's sub-intervals of equal
    time, per image row (rows differ under a rolling shutter). A pixel p sees at offset o
    what the rendered image shows at p - flow(p) * o. Rows are piecewise constant; beyond
    the image the edge row continues. Paths shorter than MIN_SWEEP are sampled at their
    middle.
    """
    height, width, channels = image.shape
    # prefix[r, col, c]: integral of the column from -0.5 to r - 0.5.
    prefix = np.zeros((height + 1, width, channels), dtype=np.float32)
    for row in range(height):
        for col in range(width):
            for c in range(channels):
                prefix[row + 1, col, c] = prefix[row, col, c] + image[row, col, c]
    parts = offsets.shape[1] - 1
    share = 1.0 / parts
    out = np.zeros_like(image)
    for row in range(height):
        for col in range(width):
            dv = flow_v[row, col]
            for k in range(parts):
                v0, v1 = row - dv * offsets[row, k], row - dv * offsets[row, k + 1]
                lo, hi = min(v0, v1), max(v0, v1)
                if hi - lo > MIN_SWEEP:
                    i_lo = min(max(int(np.floor(lo + 0.5)), 0), height - 1)
                    i_hi = min(max(int(np.floor(hi + 0.5)), 0), height - 1)
                    f_lo = lo + 0.5 - i_lo
                    f_hi = hi + 0.5 - i_hi
                    scale = share / (hi - lo)
                    for c in range(channels):
                        out[row, col, c] += scale * (
                            prefix[i_hi, col, c] + f_hi * image[i_hi, col, c]
                            - prefix[i_lo, col, c] - f_lo * image[i_lo, col, c])
                else:
                    i = min(max(int(np.floor(0.5 * (lo + hi) + 0.5)), 0), height - 1)
                    for c in range(channels):
                        out[row, col, c] += share * image[i, col, c]
    return out


def blur_along_flow(image: np.ndarray, flow: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Average each pixel of `image` (H, W, C) over its path during the exposure.

    flow: (H, W, 2) (du, dv) per radian; offsets as for `box_along_rows`. The path is
    integrated along v (`box_along_rows`), then shifted along u by its mean u offset
    (bilinear, edge columns continue): the u drift along one exposure's path is a few
    pixels at most.
    """
    blurred = box_along_rows(image, np.ascontiguousarray(flow[:, :, 1]), offsets)
    middle = offsets.mean(axis=1, dtype=np.float64)
    shift = flow[:, :, 0] * middle[:, None].astype(np.float32)
    if np.abs(shift).max(initial=0.0) < 1e-3:
        return blurred
    height, width = shift.shape
    map_u = np.arange(width, dtype=np.float32)[None, :] - shift
    map_v = np.repeat(np.arange(height, dtype=np.float32)[:, None], width, axis=1)
    channels = [cv2.remap(np.ascontiguousarray(blurred[:, :, c]), map_u, map_v,
                          cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                for c in range(blurred.shape[2])]
    return np.stack(channels, axis=-1)
