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

Computation
-----------
With numba (:mod:`photoquant._numba`) the test is three compiled passes on every
core: the Laplacians of every candidate, exposure and channel read straight
from a stack's integer sums (``v = sums / N``, the mean's bits, no float
copy of the frames), one exact median per ``(k, c)`` (a selection, not a
sort), the ratios; the numpy version (:func:`_edge_ratio_numpy`) is the
reference and gives the same bits (``tests/photoquant/test_flat_samples.py``).
Measured 2026-12-06 on a 2-core AMD EPYC, the response benchmark's
1024×768, ``K = 8`` view (2¹⁷ candidates): 86-91 → 30-33 ms (min of 15).

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

from typing import Any

import numpy as np

from photoquant._checks import default_workers
from photoquant._grid import mirror_index
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._select import median_inplace
from photoquant._threads import even_spans, thread_map
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


def _check_values(values: Any, shape: tuple[int, int]) -> np.ndarray:
    """``values`` as a ``(K, H·W, C)`` array of real numbers, or an :class:`InputError`."""
    values = np.asarray(values)
    height, width = shape
    if values.ndim != 3 or values.shape[1] != height * width or values.dtype.kind not in "iuf":
        raise InputError(
            f"`values` must be a (K, {height}·{width}, C) array of real numbers, got "
            f"{values.dtype} {values.shape}"
        )
    return values


def _neighbours(index: np.ndarray, shape: tuple[int, int], step: int) -> list[np.ndarray]:
    """The flat indices of the four neighbours of ``index`` at ``step`` pixels (mirrored):
    above, below, left, right."""
    height, width = shape
    rows, cols = np.divmod(np.asarray(index, dtype=np.intp), width)
    return [
        mirror_index(rows + dr, height) * width + mirror_index(cols + dc, width)
        for dr, dc in ((-step, 0), (step, 0), (0, -step), (0, step))
    ]


def laplacian_at(
    values: np.ndarray,
    shape: tuple[int, int],
    index: np.ndarray,
    step: int = EDGE_STEP,
    *,
    divisor: float = 1.0,
) -> np.ndarray:
    """``|4 v(p) − Σ v(neighbours at distance step)|`` at the flat pixel indices ``index``.

    Parameters
    ----------
    values : ndarray, shape (K, H·W, C)
        The stack's values, pixels in row-major order (``v = values / divisor``).
    shape : (int, int)
        The image's ``(height, width)``.
    index : ndarray of int
        Flat pixel indices.
    step : int
        Distance of the four neighbours (mirrored at the border).
    divisor : float
        ``v = values / divisor`` (a stack's integer sums over ``N`` repeats and ``N``:
        the mean's bits).

    Returns
    -------
    ndarray, shape (K, P, C)
    """
    values = _check_values(values, shape)
    index = np.asarray(index, dtype=np.intp)
    return _laplacian(values, shape, index, step, divisor, np.take(values, index, axis=1) / divisor)


def _laplacian(
    values: np.ndarray,
    shape: tuple[int, int],
    index: np.ndarray,
    step: int,
    divisor: float,
    centre: np.ndarray,
) -> np.ndarray:
    """:func:`laplacian_at` given ``centre``, the values ``v`` at ``index`` (read once)."""
    lap = 4.0 * centre
    for near in _neighbours(index, shape, step):
        lap -= np.take(values, near, axis=1) / divisor
    return np.abs(lap, out=lap)


def _edge_ratio_numpy(
    values: np.ndarray,
    shape: tuple[int, int],
    index: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    step: int,
    divisor: float,
) -> np.ndarray:
    """Per candidate, the largest ``Δ_kc / m_kc`` over its valid ``(k, c)`` (0 when none):
    the readable reference of the compiled :func:`_edge_ratio_compiled` (same bits)."""
    centre = np.take(values, index, axis=1) / divisor  # (K, P, C)
    lap = _laplacian(values, shape, index, step, divisor, centre)
    valid = (centre > lo) & (centre < hi)
    ratio = np.zeros(index.size)
    for k in range(values.shape[0]):
        for c in range(values.shape[2]):
            ok = valid[k, :, c]
            if not ok.any():
                continue
            # the typical Laplacian, floored at one code value (a noiseless image's is 0)
            scale = max(float(np.median(lap[k, ok, c])), 1.0)
            np.maximum(ratio, np.where(ok, lap[k, :, c] / scale, 0.0), out=ratio)
    return ratio


def _mirror_py(i: int, n: int) -> int:  # pragma: no cover - compiled by numba
    """numba body: :func:`photoquant._grid.mirror_index` of one index."""
    if n == 1:
        return 0
    period = 2 * (n - 1)
    i = abs(i) % period
    return period - i if i >= n else i


def _laplacians_py(
    values: Any,
    divisor: float,
    index: Any,
    height: int,
    width: int,
    step: int,
    lo: Any,
    hi: Any,
    lap: Any,
    start: int,
    stop: int,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: ``lap (K, C, P)`` at ``index[start:stop]``: ``|4 v(p) − Σ v(neighbours)|``
    where ``v(p) = values / divisor`` is valid, −1 elsewhere; the subtractions in
    :func:`laplacian_at`'s order (above, below, left, right)."""
    n_k, _, n_c = values.shape
    for i in range(start, stop):
        q = index[i]
        row = q // width
        col = q - row * width
        up = _mirror(row - step, height) * width + col
        down = _mirror(row + step, height) * width + col
        left = row * width + _mirror(col - step, width)
        right = row * width + _mirror(col + step, width)
        for k in range(n_k):
            for c in range(n_c):
                v = values[k, q, c] / divisor
                if v > lo[c] and v < hi[c]:
                    x = 4.0 * v
                    x -= values[k, up, c] / divisor
                    x -= values[k, down, c] / divisor
                    x -= values[k, left, c] / divisor
                    x -= values[k, right, c] / divisor
                    lap[k, c, i] = abs(x)
                else:
                    lap[k, c, i] = -1.0


def _valid_median_py(lap: Any) -> float:  # pragma: no cover - compiled by numba
    """numba body: the median of the entries ``≥ 0`` of ``lap`` (−1 when there are none)."""
    kept = np.empty(lap.size)
    n = 0
    for x in lap:
        if x >= 0.0:
            kept[n] = x
            n += 1
    if n == 0:
        return -1.0
    return median_inplace(kept[:n])


def _largest_ratio_py(
    lap: Any, scale: Any, ratio: Any, start: int, stop: int
) -> None:  # pragma: no cover - compiled by numba
    """numba body: ``ratio[i]`` = the largest ``lap[k, c, i] / scale[k, c]`` over the valid
    ``(k, c)`` (``lap ≥ 0``), 0 when none, for ``i`` in ``[start, stop)``."""
    n_k, n_c, _ = lap.shape
    for i in range(start, stop):
        r = 0.0
        for k in range(n_k):
            for c in range(n_c):
                x = lap[k, c, i]
                if x >= 0.0:
                    r = max(r, x / scale[k, c])
        ratio[i] = r


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    _mirror = compile_kernel(_mirror_py)
    _laplacians = compile_kernel(_laplacians_py)
    _valid_median = compile_kernel(_valid_median_py)
    _largest_ratio = compile_kernel(_largest_ratio_py)


def _edge_ratio_compiled(
    values: np.ndarray,
    shape: tuple[int, int],
    index: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    step: int,
    divisor: float,
) -> np.ndarray:  # pragma: no cover - depends on the environment
    """:func:`_edge_ratio_numpy` in three compiled passes on every core (the same bits):
    the Laplacians, one exact median per ``(k, c)``, the ratios."""
    n_k, _, n_c = values.shape
    height, width = shape
    lap = np.empty((n_k, n_c, index.size))
    spans = even_spans(index.size, min(default_workers(), 1 + index.size // 8192))
    thread_map(
        lambda s: _laplacians(
            values, float(divisor), index, height, width, step, lo, hi, lap, s.start, s.stop
        ),
        spans,
    )
    medians = thread_map(lambda kc: _valid_median(lap[kc]), np.ndindex(n_k, n_c))
    # the typical Laplacian, floored at one code value; no valid value: no ratio read
    scale = np.maximum(np.asarray(medians, dtype=np.float64).reshape(n_k, n_c), 1.0)
    ratio = np.empty(index.size)
    thread_map(lambda s: _largest_ratio(lap, scale, ratio, s.start, s.stop), spans)
    return ratio


def flat_candidates(
    values: np.ndarray,
    shape: tuple[int, int],
    index: np.ndarray,
    black_level: np.ndarray | float,
    saturation_level: np.ndarray | float,
    *,
    divisor: float = 1.0,
    limit: float = EDGE_LIMIT,
    step: int = EDGE_STEP,
    min_fraction: float = MIN_FLAT_FRACTION,
) -> np.ndarray:
    """The candidates ``index`` in flat regions (module notes), in their order.

    One compiled pass over the candidates and one exact median per exposure
    and channel when numba imports; the numpy reference otherwise (the same
    bits).

    Parameters
    ----------
    values : ndarray, shape (K, H·W, C)
        The stack's values, pixels in row-major order (``v = values / divisor``).
    shape : (int, int)
        The image's ``(height, width)``.
    index : ndarray of int
        The candidates' flat pixel indices.
    black_level, saturation_level : float or ndarray of shape (C,)
        A value ``v`` is valid strictly between the two (per channel).
    divisor : float
        ``v = values / divisor``: a stack's integer sums over its ``N`` repeats
        and ``N`` give its mean's bits without a full-size float array.
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
    values = _check_values(values, shape)
    index = np.asarray(index)
    if index.ndim != 1 or index.dtype.kind not in "iu":
        raise InputError(
            f"`index` must be a 1-d array of integers, got {index.dtype} {index.shape}"
        )
    if index.size and not (0 <= index.min() and index.max() < values.shape[1]):
        raise InputError(f"`index` must lie in [0, {values.shape[1]}) (flat pixel indices)")
    if not (limit > 0 and 0 <= min_fraction <= 1 and step >= 1 and divisor > 0):
        raise InputError(
            f"`limit` and `divisor` must be positive, `min_fraction` in [0, 1] and `step` at "
            f"least 1, got {limit!r}, {divisor!r}, {min_fraction!r}, {step!r}"
        )
    if index.size == 0:
        return index
    n_c = values.shape[-1]
    # fresh writable copies, whatever was given: one compiled signature of the kernel
    lo = np.array(np.broadcast_to(np.asarray(black_level, dtype=np.float64), (n_c,)))
    hi = np.array(np.broadcast_to(np.asarray(saturation_level, dtype=np.float64), (n_c,)))
    edge_ratio = _edge_ratio_compiled if HAVE_NUMBA else _edge_ratio_numpy
    ratio = edge_ratio(values, shape, index.astype(np.intp, copy=False), lo, hi, step, divisor)
    flat = ratio <= limit
    least = int(np.ceil(min_fraction * index.size))
    if np.count_nonzero(flat) < least:
        # a scene of texture only: the flattest candidates (stable ranks: in pixel order on ties)
        flat = np.zeros(index.size, dtype=bool)
        flat[np.argsort(ratio, kind="stable")[:least]] = True
    return index[flat]
