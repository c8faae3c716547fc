"""The webcam between the light and the bytes: exposure, gain, sensor noise, colour filter
mosaic, saturation, gamma and MJPG compression with chroma subsampling.

Radiance arrives in linear units where 1.0 fills the pixels at the reference exposure and
unit gain. The sensor counts electrons behind an RGGB colour filter mosaic (shot noise,
read noise), clips at full well, and the camera demosaics, applies the sRGB curve, rounds
to 8 bits and compresses to JPEG with 4:2:2 chroma, as a webcam's MJPG stream delivers
(the paper turned contrast enhancement and sharpening off, so neither is modelled).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import RecordingError

_SAMPLING = {
    "444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444,
    "422": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
    "420": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
}


@dataclass(frozen=True)
class SimCameraConfig:
    """Exposure and sensor of the simulated webcam.

    exposure: shutter time (s); the paper fixes a low exposure so the laser saturates less.
    gain: analogue gain. reference_exposure: the exposure at which radiance 1 fills a pixel.
    full_well, read_noise: electrons at full scale and read noise (electrons).
    rolling_shutter: time (s) from reading the first image row to the last; 0 = global.
    aperture, focus_distance: lens opening (m) and focus (m) for defocus blur.
    """

    exposure: float = 0.008
    gain: float = 1.0
    reference_exposure: float = 0.008
    full_well: float = 6000.0
    read_noise: float = 5.0
    jpeg_quality: int = 85
    chroma: str = "422"
    rolling_shutter: float = 0.0
    aperture: float = 0.0015
    focus_distance: float = 4.0

    def __post_init__(self) -> None:
        if self.chroma not in _SAMPLING:
            raise ValueError(f"chroma: expected one of {sorted(_SAMPLING)}, got {self.chroma!r}")

    @property
    def scale(self) -> float:
        """Full-scale fraction per unit radiance at this exposure and gain."""
        return self.exposure / self.reference_exposure * self.gain


def _srgb_table() -> np.ndarray:
    """uint8 sRGB encoding of every 16-bit linear value."""
    x = np.arange(65536) / 65535.0
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(255.0 * encoded).astype(np.uint8)


SRGB = _srgb_table()


def mosaic(rgb: np.ndarray) -> np.ndarray:
    """(H, W) samples of an RGGB colour filter array from an (H, W, 3) RGB image."""
    out = np.empty(rgb.shape[:2], dtype=rgb.dtype)
    out[0::2, 0::2] = rgb[0::2, 0::2, 0]
    out[0::2, 1::2] = rgb[0::2, 1::2, 1]
    out[1::2, 0::2] = rgb[1::2, 0::2, 1]
    out[1::2, 1::2] = rgb[1::2, 1::2, 2]
    return out


def expose(radiance: np.ndarray, settings: SimCameraConfig,
           rng: np.random.Generator) -> np.ndarray:
    """The 8-bit BGR image the camera makes of (H, W, 3) RGB radiance."""
    electrons = mosaic(radiance) * np.float32(settings.scale * settings.full_well)
    np.maximum(electrons, 0.0, out=electrons)
    noise = np.sqrt(electrons + np.float32(settings.read_noise ** 2))
    electrons += noise * rng.standard_normal(electrons.shape, dtype=np.float32)
    counts = np.clip(electrons * np.float32(65535.0 / settings.full_well), 0.0, 65535.0)
    # OpenCV names Bayer patterns by the second row's start: an RGGB sensor is "BayerBG".
    linear = cv2.cvtColor(np.round(counts).astype(np.uint16), cv2.COLOR_BayerBG2BGR)
    return np.take(SRGB, linear)


def encode_mjpg(image: np.ndarray, settings: SimCameraConfig) -> bytes:
    """The JPEG bytes of one MJPG frame, as the webcam sends them."""
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality,
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                            _SAMPLING[settings.chroma]])
    if not ok:
        raise RecordingError("OpenCV could not encode a JPEG frame")
    return data.tobytes()
