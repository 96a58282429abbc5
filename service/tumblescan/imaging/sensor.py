"""Turning radiance into a recorded image: sky gradient, stars, PSF, shot and read noise, quantization."""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray, IntArray


class SensorModel(BaseModel):
    """What the detector adds. ``electrons_full`` is the signal (e-) of radiance 1; DN = e- / ``electrons_per_dn``."""

    model_config = ConfigDict(extra="forbid")

    bits: int = Field(8, description="8 or 16")
    electrons_full: float = Field(8000.0, gt=0)
    electrons_per_dn: float = Field(40.0, gt=0)
    psf_sigma_px: float = Field(0.6, ge=0)
    read_noise_dn: float = Field(1.5, ge=0)
    sky_dn: float = Field(6.0, ge=0, description="mean sky level")
    sky_gradient_dn: float = Field(3.0, ge=0, description="sky change across the image")
    stars: int = Field(8, ge=0)
    noise: bool = True


def expose(radiance: FloatArray, sensor: SensorModel, rng: np.random.Generator) -> IntArray:
    """The recorded image (uint8 or uint16) of a radiance map (H, W).

    Order: stars and the radiance are blurred by a Gaussian PSF, the sky gradient is added, then
    Poisson shot noise on electrons, Gaussian read noise in DN, and rounding/clipping to ``bits``.
    Without ``noise`` only the blur, sky and quantization are applied.
    """
    import cv2

    H, W = radiance.shape
    e = np.asarray(radiance, dtype=float) * sensor.electrons_full
    for _ in range(sensor.stars):
        u, v = rng.uniform(0, W - 1), rng.uniform(0, H - 1)
        if e[int(v), int(u)] == 0:  # stars behind the target are hidden
            e[int(v), int(u)] += rng.uniform(0.2, 1.5) * sensor.electrons_full
    if sensor.psf_sigma_px > 0:
        e = np.asarray(cv2.GaussianBlur(e, (0, 0), sensor.psf_sigma_px, borderType=cv2.BORDER_REFLECT), dtype=float)
    angle = rng.uniform(0, 2 * np.pi)
    yy, xx = np.mgrid[0:H, 0:W]
    ramp = ((xx - W / 2) * np.cos(angle) + (yy - H / 2) * np.sin(angle)) / max(H, W)
    e += (sensor.sky_dn + sensor.sky_gradient_dn * ramp) * sensor.electrons_per_dn
    e = np.maximum(e, 0.0)
    if sensor.noise:
        e = rng.poisson(e).astype(float)
    dn = e / sensor.electrons_per_dn
    if sensor.noise:
        dn += rng.normal(0.0, sensor.read_noise_dn, dn.shape)
    top = 255 if sensor.bits == 8 else 65535
    out = np.clip(np.rint(dn), 0, top)
    return out.astype(np.uint8 if sensor.bits == 8 else np.uint16)
