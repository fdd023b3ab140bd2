"""Samples from flat regions: edge pixels left out of a response fit's candidates.

A response fit ties each sampled pixel's values in several exposures to one
photoquantity ``E_p`` (eq. 1 of [PQ]_). At an edge or in fine texture that
tie is weakest: a sub-pixel shift between exposures (a hand-held bracket, a
tripod's vibration), a moving leaf, a JPEG's ringing and sharpening halos, a
demosaicking error at a colour edge or the optics' blur of a bright
neighbour change a pixel's value without any change of the response, and a
fit of ``g`` reads them as the response. Debevec and Malik chose their
samples "from areas of low intensity variance in the image", "so that the
radiance is assumed constant across the area of the pixel, and the effect of
optical blur of the imaging system is minimised" ([Debevec1997]_ §2.2), by
hand; Hugin's photometric optimiser keeps, of randomly drawn points, those
with the smallest Laplacian of Gaussian ([dAngelo2007]_).

Rule
----
For every candidate pixel ``p``, every exposure ``k`` and channel ``c``, the
discrete Laplacian at a distance of ``step`` pixels (mirrored at the
image's border)::

    Δ_kc(p) = |4 v(p) − v(p ± step·x̂) − v(p ± step·ŷ)|

is compared with its typical size, the
median ``m_kc`` of ``Δ_kc`` over the candidates whose value ``v(p)`` is valid
(above the black level, below the saturation level), floored at one code
value (the quantisation step: a noiseless smooth image has ``m = 0``). A
pixel is *flat* when ``Δ_kc(p) ≤ limit · m_kc`` at every valid ``(k, c)``
(``limit = 3``); the others are left out of the candidates from which the
samples are drawn. Where fewer than half the candidates pass (a scene of
texture only), the flatter half is kept instead, ranked by the largest ratio
``Δ_kc / m_kc``: the fit keeps candidates at every level.

A pixel's own noise enters its Laplacian too (with weight 4): in a flat
region of Gaussian noise each ``(k, c)`` leaves out about 4 % of the pixels
(``|Δ| > 3 · 0.674 σ_Δ``), so about ``1 − 0.96^{K·C}`` of the region goes
(a half at ``K = 5``, ``C = 3``). The rule is as much a trim of the values
with the largest noise excursions, symmetric in their sign, as a test for
edges.

``step = 2``: on a colour-filter mosaic read as one channel (a raw Bayer
frame, e.g. a machine-vision camera's 12-bit values), the neighbours two
pixels away are the same colour, so a flat region of the scene is flat in
the Laplacian; at one pixel the mosaic's own pattern would dominate it. On
demosaicked frames it measures edges over a 5-pixel span, the span over which
a one-pixel shift or a demosaicking error changes a value.

The default of the ``"Debevec 1997"`` response (``edges="excluded"``; the
``paper`` profile keeps every candidate, ``"kept"``, as the paper). With the
response refined in the values (its default objective), measured
2026-12-06 on this 2-core machine:

* real brackets, ``photoquant crossval`` on the user's path (sampling seed
  0): the 12-bit machine-vision bracket 93.23 → 92.76 DN (its authors'
  response 92.31: 1.005×), Memorial 2.241 → 2.075, the St. Louis Arch 9.726
  → 9.643, frobisher 7.338 → 7.201;
* pqsim's ``ccd``, ``cmos``, ``film``, ``emor-0``, ``emor-1`` and ``emor-3``
  cameras (320×240, N = 1, the worst channel's ``g`` rms over the levels
  the hat weighs ≥ 5 %, geometric mean): six exposures one stop apart,
  8 bits 0.0058 → 0.0045 and 12 bits 0.0062 → 0.0044, better on every
  camera; four exposures two stops apart (8 bits) 0.0089 → 0.0095, better
  on ``cmos``, ``emor-0`` and ``emor-1``, worse on ``ccd`` (0.0028 →
  0.0041), ``film`` (0.0027 → 0.0031) and ``emor-3`` (0.0255 → 0.0353): a
  sparse bracket keeps fewer candidates at each level;
* the quick validation (master seeds 0-2 against the eight seeds' mean of
  the stored baseline): the HDR test scene's error ``ccd`` 1.247 → 1.255 %,
  ``cmos`` 3.416 → 3.383 %; the ``cmos`` camera's colour balance error (B)
  0.06 → 0.17 %; every metric within the baseline's tolerance.

As an option beside eq. 7 as written (``objective="log"``), measured
2026-12-05:

* real brackets, ``photoquant crossval`` on the user's path (mean over the
  sampling seeds 0-3; every pixel scored, edges included): Memorial 2.28 →
  2.10 DN, the St. Louis Arch 9.72 → 9.65, frobisher 7.43 → 7.35, the 12-bit
  machine-vision bracket 94.27 → 93.30 (its authors' response: 92.31);
  over the seeds, 2.10 on Memorial each time, 9.62-9.69 on the St. Louis
  Arch, 7.20-7.49 on frobisher, 93.11-93.49 on the 12-bit bracket;
* pqsim's ``ccd``, ``cmos``, ``film``, ``emor-0`` and ``emor-1`` cameras
  (160×120, N = 1, seeds 0 and 1; six exposures one stop apart, four two
  stops, three three stops, two four stops): the rms error of ``g`` against
  the truth changes by a factor of 0.75-1.40, geometric mean 0.99 (0.0104 →
  0.0102; 0.75-1.40 on the brackets of two stops, 0.84-1.24 on the others);
* the quick validation (``photoquant validate``, 320×240, N = 4; master
  seeds 0, 1, 2): the HDR test scene's error ``ccd`` 1.36 / 1.17 / 1.10 →
  1.08 / 1.16 / 1.04 % (floor 1.00 %), ``cmos`` 3.68 / 3.78 / 3.98 → 3.75 /
  3.68 / 4.15 % (floor 3.21 %); the vignetting map's largest error ``ccd``
  0.76 / 0.31 / 0.14 → 0.61 / 0.45 / 0.19 %, ``cmos`` 1.53 / 2.00 / 2.20 →
  1.07 / 1.56 / 3.04 %; the ``cmos`` camera's colour balance error R / B
  0.05 / 0.50, 0.80 / 0.03, 1.29 / 0.95 % → 1.02 / 1.36, 0.72 / 0.13, 1.66
  / 1.08 %;
* an analytic camera (tests): 16-pixel blocks over a three-decade ramp, five
  exposures one stop apart, 1 DN of noise: ``g``'s error 0.0054 → 0.0060
  on a still bracket (fewer candidates at each level), 0.0108 → 0.0082 when
  the middle exposure is shifted by one pixel;
* in a prototype without the min-fraction guard (Memorial 2.08 DN, the
  other brackets as above): with ``step = 1`` the 12-bit mosaic gained
  nothing (94.04 DN); with ``limit = 2``, Memorial 2.14 DN and the 12-bit
  bracket 93.16.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378, §2.2.
   doi:10.1145/258734.258884
.. [dAngelo2007] Hugin's photometric point sampler (P. d'Angelo, 2007;
   ``hugin_base/algorithms/point_sampler/PointSampler.h``): of the pairs of
   points drawn, those of smallest squared Laplacian of Gaussian are kept.
.. [PQ] The photoquantity paper, eq. 1, §5.2.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoquant._grid import mirror_index
from photoquant.errors import InputError

__all__ = [
    "EDGE_LIMIT",
    "EDGE_METHODS",
    "EDGE_STEP",
    "MIN_FLAT_FRACTION",
    "flat_candidates",
    "laplacian_at",
]

EDGE_METHODS = ("kept", "excluded")
"""The ``edges`` option of the Debevec response: every candidate (the paper's) or the edge
pixels left out (the default)."""

EDGE_LIMIT = 3.0
"""A flat pixel's Laplacian is at most this many times its exposure's and channel's median."""

EDGE_STEP = 2
"""Distance of the Laplacian's neighbours (pixels): a colour mosaic's same-colour sites."""

MIN_FLAT_FRACTION = 0.5
"""Below this fraction of flat candidates, the flattest this fraction is kept instead."""

ValuesAt = Callable[[np.ndarray], np.ndarray]
"""``values_at(index)``: the ``(K, P, C)`` values of a stack at flat pixel indices."""


def laplacian_at(
    values_at: ValuesAt,
    shape: tuple[int, int],
    index: np.ndarray,
    step: int = EDGE_STEP,
    *,
    centre: np.ndarray | None = None,
) -> np.ndarray:
    """``|4 v(p) − Σ v(neighbours at distance step)|`` at the flat pixel indices ``index``.

    Parameters
    ----------
    values_at : callable
        ``values_at(idx)`` → ``(K, P, C)`` values at flat (row-major) pixel indices.
    shape : (int, int)
        The image's ``(height, width)``.
    index : ndarray of int
        Flat pixel indices.
    step : int
        Distance of the four neighbours (mirrored at the border).
    centre : ndarray, shape (K, P, C), optional
        ``values_at(index)`` when the caller has read it already.

    Returns
    -------
    ndarray, shape (K, P, C)
    """
    height, width = shape
    rows, cols = np.divmod(np.asarray(index, dtype=np.intp), width)
    if centre is None:
        centre = values_at(index)
    lap = 4.0 * np.asarray(centre, dtype=np.float64)
    for dr, dc in ((-step, 0), (step, 0), (0, -step), (0, step)):
        near = mirror_index(rows + dr, height) * width + mirror_index(cols + dc, width)
        lap -= np.asarray(values_at(near), dtype=np.float64)
    return np.abs(lap, out=lap)


def flat_candidates(
    values_at: ValuesAt,
    shape: tuple[int, int],
    index: np.ndarray,
    black_level: np.ndarray | float,
    saturation_level: np.ndarray | float,
    *,
    limit: float = EDGE_LIMIT,
    step: int = EDGE_STEP,
    min_fraction: float = MIN_FLAT_FRACTION,
) -> np.ndarray:
    """The candidates ``index`` in flat regions (module notes), in their order.

    Parameters
    ----------
    values_at, shape
        The stack's values and image size, as for :func:`laplacian_at`.
    index : ndarray of int
        The candidates' flat pixel indices.
    black_level, saturation_level : float or ndarray of shape (C,)
        A value is valid strictly between the two (per channel).
    limit : float
        Largest ratio of a flat pixel's Laplacian to its median.
    step : int
        Distance of the Laplacian's neighbours.
    min_fraction : float
        Fewest candidates kept, as a fraction (the flattest ones).

    Returns
    -------
    ndarray of int
        The kept subset of ``index``.
    """
    index = np.asarray(index)
    if index.ndim != 1 or index.dtype.kind not in "iu":
        raise InputError(
            f"`index` must be a 1-d array of integers, got {index.dtype} {index.shape}"
        )
    if not (limit > 0 and 0 <= min_fraction <= 1 and step >= 1):
        raise InputError(
            f"`limit` must be positive, `min_fraction` in [0, 1] and `step` at least 1, got "
            f"{limit!r}, {min_fraction!r}, {step!r}"
        )
    if index.size == 0:
        return index
    values = np.asarray(values_at(index), dtype=np.float64)  # (K, P, C)
    lap = laplacian_at(values_at, shape, index, step, centre=values)
    lo = np.broadcast_to(np.asarray(black_level, dtype=np.float64), values.shape[-1:])
    hi = np.broadcast_to(np.asarray(saturation_level, dtype=np.float64), values.shape[-1:])
    valid = (values > lo) & (values < hi)
    ratio = np.zeros(values.shape[1])
    for k in range(values.shape[0]):
        for c in range(values.shape[2]):
            ok = valid[k, :, c]
            if not ok.any():
                continue
            # the typical Laplacian, floored at one code value (a noiseless image's is 0)
            scale = max(float(np.median(lap[k, ok, c])), 1.0)
            np.maximum(ratio, np.where(ok, lap[k, :, c] / scale, 0.0), out=ratio)
    flat = ratio <= limit
    least = int(np.ceil(min_fraction * index.size))
    if np.count_nonzero(flat) < least:
        # a scene of texture only: the flattest candidates (stable ranks: in pixel order on ties)
        flat = np.zeros(index.size, dtype=bool)
        flat[np.argsort(ratio, kind="stable")[:least]] = True
    return index[flat]
