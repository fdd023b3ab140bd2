"""Spatial non-uniformity ground truths: vignetting of the optics and PRNU of the sensor.

Two multiplicative fields of eq. 1 of [PQ], written independently of the
calibrator (photoquant's vignetting module is *not* used here):

- ``v_pλ``, the vignetting of the optics (§3.2.1, §5.5 of [PQ]), either the
  extended Goldman–Chen polynomial the paper fits
  (:func:`vignetting_extended_goldman_chen`) or the natural ``cos⁴`` fall-off
  of a thin lens with an optional mechanical cut-off (the pupil clipped by a
  barrel or hood, :func:`mechanical_vignetting`) and a fall-off of its own
  per channel (:func:`vignetting_cos4`): truths *outside* the fitted family.
  :func:`vignetting_from_record` builds either from a ``{"kind", "params"}``
  record (:data:`VIGNETTING_KINDS`), as preset files give it;
- ``u_pλ``, the sensor's photo-response non-uniformity (PRNU, §3.2.1 and §5.4
  of [PQ]; EMVA 1288 §8), :func:`prnu_field`.

Coordinates follow the project convention: pixel ``(x, y)`` (x right, y down)
has normalised coordinates ``x_n = (x + 0.5) / W``, ``y_n = (y + 0.5) / H``.

References
----------
.. [PQ] The photoquantity paper: eq. 1, §5.5.
.. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration and
   compensation", ICCV 2005, doi:10.1109/ICCV.2005.249.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021), §8 (spatial non-uniformity,
   PRNU).
.. [AAB96] N. Asada, A. Amano and M. Baba, "Photometric calibration of zoom
   lens systems", ICPR 1996, doi:10.1109/ICPR.1996.546018 (mechanical
   vignetting as the common area of the pupil and an obstructing aperture).
.. [Ray02] S. F. Ray, *Applied Photographic Optics*, 3rd ed., Focal Press,
   2002, §24 (natural ``cos⁴`` fall-off and mechanical vignetting).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
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
    "mechanical_vignetting",
    "vignetting_from_record",
    "vignetting_from_records",
    "VIGNETTING_KINDS",
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


def _per_channel(value: Any, name: str, channels: int) -> np.ndarray:
    """A positive scalar or ``channels`` positive values, as a float64 array of ``channels``."""
    arr = np.atleast_1d(check_array(value, name, kind="iuf", finite=True)).astype(np.float64)
    if arr.ndim != 1 or arr.size not in (1, channels):
        raise InputError(
            f"`{name}` must be one number or {channels} (one per channel), got {value!r}"
        )
    if np.any(arr <= 0):
        raise InputError(f"`{name}` must be positive, got {arr.tolist()}")
    return np.broadcast_to(arr, (channels,)).copy()


def mechanical_vignetting(r: Any, start: float, end: float) -> np.ndarray:
    """Mechanical (pupil-clipping) vignetting: the unobstructed fraction of the pupil.

    Parameters
    ----------
    r : array_like
        Distance of the image point from the optical centre (any unit).
    start, end : float
        The cut starts at ``r = start`` (1 inside) and blocks the whole pupil
        at ``r = end > start`` (0 beyond), same unit as ``r``.

    Returns
    -------
    ndarray, float64
        ``A(d) / π``, the common area of the pupil (a unit disc) and an
        obstructing aperture (a disc of radius ``ρ``) whose centres are
        ``d = a · r`` apart, over the pupil's area [AAB96]_; ``ρ`` and ``a``
        make the cut start at ``start`` (``d = ρ − 1``) and end at ``end``
        (``d = ρ + 1``): ``ρ = (end + start) / (end − start)``,
        ``a = (ρ − 1) / start``. This is the "cat's eye" pupil of an
        off-axis point seen through a lens barrel or hood [Ray02]_.

    Examples
    --------
    >>> mechanical_vignetting([0.0, 0.5, 1.0, 1.5, 2.0], 0.5, 1.5).round(4).tolist()
    [1.0, 1.0, 0.4466, 0.0, 0.0]
    """
    rr = check_array(r, "r", kind="iuf", finite=True).astype(np.float64)
    a0 = check_positive(start, "start")
    a1 = check_positive(end, "end")
    if not a1 > a0:
        raise InputError(f"the cut-off's `end` ({end}) must lie beyond its `start` ({start})")
    rho = (a1 + a0) / (a1 - a0)
    d = np.abs(rr) * (rho - 1.0) / a0
    out = np.where(d <= rho - 1.0, 1.0, 0.0)
    part = (d > rho - 1.0) & (d < rho + 1.0)
    dp = d[part]
    c1 = np.clip((dp * dp + 1.0 - rho * rho) / (2.0 * dp), -1.0, 1.0)
    c2 = np.clip((dp * dp + rho * rho - 1.0) / (2.0 * dp * rho), -1.0, 1.0)
    k = (-dp + 1.0 + rho) * (dp + 1.0 - rho) * (dp - 1.0 + rho) * (dp + 1.0 + rho)
    area = np.arccos(c1) + rho * rho * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    out[part] = np.clip(area / np.pi, 0.0, 1.0)
    return out


def vignetting_cos4(
    shape: Sequence[int],
    focal_px: Any,
    channels: int | None = None,
    centre: tuple[float, float] | None = None,
    *,
    cutoff_start_px: Any = None,
    cutoff_end_px: Any = None,
) -> np.ndarray:
    """Natural vignetting of a thin lens, the ``cos⁴`` law, with an optional mechanical cut-off.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    focal_px : float or sequence of C floats
        Focal length in pixels (positive); one per channel gives each channel
        a fall-off of its own (a lens whose pupil or stop acts differently by
        wavelength).
    channels : int, optional
        Number of channels ``C``; ``len(focal_px)`` for a sequence, 3 otherwise.
    centre : (x, y), optional
        Optical centre in pixel coordinates; the image centre ``(W/2, H/2)`` by
        default (between pixels when a side is even).
    cutoff_start_px, cutoff_end_px : float or sequence of C floats, optional
        A mechanical cut-off (:func:`mechanical_vignetting`) starting at this
        distance from the centre and blocking all light at the end distance,
        in pixels; both or neither.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``cos⁴ θ = (f² / (f² + r²))²`` times the cut-off's unobstructed
        pupil fraction, ``r`` the distance of the pixel centre
        ``(x + 0.5, y + 0.5)`` to ``centre``; 1 at the centre.

    Notes
    -----
    Not a member of the Goldman–Chen family with three terms exactly (its
    series in ``r²`` is infinite), so it tests a calibrator on a truth outside
    its model; the cut-off adds a kink (its onset) that no polynomial has.
    """
    h, w = check_shape(shape)
    seq = np.ndim(focal_px) > 0
    c = check_int(
        channels if channels is not None else (np.size(focal_px) if seq else 3), "channels", 1
    )
    f = _per_channel(focal_px, "focal_px", c)
    cx, cy = (w / 2.0, h / 2.0) if centre is None else (float(centre[0]), float(centre[1]))
    x = np.arange(w, dtype=np.float64) + 0.5 - cx
    y = np.arange(h, dtype=np.float64) + 0.5 - cy
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    v = (f * f / (f * f + r2[..., None])) ** 2
    if (cutoff_start_px is None) != (cutoff_end_px is None):
        raise InputError("`cutoff_start_px` and `cutoff_end_px` go together (give both or neither)")
    if cutoff_start_px is not None:
        a0 = _per_channel(cutoff_start_px, "cutoff_start_px", c)
        a1 = _per_channel(cutoff_end_px, "cutoff_end_px", c)
        r = np.sqrt(r2)
        cut = np.stack([mechanical_vignetting(r, a0[i], a1[i]) for i in range(c)], axis=2)
        v = v * cut
    return v


def _half_diagonal(shape: Sequence[int]) -> float:
    h, w = check_shape(shape)
    return float(np.hypot(w, h) / 2.0)


def _record_egc(params: Mapping[str, Any], shape: Sequence[int], channels: int) -> np.ndarray:
    m = check_array(params.get("m"), "m", kind="iuf", finite=True).astype(np.float64)
    m = np.broadcast_to(m, (channels, 6)) if m.shape == (6,) else m
    if m.shape != (channels, 6):
        raise InputError(f"`m` must be 6 numbers or {channels} rows of 6 (m1..m6), got {m.shape}")
    return vignetting_extended_goldman_chen(m, shape)


def _record_cos4(params: Mapping[str, Any], shape: Sequence[int], channels: int) -> np.ndarray:
    h, w = check_shape(shape)
    hd = _half_diagonal(shape)
    centre = params.get("centre") or (0.5, 0.5)
    cn = check_array(centre, "centre", shape=(2,), kind="iuf", finite=True)

    def px(name: str) -> Any:
        value = params.get(name)
        return None if value is None else _per_channel(value, name, channels) * hd

    return vignetting_cos4(
        shape,
        px("focal"),
        channels,
        centre=(float(cn[0]) * w, float(cn[1]) * h),
        cutoff_start_px=px("cutoff_start"),
        cutoff_end_px=px("cutoff_end"),
    )


VIGNETTING_KINDS: Mapping[str, tuple[Callable[..., np.ndarray], frozenset[str]]] = {
    "extended_goldman_chen": (_record_egc, frozenset({"m"})),
    "cos4": (_record_cos4, frozenset({"focal", "centre", "cutoff_start", "cutoff_end"})),
}
"""Vignetting truths by kind: ``kind → (map builder, parameter names)``.

- ``"extended_goldman_chen"``: ``{"m": [m1..m6]}`` (or one row per channel),
  :func:`vignetting_extended_goldman_chen`.
- ``"cos4"``: ``{"focal", "centre", "cutoff_start", "cutoff_end"}``:
  :func:`vignetting_cos4` with lengths in half-diagonals of the image (so a
  record means the same lens at every resolution; the corner is at 1),
  ``centre`` in normalised coordinates (``[0.5, 0.5]`` by default), each
  length one number or one per channel, the cut-off optional.
"""


def vignetting_from_record(
    record: Mapping[str, Any], shape: Sequence[int], channels: int
) -> np.ndarray:
    """The map ``v`` (H, W, C) of a ``{"kind", "params"}`` record of :data:`VIGNETTING_KINDS`.

    Examples
    --------
    >>> rec = {"kind": "cos4", "params": {"focal": 2.0}}
    >>> v = vignetting_from_record(rec, (3, 4), 3)
    >>> v.shape, round(float(v[0, 0, 0]), 6)  # f = 2 · 2.5 px, r² = 1.5² + 1²: (25 / 28.25)²
    ((3, 4, 3), 0.783147)
    """
    if not isinstance(record, Mapping) or "kind" not in record:
        raise InputError(
            f"a vignetting record is {{'kind': ..., 'params': {{...}}}}, got {record!r}"
        )
    kind = str(record["kind"]).lower()
    if kind not in VIGNETTING_KINDS:
        raise InputError(
            f"unknown vignetting kind {record['kind']!r}; valid: {sorted(VIGNETTING_KINDS)}"
        )
    build, names = VIGNETTING_KINDS[kind]
    params = record.get("params", {})
    if not isinstance(params, Mapping):
        raise InputError(f"vignetting {kind!r}: `params` must be a mapping, got {params!r}")
    unknown = set(params) - names
    if unknown:
        raise InputError(
            f"vignetting {kind!r}: unknown parameter(s) {sorted(unknown)}; valid: {sorted(names)}"
        )
    if kind == "cos4" and params.get("focal") is None:
        raise InputError("vignetting 'cos4' needs `focal` (in half-diagonals of the image)")
    v = build(params, shape, check_int(channels, "channels", 1))
    if np.any(v <= 0) or not np.all(np.isfinite(v)):
        raise InputError(
            f"vignetting {kind!r}: the map is not positive inside the image (cut too deep?)"
        )
    return v


def vignetting_from_records(records: Any, shape: Sequence[int], channels: int) -> np.ndarray:
    """``v`` from one record (every channel) or a sequence of ``channels`` records (one each)."""
    if isinstance(records, Mapping):
        return vignetting_from_record(records, shape, channels)
    recs = list(records)
    if len(recs) != channels:
        raise InputError(
            f"`vignetting` must be one record or {channels} (one per channel), got {len(recs)}"
        )
    return np.concatenate([vignetting_from_record(r, shape, 1) for r in recs], axis=2)


def _unit(field: np.ndarray) -> np.ndarray:
    """Zero mean and unit standard deviation per channel (a constant field stays 0)."""
    field = field - field.mean(axis=(0, 1), keepdims=True)
    std = field.std(axis=(0, 1), keepdims=True)
    return np.divide(field, std, out=np.zeros_like(field), where=std > 0)


_FFT_RADIUS = 200
"""The Gaussian kernel radius (pixels) above which :func:`_smooth` filters by FFT."""


def _smooth(white: np.ndarray, sigma: float) -> np.ndarray:
    """``scipy.ndimage.gaussian_filter(white, (σ, σ, 0), mode="reflect")`` of ``white (H, W,
    C)``: the same kernel (truncated at 4σ, normalised), the same mirrored edges.

    Above a radius of :data:`_FFT_RADIUS` the two 1-d passes are FFT convolutions of the
    mirrored rows and columns (``scipy.signal.fftconvolve``), equal to the direct ones to
    about 1e-15 (tested) and far faster for a wide kernel: the PRNU's smooth component at
    2112×2816 (σ = 317 px, a twin of a 6-megapixel camera) took about 40 s directly, at
    768×1024 (σ = 115 px, ``validate --full``) 1.8 s against 0.8 s (2026-12-07, 2 cores).
    Narrower kernels (the quick job's σ = 36 px) take the direct filter.
    """
    radius = int(4.0 * sigma + 0.5)
    if radius <= _FFT_RADIUS:
        return gaussian_filter(white, sigma=(sigma, sigma, 0.0), mode="reflect")
    from scipy.signal import fftconvolve

    x = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 / (sigma * sigma) * x**2)
    kernel /= kernel.sum()
    out = white
    for axis in (0, 1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (radius, radius)
        shape = [1] * out.ndim
        shape[axis] = kernel.size
        mirrored = np.pad(out, pad, mode="symmetric")  # scipy.ndimage's "reflect"
        out = fftconvolve(mirrored, kernel.reshape(shape), mode="valid", axes=axis)
    return out


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
    low = _smooth(white_low, sigma_px)
    u = 1.0 + sl * _unit(low) + sp * _unit(white_pix)
    if np.any(u <= 0):
        raise InputError(
            "`sigma_pixel`/`sigma_lowfreq` too large: the sensitivity field is not positive"
        )
    return u
