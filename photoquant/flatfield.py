"""Sensor non-uniformity (PRNU) look-up table from the irradiance scene, §5.4.

With the optics removed, every cell of the sensor receives (nearly) the same
irradiance; the linearised, colour-balanced image of this "irradiance scene",
normalised to a mean of 1 per channel, is the per-pixel sensitivity ``u_pλ``.

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, §5.4.
.. [EMVA1288] EMVA Standard 1288, Release 4.0 (2021): photo response
   non-uniformity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoquant._checks import check_array
from photoquant.errors import CalibrationError

__all__ = ["SensorLUT", "sensor_lut_IrradianceScene"]


@dataclass(frozen=True, eq=False)
class SensorLUT:
    """A sensor non-uniformity LUT.

    Attributes
    ----------
    lut : ndarray, shape (H, W, C), float32
        ``u_pλ``, mean 1 per channel over valid pixels; 1 at flagged pixels.
    n_flagged : int
        Pixel-channels without a valid exposure in the irradiance scene.
    prnu_std : ndarray, shape (C,)
        Standard deviation of ``u`` per channel (the measured PRNU).
    """

    lut: np.ndarray
    n_flagged: int
    prnu_std: np.ndarray


def sensor_lut_IrradianceScene(
    linear: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    max_flagged_fraction: float = 0.01,
) -> SensorLUT:
    """Sensor LUT from the linearised irradiance scene (§5.4 of [PQ]_).

    Parameters
    ----------
    linear : ndarray, shape (H, W, C)
        Linearised photoquantity of the optics-free, uniformly lit sensor.
    mask : ndarray, shape (H, W, C) of bool, optional
        Pixels without a valid exposure; they get ``u = 1``.
    max_flagged_fraction : float
        Raise :class:`CalibrationError` when more than this fraction of the
        pixels is flagged: the irradiance scene was badly exposed.

    Returns
    -------
    SensorLUT
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    bad = ~np.isfinite(linear) | (linear <= 0)
    if mask is not None:
        bad |= check_array(mask, "mask", shape=linear.shape, kind="b")
    fraction = bad.mean()
    if fraction > max_flagged_fraction:
        raise CalibrationError(
            f"{100 * fraction:.2f} % of the irradiance scene has no valid exposure "
            f"(at most {100 * max_flagged_fraction:.2f} % allowed): re-capture it with "
            "exposure times that keep the sensor between dark and saturated"
        )
    n_ch = linear.shape[2]
    lut = np.ones(linear.shape, dtype=np.float64)
    std = np.zeros(n_ch)
    for ch in range(n_ch):
        ok = ~bad[..., ch]
        values = linear[..., ch][ok]
        u = values / values.mean()
        lut[..., ch][ok] = u
        std[ch] = u.std()
    return SensorLUT(lut=lut.astype(np.float32), n_flagged=int(bad.sum()), prnu_std=std)
