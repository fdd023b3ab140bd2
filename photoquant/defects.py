"""Defective pixels: hot and stuck pixels found in exposure stacks, flagged and not merged.

A real sensor has a few pixels that do not measure light: *stuck* (dead)
pixels give the same value in every frame whatever the exposure, *hot*
pixels collect a large dark charge and stand far above their neighbours in
every frame [EMVA]_. Eq. 1 of [PQ] has no term for them; merged, they
become spurious bright or flat points of the photoquantity, of the sensor
LUT and of the vignetting fit's samples. This module finds them from the
stacks themselves (no dark frames needed) and flags them, so that they get
zero weight, as pixels with no valid exposure do
(:func:`exclude_defects`).

Criteria, per pixel and channel, from the repeat means ``c̄_k`` of a stack:

- **stuck**: every frame (all exposures, all repeats) holds the same value,
  strictly between the black level and the saturation level (a pixel
  saturated or dark in every frame is flagged by the merge already), while
  the median of its 8 neighbours moves by more than ``stuck_min_change_dn``
  between the shortest and the longest exposure (the scene's light did
  change: a real pixel's value would have followed it);
- **hot**: in each of its ``max(hot_min_exposures, K // 3)`` shortest
  unsaturated exposures (at least ``hot_min_exposures`` of them), ``c̄_k`` exceeds the ``r``-th largest of
  its 8 neighbours by more than ``max(hot_min_dn, hot_sigmas · σ_k)``, where
  ``σ_k`` is a robust spread (1.4826 · MAD) of that excess over the image.
  With one stack ``r = 1`` (all 8 neighbours): a scene's bright spot is
  wider than one pixel behind any lens, and an edge or a corner has
  neighbours on its bright side. With several stacks ``r = 4``: a hot pixel
  beside a bright edge is still found, and a scene corner is not flagged in
  every view.

With several stacks (the calibration views, which see the scene shifted),
a pixel is defective where one stack flags it and none clears it (a stack
clears a pixel whose values change, or that stays below the threshold in
enough unsaturated short exposures; a pixel saturated or dark in a view
tells nothing there): a defect is a property of the sensor, the scene
content is not.

References
----------
.. [EMVA] EMVA Standard 1288, release 4.0 (2021) (defect pixels: hot,
   dead and stuck pixels, found from dark and flat images).
.. [PQ] The photoquantity paper: eq. 1, §5.2 (merge).
.. [Malvar2004] Malvar, H. S., He, L.-W., & Cutler, R. (2004). High-quality
   linear interpolation for demosaicing of Bayer-patterned color images.
   ICASSP 2004, iii-485. doi:10.1109/ICASSP.2004.1326587
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from photoquant._checks import check_int, default_workers
from photoquant._grid import mirror_index
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._select import channel_histograms
from photoquant._threads import thread_map
from photoquant.errors import InputError
from photoquant.stack import ExposureStack, _compare_per_channel
from photoquant.utils import check_positive

__all__ = [
    "DEMOSAIC_RADIUS_PX",
    "DefectMap",
    "detect_defects",
    "exclude_defects",
    "hide_defects",
]

DEMOSAIC_RADIUS_PX = 2
"""How far a demosaicing carries a pixel's value into its neighbours (Malvar–He–Cutler's 5 × 5)."""

_RING = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=bool)
"""The 8 neighbours of a pixel."""


@dataclass(frozen=True, eq=False)
class DefectMap:
    """Hot and stuck pixels of a sensor, per pixel and channel.

    Attributes
    ----------
    hot, stuck : ndarray, shape (H, W, C), bool
        The flagged pixels (disjoint).
    """

    hot: np.ndarray
    stuck: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """``(H, W, C)`` bool: hot or stuck."""
        return self.hot | self.stuck

    def neighbourhood(self, radius: int = DEMOSAIC_RADIUS_PX) -> DefectMap:
        """The defects with every pixel within ``radius`` of one, in every channel, as stuck.

        In a demosaiced image a defect's value is carried into its neighbours
        of every channel (bilinear interpolation: 1 pixel; Malvar, He &
        Cutler's: 2 [Malvar2004]_). On a frame set that is mostly dark (a
        glare capture) such pixels, which do not scale with the exposure
        either, can outnumber the lit ones.
        """
        from scipy.ndimage import binary_dilation

        check_int(radius, "radius", 0)
        any_channel = np.asarray(self.mask.any(axis=-1), dtype=bool)
        if radius > 0:
            any_channel = np.asarray(
                binary_dilation(any_channel, np.ones((3, 3), bool), iterations=radius), dtype=bool
            )
        spread = np.broadcast_to(any_channel[:, :, None], self.mask.shape)
        return DefectMap(self.hot.copy(), spread & ~self.hot)

    def report(self) -> dict[str, Any]:
        """Counts for a calibration report (JSON-ready)."""
        return {"hot": int(self.hot.sum()), "stuck": int(self.stuck.sum())}

    def to_params(self) -> dict[str, list[int]]:
        """The flagged pixels as flat indices into ``(H, W, C)``, ascending (JSON-ready).

        A sensor's defects are few (EMVA 1288 counts them in parts per
        million), so a list of indices is far smaller than a map.
        """
        return {
            "hot": np.flatnonzero(self.hot).tolist(),
            "stuck": np.flatnonzero(self.stuck).tolist(),
        }

    @classmethod
    def from_params(cls, params: Any, shape: tuple[int, int, int]) -> DefectMap:
        """The inverse of :meth:`to_params`, validated (camera files are untrusted).

        Raises :class:`InputError` naming the problem: not an object of two
        lists, an index that is not an integer or lies outside ``shape``, an
        index listed twice, or a pixel both hot and stuck.
        """
        if not isinstance(params, dict) or set(params) != {"hot", "stuck"}:
            raise InputError("`defects` must be an object with the lists `hot` and `stuck`")
        size = int(np.prod(shape))
        maps = {}
        for kind in ("hot", "stuck"):
            idx = params[kind]
            if not isinstance(idx, list) or not all(
                isinstance(i, int) and not isinstance(i, bool) for i in idx
            ):
                raise InputError(f"`defects.{kind}` must be a list of integer pixel indices")
            flat = np.asarray(idx, dtype=np.int64)
            if flat.size and (flat.min() < 0 or flat.max() >= size):
                raise InputError(
                    f"`defects.{kind}` has an index outside the {shape[0]}x{shape[1]}x{shape[2]} "
                    f"image (indices run from 0 to {size - 1})"
                )
            if np.unique(flat).size != flat.size:
                raise InputError(f"`defects.{kind}` lists a pixel twice")
            m = np.zeros(size, dtype=bool)
            m[flat] = True
            maps[kind] = m.reshape(shape)
        if np.any(maps["hot"] & maps["stuck"]):
            raise InputError("`defects` lists a pixel as both hot and stuck")
        return cls(hot=maps["hot"], stuck=maps["stuck"])


def _ring_rank(image: np.ndarray, rank: int) -> np.ndarray:
    """``rank``-th largest of the 8 neighbours of every pixel, per channel (edges mirrored).

    The readable reference (:mod:`scipy.ndimage`); :func:`_ring_rank_fast`
    gives the same values.
    """
    if rank == 1:
        return ndimage.maximum_filter(image, footprint=_RING[..., None], mode="mirror")
    return ndimage.rank_filter(image, -rank, footprint=_RING[..., None], mode="mirror")


def _sort8_py(
    v0: Any, v1: Any, v2: Any, v3: Any, v4: Any, v5: Any, v6: Any, v7: Any
) -> Any:  # pragma: no cover - numba body
    """numba body: 8 values in increasing order, through Batcher's odd-even merge sort
    (19 branch-free compare-exchanges; Knuth, *The Art of Computer Programming* 3, §5.3.4)."""
    v0, v1 = min(v0, v1), max(v0, v1)
    v2, v3 = min(v2, v3), max(v2, v3)
    v4, v5 = min(v4, v5), max(v4, v5)
    v6, v7 = min(v6, v7), max(v6, v7)
    v0, v2 = min(v0, v2), max(v0, v2)
    v1, v3 = min(v1, v3), max(v1, v3)
    v4, v6 = min(v4, v6), max(v4, v6)
    v5, v7 = min(v5, v7), max(v5, v7)
    v1, v2 = min(v1, v2), max(v1, v2)
    v5, v6 = min(v5, v6), max(v5, v6)
    v0, v4 = min(v0, v4), max(v0, v4)
    v1, v5 = min(v1, v5), max(v1, v5)
    v2, v6 = min(v2, v6), max(v2, v6)
    v3, v7 = min(v3, v7), max(v3, v7)
    v2, v4 = min(v2, v4), max(v2, v4)
    v3, v5 = min(v3, v5), max(v3, v5)
    v1, v2 = min(v1, v2), max(v1, v2)
    v3, v4 = min(v3, v4), max(v3, v4)
    v5, v6 = min(v5, v6), max(v5, v6)
    return (v0, v1, v2, v3, v4, v5, v6, v7)


def _ring_row_py(
    above: Any, row: Any, below: Any, out: Any, n_ch: int, sel: int
) -> None:  # pragma: no cover - numba body
    """numba body: the ``sel``-th smallest of the 8 neighbours of a row's inner pixels.

    Rows are flat (``W·C`` values): a pixel's left and right neighbours are
    ``n_ch`` values away, so the loop runs over contiguous values and
    vectorises (inlined with a constant ``sel``).
    """
    m = row.size
    for q in range(n_ch, m - n_ch):
        out[q] = _sort8(
            above[q - n_ch],
            above[q],
            above[q + n_ch],
            row[q - n_ch],
            row[q + n_ch],
            below[q - n_ch],
            below[q],
            below[q + n_ch],
        )[sel]


def _ring_rank_py(  # pragma: no cover - numba body
    image: Any, rank: Any, out: Any, row_start: int, row_stop: int
) -> None:
    """numba body of :func:`_ring_rank_fast` for rows ``[row_start, row_stop)``: per value,
    its 8 neighbours sorted (:func:`_sort8_py`), then the ``rank``-th largest; row by
    row, the first and last pixel of a row (mirrored edges) apart. Measured 2026-12-02
    on a 768×1024×3 float64 image (2-core machine, quiet): 6 ms, against 17 ms
    pixel by pixel with the channel innermost (no vectors).
    """
    h, w, n_ch = image.shape
    m = w * n_ch
    sel = 8 - rank
    for i in range(row_start, row_stop):
        # "mirror" edges: index -1 reads 1, index h reads h - 2 (one row: itself)
        im = i - 1 if i > 0 else min(1, h - 1)
        ip = i + 1 if i < h - 1 else max(h - 2, 0)
        above = image[im].reshape(m)
        row = image[i].reshape(m)
        below = image[ip].reshape(m)
        out_row = out[i].reshape(m)
        for j in (0, w - 1):
            jm = j - 1 if j > 0 else min(1, w - 1)
            jp = j + 1 if j < w - 1 else max(w - 2, 0)
            for ch in range(n_ch):
                out_row[j * n_ch + ch] = _sort8(
                    above[jm * n_ch + ch],
                    above[j * n_ch + ch],
                    above[jp * n_ch + ch],
                    row[jm * n_ch + ch],
                    row[jp * n_ch + ch],
                    below[jm * n_ch + ch],
                    below[j * n_ch + ch],
                    below[jp * n_ch + ch],
                )[sel]
        # the two ranks the defect search uses by default get their own loop with
        # the rank fixed (1.5× faster than the selection made per value)
        if sel == 4:
            _ring_row(above, row, below, out_row, n_ch, 4)
        elif sel == 7:
            _ring_row(above, row, below, out_row, n_ch, 7)
        else:
            _ring_row(above, row, below, out_row, n_ch, sel)


_sort8: Any = compile_kernel(_sort8_py, inline="always") if HAVE_NUMBA else None
_ring_row: Any = compile_kernel(_ring_row_py, inline="always") if HAVE_NUMBA else None
_ring_rank_nb = compile_kernel(_ring_rank_py) if HAVE_NUMBA else None


def _channel_at_py(x: Any, center: Any, i: int, c: int) -> Any:  # pragma: no cover
    """numba body: ``x[i, c]``, or ``|x[i, c] − center[c]|`` when ``center`` is not empty."""
    v = x[i, c]
    if center.size > 0:
        v = abs(v - center[c])
    return v


def _channel_key_bins_py(x: Any, center: Any, counts: Any, n_nan: Any) -> None:  # pragma: no cover
    """numba body: per channel of ``x (M, C)`` (or of ``|x − center|``), the histogram of
    the top 16 bits of each value's order key (its bits as a uint64 that sorts as the
    floats do: sign flipped, negatives inverted), in one pass over the interleaved
    values; NaNs are counted, not binned."""
    top = np.uint64(1) << np.uint64(63)
    m, n_ch = x.shape
    for i in range(m):
        for c in range(n_ch):
            v = _channel_at(x, center, i, c)
            if v != v:
                n_nan[c] += 1
                continue
            b = np.float64(v).view(np.uint64)
            key = b ^ ((np.uint64(0) - (b >> np.uint64(63))) | top)  # ~b if negative, else b | top
            counts[c, key >> np.uint64(48)] += 1


def _channel_key_gather_py(
    x: Any, center: Any, lo: Any, hi: Any, starts: Any, out: Any
) -> None:  # pragma: no cover
    """numba body: channel ``c``'s values (as :func:`_channel_key_bins_py` sees them) whose
    key's top 16 bits lie in ``[lo[c], hi[c]]`` go to ``out[starts[c]:]``, in order.

    Each channel writes one value past its own (overwritten by the next channel's
    first; ``out`` has one slot to spare at its end).
    """
    top = np.uint64(1) << np.uint64(63)
    m, n_ch = x.shape
    for c in range(n_ch):  # channel by channel, the bounds and count in registers
        if hi[c] < lo[c]:  # nothing to gather (a channel with a NaN)
            continue
        n = starts[c]
        lo_c = np.uint64(lo[c])
        hi_c = np.uint64(hi[c])
        for i in range(m):
            v = _channel_at(x, center, i, c)
            b = np.float64(v).view(np.uint64)
            # no branch (signs are random, the keys inside rare: branches mispredict):
            # every value is written at out[n], which only advances past a kept one
            key = (b ^ ((np.uint64(0) - (b >> np.uint64(63))) | top)) >> np.uint64(48)
            out[n] = v
            n += (v == v) & (key >= lo_c) & (key <= hi_c)


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    _channel_at = compile_kernel(_channel_at_py, inline="always")
    _channel_key_bins_nb = compile_kernel(_channel_key_bins_py)
    _channel_key_gather_nb = compile_kernel(_channel_key_gather_py)


def _channel_medians(x: np.ndarray, center: np.ndarray | None = None) -> np.ndarray:
    """Per channel of ``x (M, C)`` float64, ``np.median`` of the channel, or of its
    ``|x − center[c]|``: the same values (a zero's sign aside).

    A median is one or the mean of two order statistics of the data: a radix
    select finds them. One compiled pass over the interleaved values bins every
    channel's by the top 16 bits of their order keys (no copy of a channel, no
    ``|x − center|`` array); a second gathers the bin(s) holding the middle
    ranks, which alone are partitioned, then averaged as numpy does. NaN
    (numpy's NaN median), small arrays and no numba go to numpy. Measured
    2026-12-02 on a 768×1024×3 excess plane (quiet machine): the defect
    search's three robust spreads (the median, then the median absolute
    deviation) 58 → 21–27 ms, against a radix select per channel copied out
    (itself ~3× faster than numpy's introselect).
    """
    m, n_ch = x.shape
    if HAVE_NUMBA and m >= 4096 and x.dtype.kind in "iu":
        exact = _integer_channel_medians(x, center)
        if exact is not None:
            return exact
    if not HAVE_NUMBA or m < 4096 or x.dtype != np.float64:
        cols = [x[:, c] if center is None else np.abs(x[:, c] - center[c]) for c in range(n_ch)]
        return np.array([float(np.median(col)) for col in cols])
    x = np.ascontiguousarray(x)
    cen = np.empty(0) if center is None else np.asarray(center, dtype=np.float64)
    counts = np.zeros((n_ch, 1 << 16), dtype=np.int64)
    n_nan = np.zeros(n_ch, dtype=np.int64)
    _channel_key_bins_nb(x, cen, counts, n_nan)
    out = np.empty(n_ch)
    k_lo, k_hi = (m - 1) // 2, m // 2
    lo = np.zeros(n_ch, dtype=np.int64)
    hi = np.full(n_ch, -1, dtype=np.int64)  # nothing gathered for a channel with a NaN
    below = np.zeros(n_ch, dtype=np.int64)
    size = np.zeros(n_ch, dtype=np.int64)
    for c in range(n_ch):
        if n_nan[c]:
            out[c] = np.nan  # numpy's median of data with a NaN
            continue
        cum = np.cumsum(counts[c])
        lo[c] = np.searchsorted(cum, k_lo, side="right")
        hi[c] = np.searchsorted(cum, k_hi, side="right")
        below[c] = cum[lo[c] - 1] if lo[c] else 0
        size[c] = cum[hi[c]] - below[c]
    starts = np.concatenate([[0], np.cumsum(size)[:-1]])
    cand = np.empty(int(size.sum()) + 1)  # + 1: the gather's spare slot
    _channel_key_gather_nb(x, cen, lo, hi, starts, cand)
    for c in range(n_ch):
        if n_nan[c]:
            continue
        part = np.partition(
            cand[starts[c] : starts[c] + size[c]], [k_lo - below[c], k_hi - below[c]]
        )
        # numpy's median: the mean of the middle two (even M) or the middle one alone
        out[c] = float(np.mean(part[k_lo - below[c] : k_hi - below[c] + 1]))
    return out


_MAX_INTEGER_BINS = 1 << 20
"""The widest range of integer values :func:`_integer_channel_medians` counts (beyond:
the radix select of :func:`_channel_medians`)."""


def _integer_channel_medians(x: np.ndarray, center: np.ndarray | None) -> np.ndarray | None:
    """:func:`_channel_medians` of integers ``x (M, C)`` from each channel's histogram.

    An integer's median is one integer or the mean of two, and its absolute
    deviations from it are integers or half-integers: their histogram (of
    ``2 |x − center|`` for the deviations) gives the order statistics exactly,
    in one pass, and their mean is numpy's to the bit (float64 holds them
    exactly). ``None`` where the values span more than :data:`_MAX_INTEGER_BINS`
    or ``center`` is not a whole or half number (the caller's radix select then).
    Measured (2026-12-07, 2816×2112×3 int16 excess planes, 2 cores): the
    median and the median absolute deviation of a plane 164 → 57 ms.
    """
    m, n_ch = x.shape
    lo, hi = int(x.min()), int(x.max())
    if center is None:
        n_bins, offset, cen2 = hi - lo + 1, lo, np.empty(0, dtype=np.int64)
    else:
        cen = np.asarray(center, dtype=np.float64)
        if not np.all(np.isfinite(cen)) or np.any(2 * cen != np.round(2 * cen)):
            return None
        cen2 = np.round(2 * cen).astype(np.int64)
        n_bins = int(np.abs(2 * np.array([lo, hi])[:, None] - cen2[None]).max()) + 1
        offset = 0
    if n_bins > _MAX_INTEGER_BINS:
        return None
    counts = channel_histograms(x, offset, n_bins, None if center is None else cen2)
    k_lo, k_hi = (m - 1) // 2, m // 2
    out = np.empty(n_ch)
    for c in range(n_ch):
        cum = np.cumsum(counts[c])
        key_lo = int(np.searchsorted(cum, k_lo, side="right"))
        key_hi = int(np.searchsorted(cum, k_hi, side="right"))
        if center is None:
            a, b = float(key_lo + offset), float(key_hi + offset)
        else:
            a, b = key_lo / 2, key_hi / 2
        # numpy's median: the mean of the middle two (even M) or the middle one alone
        out[c] = a if k_lo == k_hi else float(np.mean([a, b]))
    return out


def _ring_rank_fast(image: np.ndarray, rank: int) -> np.ndarray:
    """:func:`_ring_rank`, with a compiled kernel when numba is there (the same values).

    An order statistic is one of its inputs, so both give the same bits
    (:mod:`tests.photoquant.test_defects` checks it). Measured 2026-12-01 on
    a 768×1024×3 float64 image (the shared 2-core machine, loaded): scipy's
    ``rank_filter`` with the 8-pixel ring 270 ms, this kernel about 30 ms
    (6 ms since it runs along rows, quiet machine, 2026-12-02); the
    hot-pixel test runs it once per short exposure of every view.
    """
    if _ring_rank_nb is None or image.ndim != 3:
        return _ring_rank(image, rank)
    src = np.ascontiguousarray(image)
    out = np.empty_like(src)
    # bands of rows on threads (the kernel releases the GIL; each row reads its
    # neighbours in the whole image): the same values for any split
    h = src.shape[0]
    bands = _row_bands(h, src.nbytes)
    thread_map(lambda band: _ring_rank_nb(src, int(rank), out, *band), bands)
    return out


def _row_bands(height: int, nbytes: int) -> list[tuple[int, int]]:
    """Row ranges splitting an image among the CPUs (one band below about 1 MB)."""
    n = max(1, min(default_workers(), nbytes // (1 << 20), height))
    edges = np.linspace(0, height, n + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def _ring_median(image: np.ndarray) -> np.ndarray:
    return ndimage.median_filter(image, footprint=_RING[..., None], mode="mirror")


def _ring_median_at(image: np.ndarray, where: np.ndarray) -> np.ndarray:
    """:func:`_ring_median` of ``image (H, W, C)`` at the ``where`` pixels only (1-d, in order).

    scipy's median of the 8 neighbours is their 5th smallest (rank
    ``8 // 2``); the same value, gathered with the same mirrored edges, for
    the few pixels that need it (the stuck candidates) instead of the image.
    """
    ii, jj, cc = np.nonzero(where)
    h, w = image.shape[:2]
    ring = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di, dj) != (0, 0)]
    vals = np.stack(
        [image[mirror_index(ii + di, h), mirror_index(jj + dj, w), cc] for di, dj in ring], axis=-1
    )
    return np.sort(vals, axis=-1)[..., 4]


_KEEP_EXCESS_BYTES = 256 * 2**20
"""Excess planes kept between the two passes of the hot test (beyond: recomputed)."""


def _plane_means(stack: ExposureStack) -> Any:
    """``mean(k)``: ``stack.mean()[k]`` to the last bit, one plane at a time.

    The stack's cached means when it has them; else the plane of its repeat
    sums over ``N`` (what :meth:`ExposureStack.mean` computes for the whole
    stack) or, for one repeat, the frame as float64: no ``(K, H, W, C)``
    float64 array for a scene stack that is only corrected.
    """
    if stack._mean:
        full = stack._mean[0]
        return lambda k: full[k]
    if stack.n_repeats == 1:
        frames = stack.frames[0]
        return lambda k: frames[k].astype(np.float64)
    sums = stack.repeat_sum()
    n = stack.n_repeats
    return lambda k: sums[k] / n


def _excess_planes(stack: ExposureStack, mean: Any, rank: int) -> Any:
    """``excess(k)``: the repeat mean of exposure ``k`` less its ring rank (the hot test).

    One repeat of integer frames: the frame is its own mean and the ring's
    rank one of its values, so the excess is an integer, computed from the
    frame in its own dtype and held as ``int16`` (8-bit frames) or ``int32``:
    the same numbers as the float64 planes, at a quarter or half their memory
    (the kept planes fit the budget) and their robust spread from a histogram
    (:func:`_integer_channel_medians`), compared with their thresholds in their
    own dtype (:func:`_greater_level`). Measured (2026-12-07, the St. Louis
    Arch's four 2816×2112 JPEG frames, 2 cores, min of two): the defect search
    2.42 → 0.54 s, the same map (the float64 planes did not fit the kept
    planes' budget: three of four were computed twice). Otherwise float64
    planes of ``mean(k)``.
    """
    frames = stack.frames
    if stack.n_repeats == 1 and frames.dtype.kind in "iu" and frames.dtype.itemsize <= 2:
        kind = np.int16 if frames.dtype.itemsize == 1 else np.int32
        return lambda k: np.subtract(frames[0, k], _ring_rank_fast(frames[0, k], rank), dtype=kind)
    return lambda k: mean(k) - _ring_rank_fast(mean(k), rank)


def _greater_level(values: np.ndarray, level: Any) -> Any:
    """``level`` for ``values > level``, in the values' dtype where they are integers:
    ``⌊level⌋`` (``x > t ⟺ x > ⌊t⌋`` for an integer ``x``), at most the dtype's largest
    value. The same booleans, without casting every value to float64 for the
    comparison; ``level`` itself where its floor lies below the dtype's range."""
    if values.dtype.kind not in "iu":
        return level
    info = np.iinfo(values.dtype)
    floor = np.floor(level)
    if np.any(floor < info.min):
        return level
    return np.minimum(floor, info.max).astype(values.dtype)


def _below_clip(stack: ExposureStack, mean: Any) -> Any:
    """``below(k)``: ``stack.mean()[k] < saturation_level − 0.5`` per value (bool).

    For integer repeats without cached means, the integer sums (one repeat:
    the frame itself) are compared instead, with ``sum < ⌈N·(s − ½)⌉``: the same booleans (for an
    integer sum ``S``, ``S < x ⟺ S < ⌈x⌉``; and ``S/N`` rounds to below ``s −
    ½`` exactly when ``S < N·(s − ½)``, which lies at least ``1/(2N)`` from any
    ``S/N``, far above a rounding error), with no float64 plane made for the
    exposures the hot test does not use (6 of 8 at the paper's settings:
    ~16 ms a stack). Integer saturation levels only (the detected ones are);
    else the means are compared.
    """
    sat = np.asarray(stack.saturation_level, dtype=np.float64)
    n = stack.n_repeats
    integral = bool(np.all(sat == np.round(sat))) and float(sat.max()) * n < 2.0**52
    if stack._mean or not integral or stack.frames.dtype.kind not in "iu":
        return lambda k: _compare_per_channel(np.less, mean(k), sat - 0.5)
    limit = np.ceil(n * (sat - 0.5)).astype(np.int64)
    # one repeat: the frames themselves are the sums (compared in their own dtype)
    sums = stack.integer_sums()
    return lambda k: _compare_per_channel(np.less, sums[k], limit)


def _one_stack(
    stack: ExposureStack,
    hot_sigmas: float,
    hot_min_dn: float,
    hot_min_exposures: int,
    stuck_min_change_dn: float,
    hot_rank: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(hot, not_hot, stuck, not_stuck)`` of one stack; neither: the stack cannot tell."""
    black = np.asarray(stack.black_level, dtype=np.float64)
    sat = np.asarray(stack.saturation_level, dtype=np.float64)
    # every frame's extremes: of the per-repeat extremes the stack keeps (cached, shared
    # with its saturation and dark masks), not another pass over the (N, K) frames
    rep_lo, rep_hi = stack._repeat_extremes()
    lo, hi = rep_lo.min(axis=0), rep_hi.max(axis=0)
    order = np.argsort(stack.exposure_s)
    mean = _plane_means(stack)  # mean(k): the repeat mean of exposure k, stack.mean()[k]
    excess_of = _excess_planes(stack, mean, hot_rank)
    not_stuck = lo != hi
    # per-channel thresholds compared along whole rows (_compare_per_channel), not in
    # numpy's broadcast inner loops of length C: the same booleans, 5-6× faster
    stuck = (lo == hi) & _compare_per_channel(np.greater, lo, black)
    stuck &= _compare_per_channel(np.less, lo, sat)
    if stack.n_exposures >= 2:
        # the neighbours' medians only where a pixel is a candidate (few): the same
        # values as the filtered images (_ring_median) there
        if stuck.any():
            change = np.abs(
                _ring_median_at(mean(order[-1]), stuck) - _ring_median_at(mean(order[0]), stuck)
            )
            stuck[stuck] = change > stuck_min_change_dn
    else:
        stuck[:] = False
    # a hot pixel's extra charge is fixed: it stands out most in its shortest unsaturated
    # exposures, where the scene is darkest; the long ones may bury it under the texture
    n_k = stack.n_exposures
    n_short = max(hot_min_exposures, n_k // 3)
    # running count of unsaturated exposures (shortest first): `use` of exposure k is
    # "unsaturated and among the n_short shortest unsaturated" (a cumulative sum, by plane)
    n_unsat = np.zeros(stuck.shape, dtype=np.int16 if n_k < 2**15 else np.int64)
    n_use = np.zeros(stuck.shape, dtype=n_unsat.dtype)
    # Two passes, the same result: the threshold is at least hot_min_dn, so a pixel can
    # be "above" only where its excess beats hot_min_dn in every used exposure
    # (`maybe`); the robust spreads (two image medians per channel and exposure, most of
    # the cost) are computed only when some pixel is still a candidate after all of them.
    maybe = np.ones(stuck.shape, dtype=bool)
    used: list[tuple[int, np.ndarray, np.ndarray | None]] = []
    keep_bytes = 0
    below_clip = _below_clip(stack, mean)
    for k in order:
        unsat_k = below_clip(k)  # repeat mean below the clip
        n_unsat += unsat_k
        use_k = unsat_k & (n_unsat <= n_short)
        n_use += use_k
        if not use_k.any():
            continue
        excess = excess_of(k)
        maybe &= (excess > _greater_level(excess, hot_min_dn)) | ~use_k
        keep = keep_bytes + excess.nbytes <= _KEEP_EXCESS_BYTES
        keep_bytes += excess.nbytes if keep else 0
        used.append((int(k), use_k, excess if keep else None))
    above = np.zeros(stuck.shape, dtype=bool)
    if maybe.any() and used:
        above[:] = True
        for k, use_k, kept in used:
            excess = excess_of(k) if kept is None else kept
            # per channel 1.4826 · median(|e − median(e)|), all channels in each pass
            flat = excess.reshape(-1, excess.shape[-1])
            spread = 1.4826 * _channel_medians(flat, _channel_medians(flat))
            thr = _greater_level(excess, np.maximum(hot_min_dn, hot_sigmas * spread))
            above &= _compare_per_channel(np.greater, excess, thr) | ~use_k
    elif not used:
        above[:] = True  # no exposure used: "above" in none is vacuous (never told)
    told = n_use >= hot_min_exposures
    hot = above & told & ~stuck
    return hot, told & ~above, stuck, not_stuck


def detect_defects(
    stacks: ExposureStack | Sequence[ExposureStack],
    *,
    hot_sigmas: float = 8.0,
    hot_min_dn: float = 4.0,
    hot_min_exposures: int = 2,
    stuck_min_change_dn: float = 2.0,
    hot_rank: int | None = None,
) -> DefectMap:
    """Find hot and stuck pixels in one or more stacks of the same sensor.

    Parameters
    ----------
    stacks : ExposureStack or sequence of ExposureStack
        Bracketed captures of the same image size (e.g. the calibration
        views); a pixel is flagged where one stack flags it and none clears it.
    hot_sigmas : float
        Hot threshold in robust standard deviations of the excess over the
        neighbours' maximum (8: a clean pixel's chance of passing it in two
        exposures is far below 1e-10 for Gaussian noise).
    hot_min_dn : float
        Smallest excess (DN) that counts as hot, whatever the noise.
    hot_min_exposures : int
        Unsaturated exposures a hot pixel must stand out in.
    stuck_min_change_dn : float
        How much the neighbours' median must change between the shortest and
        the longest exposure for a constant pixel to count as stuck.
    hot_rank : int, optional
        A hot pixel exceeds the ``hot_rank``-th largest of its 8 neighbours
        (1: all of them). Default: 4 with several stacks (a hot pixel beside
        a scene edge has up to 3 bright neighbours; a scene corner that
        passes in one view does not in the others, shifted), 1 with one stack
        (a bright region's corner pixel has 3 bright neighbours).

    Returns
    -------
    DefectMap

    Examples
    --------
    >>> import numpy as np
    >>> from photoquant.stack import ExposureStack
    >>> t = np.array([1e-3, 4e-3, 16e-3])
    >>> frames = np.broadcast_to((t * 5e3)[None, :, None, None, None], (2, 3, 8, 8, 1))
    >>> frames = np.rint(frames).astype(np.uint8)
    >>> frames[:, :, 3, 4, 0] = 77  # stuck
    >>> frames[:, :, 5, 2, 0] += 60  # hot
    >>> d = detect_defects(ExposureStack(frames, t, bit_depth=8, channels=("Y",)))
    >>> np.argwhere(d.stuck[..., 0]).tolist(), np.argwhere(d.hot[..., 0]).tolist()
    ([[3, 4]], [[5, 2]])
    """
    seq = [stacks] if isinstance(stacks, ExposureStack) else list(stacks)
    if not seq or not all(isinstance(s, ExposureStack) for s in seq):
        raise InputError("`stacks` must be an ExposureStack or a non-empty sequence of them")
    shape = seq[0].frames.shape[2:]
    if any(s.frames.shape[2:] != shape for s in seq):
        raise InputError("`stacks` must all have the same image size and channels")
    hs = check_positive(hot_sigmas, "hot_sigmas")
    hm = check_positive(hot_min_dn, "hot_min_dn", allow_zero=True)
    sc = check_positive(stuck_min_change_dn, "stuck_min_change_dn", allow_zero=True)
    if isinstance(hot_min_exposures, bool) or not isinstance(hot_min_exposures, int | np.integer):
        raise InputError(f"`hot_min_exposures` must be an integer, got {hot_min_exposures!r}")
    if hot_min_exposures < 1:
        raise InputError(f"`hot_min_exposures` must be at least 1, got {hot_min_exposures}")
    rank = (4 if len(seq) > 1 else 1) if hot_rank is None else hot_rank
    if isinstance(rank, bool) or not isinstance(rank, int | np.integer) or not 1 <= rank <= 8:
        raise InputError(f"`hot_rank` must be an integer in [1, 8], got {hot_rank!r}")
    hot = np.zeros(shape, dtype=bool)
    stuck = np.zeros(shape, dtype=bool)
    not_hot = np.zeros(shape, dtype=bool)
    not_stuck = np.zeros(shape, dtype=bool)
    # one stack per thread (numpy and the numba kernels release the GIL); the union does
    # not depend on the order (paper's settings, 3 views: 0.55 -> 0.38 s on 2 cores,
    # measured 2026-12-02)
    per_stack = thread_map(
        lambda s: _one_stack(s, hs, hm, int(hot_min_exposures), sc, int(rank)), seq
    )
    for h, nh, st, nst in per_stack:
        hot |= h
        not_hot |= nh
        stuck |= st
        not_stuck |= nst
    stuck &= ~not_stuck
    return DefectMap(hot=hot & ~not_hot & ~stuck, stuck=stuck)


def exclude_defects(merged: Any, defects: DefectMap | None) -> Any:
    """A merge result (:class:`photoquant.merge.MergeResult`) with the defects flagged.

    Flagged pixels get the merge's own treatment of a pixel without a valid
    exposure: ``mask`` set, ``log_photoquantity`` NaN, ``weight_sum`` 0, so
    that every later step (sensor LUT, vignetting, balance, correction)
    leaves them out. Their ``all_saturated`` and ``all_dark`` flags are
    cleared: a stuck or hot pixel's value is not light, so it says nothing of
    a source too bright (or a shadow too dark) for the exposures. ``None`` or
    an empty map returns ``merged`` unchanged.
    """
    if defects is None or not defects.mask.any():
        return merged
    bad = defects.mask
    if bad.shape != merged.mask.shape:
        raise InputError(
            f"the defect map has shape {bad.shape}, the merged image {merged.mask.shape}"
        )
    return dataclasses.replace(
        merged,
        log_photoquantity=np.where(bad, np.nan, merged.log_photoquantity),
        mask=merged.mask | bad,
        all_saturated=merged.all_saturated & ~bad,
        all_dark=merged.all_dark & ~bad,
        weight_sum=np.where(bad, 0.0, merged.weight_sum),
        report={**merged.report, "defects": defects.report()},
    )


def hide_defects(
    stack: ExposureStack, defects: DefectMap | None, level: np.ndarray | None = None
) -> ExposureStack:
    """``stack`` with its defects at the saturation level in every frame: no response sample.

    A pixel saturated in every frame carries no information to a response
    method (zero weight, never sampled), which is what a defect should be
    for the response fit; its histogram-based sampling would otherwise pick
    hot pixels first, as the rarest bright values. The saturation and black
    levels are kept. ``level`` (per channel): the clipping level to hide
    them at, where a step judges values against another one than the
    stack's (a response's). Returns ``stack`` itself when there is nothing
    to hide.
    """
    if defects is None or not defects.mask.any():
        return stack
    bad = defects.mask
    if bad.shape != stack.frames.shape[2:]:
        raise InputError(
            f"the defect map has shape {bad.shape}, the stack {stack.frames.shape[2:]}"
        )
    sat = np.asarray(stack.saturation_level if level is None else level)
    frames = np.where(bad[None, None], sat.astype(stack.frames.dtype), stack.frames)
    return stack.with_frames(frames)
