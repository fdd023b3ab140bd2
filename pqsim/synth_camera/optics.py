"""Spatial non-uniformity ground truths: vignetting of the optics and PRNU of the sensor.

Two multiplicative fields of eq. 1 of [PQ], written independently of the
calibrator (photoquant's vignetting module is *not* used here):

- ``v_pλ``, the vignetting of the optics (§3.2.1, §5.5 of [PQ]), either the
  extended Goldman–Chen polynomial the paper fits
  (:func:`vignetting_extended_goldman_chen`) or the natural ``cos⁴`` fall-off
  of a thin lens (:func:`vignetting_cos4`), a truth *outside* the fitted family;
- ``u_pλ``, the sensor's photo-response non-uniformity (PRNU, §3.2.1 and §5.4
  of [PQ]; EMVA 1288 §8), :func:`prnu_field`.

Coordinates follow the project convention: pixel ``(x, y)`` (x right, y down)
has normalised coordinates ``x_n = (x + 0.5) / W``, ``y_n = (y + 0.5) / H``.

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``: eq. 1, §5.5.
.. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration and
   compensation", ICCV 2005, doi:10.1109/ICCV.2005.249.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021), §8 (spatial non-uniformity,
   PRNU).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter

from photoquant.errors import InputError
from photoquant.utils import check_array, check_int, check_positive

__all__ = [
    "check_shape",
    "normalised_coordinates",
    "vignetting_extended_goldman_chen",
    "vignetting_cos4",
    "prnu_field",
]


def check_shape(shape: Any, name: str = "shape") -> tuple[int, int]:
    """Return an image shape ``(H, W)`` of two positive ints."""
    try:
        h, w = (int(s) for s in shape)
        ok = all(float(s) == int(s) for s in shape)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be (H, W), got {shape!r}") from None
    if not ok or h < 1 or w < 1:
        raise InputError(f"`{name}` must be two positive integers (H, W), got {shape!r}")
    return h, w


def normalised_coordinates(shape: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Normalised pixel-centre coordinates ``(x_n, y_n)``, each of shape ``(H, W)``.

    ``x_n = (x + 0.5) / W`` and ``y_n = (y + 0.5) / H``.
    """
    h, w = check_shape(shape)
    xn = (np.arange(w, dtype=np.float64) + 0.5) / w
    yn = (np.arange(h, dtype=np.float64) + 0.5) / h
    return np.broadcast_to(xn[None, :], (h, w)), np.broadcast_to(yn[:, None], (h, w))


def vignetting_extended_goldman_chen(params: Any, shape: Sequence[int]) -> np.ndarray:
    """Vignetting of the extended Goldman–Chen model (§5.5 of [PQ], after [GC05]).

    Parameters
    ----------
    params : array_like, shape (C, 6)
        Per channel ``m1..m6``: polynomial factors ``m1, m2, m3``, elliptical
        scale ``m4`` and centre ``(m5, m6)`` in normalised coordinates.
    shape : (H, W)
        Image shape.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``v = 1 + m1 R + m2 R² + m3 R³`` with
        ``R = m4 (x_n - m5)² + (y_n - m6)²``.

    Notes
    -----
    ``v = 1`` at the centre ``(m5, m6)``. The values are not clipped: a
    parameter set giving ``v <= 0`` somewhere is refused, since no optics
    transmits negative light.

    Examples
    --------
    >>> v = vignetting_extended_goldman_chen([[-0.3, 0, 0, 1, 0.5, 0.5]], (3, 3))
    >>> float(v[1, 1, 0]), round(float(v[0, 0, 0]), 6)
    (1.0, 0.933333)
    """
    p = check_array(params, "params", ndim=2, kind="iuf", finite=True).astype(np.float64)
    if p.shape[1] != 6:
        raise InputError(f"`params` must have shape (C, 6) (m1..m6 per channel), got {p.shape}")
    xn, yn = normalised_coordinates(shape)
    m1, m2, m3, m4, m5, m6 = (p[:, i] for i in range(6))
    r = m4 * (xn[..., None] - m5) ** 2 + (yn[..., None] - m6) ** 2
    v = 1.0 + r * (m1 + r * (m2 + r * m3))
    if np.any(v <= 0):
        raise InputError("`params` give non-positive vignetting inside the image")
    return v


def vignetting_cos4(
    shape: Sequence[int],
    focal_px: float,
    channels: int = 3,
    centre: tuple[float, float] | None = None,
) -> np.ndarray:
    """Natural vignetting of a thin lens, the ``cos⁴`` law.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    focal_px : float
        Focal length in pixels (positive).
    channels : int
        Number of (identical) channels ``C``.
    centre : (x, y), optional
        Optical centre in pixel coordinates; the image centre ``(W/2, H/2)`` by
        default (between pixels when a side is even).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``cos⁴ θ = (f² / (f² + r²))²``, ``r`` the distance of the pixel centre
        ``(x + 0.5, y + 0.5)`` to ``centre``; 1 at the centre.

    Notes
    -----
    Not a member of the Goldman–Chen family with three terms exactly (its
    series in ``r²`` is infinite), so it tests a calibrator on a truth outside
    its model.
    """
    h, w = check_shape(shape)
    f = check_positive(focal_px, "focal_px")
    channels = check_int(channels, "channels", 1)
    cx, cy = (w / 2.0, h / 2.0) if centre is None else (float(centre[0]), float(centre[1]))
    x = np.arange(w, dtype=np.float64) + 0.5 - cx
    y = np.arange(h, dtype=np.float64) + 0.5 - cy
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    v = (f * f / (f * f + r2)) ** 2
    return np.repeat(v[..., None], int(channels), axis=2)


def _unit(field: np.ndarray) -> np.ndarray:
    """Zero mean and unit standard deviation per channel (a constant field stays 0)."""
    field = field - field.mean(axis=(0, 1), keepdims=True)
    std = field.std(axis=(0, 1), keepdims=True)
    return np.divide(field, std, out=np.zeros_like(field), where=std > 0)


def prnu_field(
    shape: Sequence[int],
    channels: int,
    rng: np.random.Generator,
    sigma_pixel: float = 0.01,
    sigma_lowfreq: float = 0.02,
    lowfreq_scale: float = 0.15,
) -> np.ndarray:
    """Random sensor sensitivity ``u`` (PRNU): per-pixel noise plus a smooth component.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    channels : int
        Number of channels ``C``; each channel has its own field.
    rng : numpy.random.Generator
        Source of randomness: one ``(H, W, C)`` normal draw for the smooth
        component, then one for the per-pixel component.
    sigma_pixel : float
        Standard deviation of the per-pixel (white) component, in ``[0, 0.25]``.
    sigma_lowfreq : float
        Standard deviation of the smooth component, in ``[0, 0.25]``.
    lowfreq_scale : float
        Correlation length of the smooth component as a fraction of
        ``min(H, W)`` (Gaussian filter σ; at least 1 pixel).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``u = 1 + σ_lowfreq·L + σ_pixel·P`` where ``L`` (filtered white noise)
        and ``P`` (white noise) are each scaled to zero sample mean and unit
        sample standard deviation per channel. Hence the mean of each channel
        is exactly 1 and its standard deviation is
        ``sqrt(σ_l² + σ_p² + 2 σ_l σ_p ρ)``, ``ρ`` the (small, random) sample
        correlation of ``L`` and ``P``.

    Raises
    ------
    InputError
        If a sigma is out of range, or the field is not positive everywhere.
    """
    h, w = check_shape(shape)
    channels = check_int(channels, "channels", 1)
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"`rng` must be a numpy.random.Generator, got {type(rng).__name__}")
    sp = check_positive(sigma_pixel, "sigma_pixel", allow_zero=True)
    sl = check_positive(sigma_lowfreq, "sigma_lowfreq", allow_zero=True)
    for name, s in (("sigma_pixel", sp), ("sigma_lowfreq", sl)):
        if s > 0.25:
            raise InputError(f"`{name}` must be at most 0.25 (relative sensitivity), got {s}")
    scale = check_positive(lowfreq_scale, "lowfreq_scale")
    c = int(channels)
    white_low = rng.standard_normal((h, w, c))
    white_pix = rng.standard_normal((h, w, c))
    sigma_px = max(1.0, scale * min(h, w))
    low = gaussian_filter(white_low, sigma=(sigma_px, sigma_px, 0.0), mode="reflect")
    u = 1.0 + sl * _unit(low) + sp * _unit(white_pix)
    if np.any(u <= 0):
        raise InputError(
            "`sigma_pixel`/`sigma_lowfreq` too large: the sensitivity field is not positive"
        )
    return u
