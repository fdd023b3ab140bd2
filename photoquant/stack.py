"""Exposure stacks: repeated frames at several exposure times, and their denoising.

A capture of one static scene is a stack of frames ``(N, K, H, W, C)``: ``N``
repeats of each of ``K`` exposure times, images of ``H`` rows, ``W`` columns and
``C`` channels, holding integer pixel values in ``[0, 2**bit_depth - 1]``.

Pixel values sit on a per-channel *black level* ``b`` (the offset of raw and
machine-vision data: the value of a pixel that received no light, 0 for most
8-bit images): the signal is ``c - b``, a value at or below ``b`` carries no
measurable light (:meth:`ExposureStack.dark_clipped`), and the usable range of
a channel is ``(b, saturation_level)``.

Denoising averages the ``N`` repeats (eq. 2 of the reference paper); a pixel
value is treated as *saturated* when any of its repeats reached the channel's
saturation level, because the mean of partly clipped samples is biased.

References
----------
.. [PQ] The photoquantity paper: eq. 1 (model),
   eq. 2 (denoising), appendix A (1/sqrt(N) noise reduction).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoquant._checks import (
    check_array,
    check_bit_depth,
    check_choice,
    check_exposure_times,
    check_int,
    default_workers,
)
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._threads import even_spans, thread_map
from photoquant.errors import InputError

__all__ = [
    "EXPOSURE_BASES",
    "ExposureStack",
    "denoise_mean",
    "detect_saturation_levels",
]


#: What ``ExposureStack.exposure_s`` measures: seconds of exposure, or the
#: relative exposure value ``t · (S / 100) / N²`` (ISO speed ``S``, f-number
#: ``N``) when the aperture or the gain varies across the bracket.
EXPOSURE_BASES = ("time", "exposure value")


def denoise_mean(frames: np.ndarray) -> np.ndarray:
    """Average the ``N`` repeats of a stack, eq. 2 of [PQ].

    Parameters
    ----------
    frames : ndarray, shape (N, K, H, W, C)
        Integer or float pixel values.

    Returns
    -------
    ndarray, shape (K, H, W, C), float64
        The denoised values ``c̄_pkλ = (1/N) Σ_n c_pkλn``.

    Notes
    -----
    The standard deviation of the mean drops as ``σ/√N`` (appendix A of [PQ]).
    """
    frames = check_array(frames, "frames", ndim=5, kind="iuf")
    if frames.shape[0] == 1:
        return frames[0].astype(np.float64)
    return frames.mean(axis=0, dtype=np.float64)


# ---------------------------------------------------------------------------
# compiled kernels (numba, optional): one pass over the frames, the same values
# as the numpy paths (integers, no rounding); measured 2026-12-01 on a
# 1024×768×3, N = 10, K = 8 uint8 stack (the shared 2-core machine, loaded):
# detect_saturation_levels 0.07 s of CPU against 0.23 (a histogram by scattered
# increments instead: 0.12 s for its pass alone), the repeat sums and extremes in
# one pass instead of three
# ---------------------------------------------------------------------------


def _pile_counts_py(
    rows: Any, top_row: Any, low_row: Any, pile: Any, near: Any
) -> None:  # pragma: no cover
    """numba body: per row position, the values at ``top_row`` and in ``[low_row, top_row)``.

    ``rows (R, W·C)`` with per-position thresholds (a channel's, tiled over
    the row): branch-free counts that vectorise, one pass. The counts go to
    one-byte accumulators for blocks of 255 rows (32 lanes of a vector
    register instead of 4 int64 ones: 8× faster, 11 → 1.5 ms for a
    1024×768×3, K = 8 stack), added to ``pile`` and ``near`` after each block.
    """
    n_r, m = rows.shape
    pile8 = np.zeros(m, dtype=np.uint8)
    near8 = np.zeros(m, dtype=np.uint8)
    for r0 in range(0, n_r, 255):
        for r in range(r0, min(r0 + 255, n_r)):
            for q in range(m):
                v = rows[r, q]
                t = top_row[q]
                pile8[q] += np.uint8(v == t)
                near8[q] += np.uint8((v >= low_row[q]) & (v < t))
        for q in range(m):
            pile[q] += pile8[q]
            near[q] += near8[q]
            pile8[q] = 0
            near8[q] = 0


def _repeat_stats_py(frames: Any, total: Any, lo: Any, hi: Any) -> None:  # pragma: no cover
    """numba body: per value of ``frames (N, M)``, the sum, lowest and highest repeat."""
    n_rep, m = frames.shape
    for i in range(m):
        f = frames[0, i]
        total[i] = f
        lo[i] = f
        hi[i] = f
    for r in range(1, n_rep):
        for i in range(m):
            f = frames[r, i]
            total[i] += f
            lo[i] = min(lo[i], f)
            hi[i] = max(hi[i], f)


def _gather_by_channel_py(
    frames: Any,
    sums: Any,
    lo: Any,
    hi: Any,
    index: Any,
    n_rep: float,
    sat_thr: Any,
    dark_thr: Any,
    values: Any,
    excluded: Any,
    start: int,
    stop: int,
) -> None:  # pragma: no cover
    """numba body: at pixels ``index[start:stop]``, ``values (C, K, P)`` = the repeats'
    sum / ``n_rep`` and ``excluded (C, K, P)`` = a repeat at or above ``sat_thr`` or at
    or below ``dark_thr``; from the cached ``sums, lo, hi (K, M, C)`` when ``frames``
    is empty (``(0, K, M, C)``), else from ``frames (N, K, M, C)``."""
    n_c = values.shape[0]
    n_k = values.shape[1]
    from_frames = frames.shape[0] > 0
    for k in range(n_k):
        for i in range(start, stop):
            q = index[i]
            for c in range(n_c):
                if from_frames:
                    f = frames[0, k, q, c]
                    total = np.int64(f)
                    low = f
                    high = f
                    for r in range(1, frames.shape[0]):
                        f = frames[r, k, q, c]
                        total += f
                        low = min(low, f)
                        high = max(high, f)
                else:
                    total = np.int64(sums[k, q, c])
                    low = lo[k, q, c]
                    high = hi[k, q, c]
                values[c, k, i] = total / n_rep
                excluded[c, k, i] = (high >= sat_thr[c]) or (low <= dark_thr[c])


def _frame_extremes_py(
    flat: Any, lo: Any, hi: Any, start: int, stop: int
) -> None:  # pragma: no cover
    """numba body: per position ``i`` in ``[start, stop)`` of ``flat (F, M)``, the lowest and
    highest of its ``F`` frames, into ``lo`` and ``hi``.

    Blocks of 16 384 positions, each frame's block in turn: the block's
    extremes stay in the core's cache while the frames stream through once.
    One-dimensional slices and comparisons, which vectorise (indexing the
    two-dimensional array in the inner loop did not: 8× slower).
    """
    n_f = flat.shape[0]
    for b0 in range(start, stop, 16384):
        b1 = min(b0 + 16384, stop)
        lo_b = lo[b0:b1]
        hi_b = hi[b0:b1]
        row = flat[0, b0:b1]
        for i in range(b1 - b0):
            lo_b[i] = row[i]
            hi_b[i] = row[i]
        for f in range(1, n_f):
            row = flat[f, b0:b1]
            for i in range(b1 - b0):
                v = row[i]
                if v < lo_b[i]:
                    lo_b[i] = v
                if v > hi_b[i]:
                    hi_b[i] = v


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    _frame_extremes_nb = compile_kernel(_frame_extremes_py)
    _gather_by_channel_nb = compile_kernel(_gather_by_channel_py)
    _pile_counts_nb = compile_kernel(_pile_counts_py)
    _repeat_stats_nb = compile_kernel(_repeat_stats_py)


def _pile_counts(
    rows: np.ndarray, top: np.ndarray, low: np.ndarray, n_ch: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """Per channel: values at ``top`` and in ``[low, top)``, or None without numba."""
    if not HAVE_NUMBA or not rows.flags.c_contiguous or rows.dtype.kind not in "iu":
        return None
    reps = rows.shape[1] // n_ch
    pile = np.zeros(rows.shape[1], dtype=np.int64)
    near = np.zeros(rows.shape[1], dtype=np.int64)
    top_row = np.tile(top.astype(rows.dtype), reps)
    low_row = np.tile(low.astype(rows.dtype), reps)
    _pile_counts_nb(rows, top_row, low_row, pile, near)
    return pile.reshape(-1, n_ch).sum(axis=0), near.reshape(-1, n_ch).sum(axis=0)


def detect_saturation_levels(
    frames: np.ndarray,
    bit_depth: int,
    *,
    min_fraction: float = 1e-4,
    min_count: int = 3,
    pile_up_ratio: float = 4.0,
) -> np.ndarray:
    """Detect the level at which each channel clips, from a pile-up at its maximum.

    Real cameras often clip a channel below the nominal ``2**bit_depth - 1``
    (the white level of a raw file, or white balance applied after clipping).
    Clipped pixels then pile up at one value, the channel's maximum.

    Parameters
    ----------
    frames : ndarray, shape (..., C)
        Integer pixel values, channels last.
    bit_depth : int
        Nominal bit depth, 8 to 16.
    min_fraction, min_count : float, int
        A pile-up must hold at least ``max(min_count, min_fraction * n)`` of the
        channel's ``n`` values ...
    pile_up_ratio : float
        ... and at least ``pile_up_ratio`` times the mean count of the levels
        just below it.

    Returns
    -------
    ndarray, shape (C,), int64
        Per channel: the maximum value when it piles up (or equals the nominal
        maximum), otherwise the nominal maximum ``2**bit_depth - 1`` (the
        data never clip, so nothing is treated as saturated before it). A
        channel whose every value is 0 (no light at all) has nothing that
        clips either: the nominal maximum.
    """
    bit_depth = check_bit_depth(bit_depth)
    frames = check_array(frames, "frames", kind="iu")
    levels = _detect_saturation_levels(frames, bit_depth, min_fraction, min_count, pile_up_ratio)
    levels[levels < 1] = 2**bit_depth - 1  # a pile at 0 is black, not clipping
    return levels


def _detect_saturation_levels(
    frames: np.ndarray, bit_depth: int, min_fraction: float, min_count: int, pile_up_ratio: float
) -> np.ndarray:
    """:func:`detect_saturation_levels` on checked input, a pile at 0 included."""
    c_max = 2**bit_depth - 1
    n_ch = frames.shape[-1]
    levels = np.full(n_ch, c_max, dtype=np.int64)
    rows = _channel_rows(frames)
    extremes = _frame_extremes(frames)
    if extremes is not None:
        # one pass gives every channel's maximum and the constant pixels
        lo, hi = extremes
        top = _channel_reduce(np.maximum, _channel_rows(hi), n_ch).astype(np.int64)
        stuck = _stuck_from_extremes(lo, hi, min_count)
    else:
        top = _channel_reduce(np.maximum, rows, n_ch).astype(np.int64)
        stuck = _stuck_pixels(frames, min_count)
    span = max(2, (c_max + 1) // 64)
    if stuck is not None and stuck.any():
        return _saturation_levels_without_stuck(
            frames, stuck, c_max, span, min_fraction, min_count, pile_up_ratio
        )
    check = np.flatnonzero(top < c_max)
    if check.size == 0:
        return levels
    counted = _pile_counts(rows, top, np.maximum(top - span, 0), n_ch)
    if counted is not None:
        # the same counts in one compiled pass: the pile at the maximum and the values
        # in the span below it (whose mean per level is the numpy path's, levels below
        # 0 counting 0)
        n_values = rows.size // n_ch
        for ch in check:
            pile = counted[0][ch]
            below = counted[1][ch] / span
            if pile >= max(min_count, min_fraction * n_values) and pile >= pile_up_ratio * below:
                levels[ch] = top[ch]
        return levels
    # per checked channel: the count of its maximum (the pile), and a histogram of the
    # values just below it (few), in chunks of rows (bounded memory, no length-C loops)
    reps = rows.shape[1] // n_ch
    checked = np.zeros(n_ch, dtype=bool)
    checked[check] = True
    chk_row = np.tile(checked, reps)
    top_row = np.tile(top.astype(rows.dtype), reps)
    low_row = np.tile(np.maximum(top - span, 0).astype(rows.dtype), reps)
    counts = np.zeros((n_ch, span + 1), dtype=np.int64)
    pile_row = np.zeros(rows.shape[1], dtype=np.int64)
    step = max(1, (1 << 22) // rows.shape[1])
    for r in range(0, rows.shape[0], step):
        chunk = rows[r : r + step]
        at_top = (chunk == top_row) & chk_row
        pile_row += at_top.sum(axis=0)
        below = (chunk >= low_row) & (chunk < top_row) & chk_row
        near = np.flatnonzero(below)
        ch_of = near % n_ch  # rows hold whole pixels: the channel is the position mod C
        bins = ch_of * (span + 1) + (chunk.reshape(-1)[near].astype(np.int64) - (top - span)[ch_of])
        counts += np.bincount(bins, minlength=n_ch * (span + 1)).reshape(n_ch, span + 1)
    counts[:, -1] = pile_row.reshape(-1, n_ch).sum(axis=0)
    n_values = rows.size // n_ch
    for ch in check:
        pile = counts[ch, -1]
        below = counts[ch, :-1].mean()
        if pile >= max(min_count, min_fraction * n_values) and pile >= pile_up_ratio * below:
            levels[ch] = top[ch]
    return levels


def _channel_rows(a: np.ndarray) -> np.ndarray:
    """``a (..., W, C)`` as rows of ``W·C`` values (a view when it can be, else a copy).

    Per-channel operations on the rows use a threshold row ``np.tile(x, W)``
    and run over long contiguous rows, not numpy's inner loops of length C.
    """
    if a.ndim < 2:
        return a.reshape(1, -1)
    return a.reshape(-1, a.shape[-2] * a.shape[-1])


def _channel_reduce(ufunc: np.ufunc, rows: np.ndarray, n_ch: int) -> np.ndarray:
    """Per channel the ``ufunc`` reduction (max, min) of rows from :func:`_channel_rows`."""
    return ufunc.reduce(ufunc.reduce(rows, axis=0).reshape(-1, n_ch), axis=0)


def _compare_per_channel(ufunc: np.ufunc, a: np.ndarray, level: np.ndarray) -> np.ndarray:
    """``ufunc(a, level)`` for ``a (..., W, C)`` and a per-channel ``level (C,)``, bool."""
    rows = _channel_rows(a)
    reps = rows.shape[1] // a.shape[-1]
    level = np.asarray(level)
    if rows.dtype.kind in "iu" and level.dtype.kind in "iu" and level.size:
        # integer levels the frames' dtype holds: compared in that dtype (the same result,
        # without casting every value to int64: 4× faster on uint8 frames)
        info = np.iinfo(rows.dtype)
        if info.min <= level.min() and level.max() <= info.max:
            level = level.astype(rows.dtype)
    return ufunc(rows, np.tile(level, reps)).reshape(a.shape)


def _saturation_levels_without_stuck(
    frames: np.ndarray,
    stuck: np.ndarray,
    c_max: int,
    span: int,
    min_fraction: float,
    min_count: int,
    pile_up_ratio: float,
) -> np.ndarray:
    """:func:`detect_saturation_levels` channel by channel, stuck pixels left out.

    The per-channel reference path, taken only when the stacks hold stuck
    pixels (rare: the vectorised path serves every other stack).
    """
    values = frames.reshape(-1, frames.shape[-1])
    levels = np.full(values.shape[1], c_max, dtype=np.int64)
    for ch in range(values.shape[1]):
        v = values[:, ch]
        if stuck[:, ch].any() and not stuck[:, ch].all():
            # a stuck pixel's frames are no clip (with nothing else left, keep them all)
            v = frames.reshape(-1, stuck.shape[0], frames.shape[-1])[:, ~stuck[:, ch], ch].ravel()
        top = int(v.max())
        if top >= c_max:
            continue
        counts = np.bincount(v[v >= top - span].astype(np.int64) - (top - span), minlength=span + 1)
        pile = counts[-1]
        below = counts[:-1].mean()
        if pile >= max(min_count, min_fraction * v.size) and pile >= pile_up_ratio * below:
            levels[ch] = top
    return levels


def _stuck_pixels(frames: np.ndarray, min_count: int) -> np.ndarray | None:
    """``(H·W, C)`` bool: pixels stuck at a value of their own, or None (fewer than 2 frames).

    A stuck pixel (:mod:`photoquant.defects`) holds one value in every frame;
    its ``N·K`` equal values would pass for a pile-up at a clip. A pixel
    clipped in every frame is constant too, but at a value many pixels share,
    so only constant pixels whose value fewer than ``min_count`` constant
    pixels hold are left out of the pile-up count.
    """
    if frames.ndim != 5 or frames.shape[0] * frames.shape[1] < 2:
        return None
    flat = frames.reshape(frames.shape[0] * frames.shape[1], -1, frames.shape[-1])
    return _stuck_from_extremes(flat.min(axis=0), flat.max(axis=0), min_count)


def _frame_extremes(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The lowest and highest value of each position ``(H, W, C)`` over the ``N·K`` frames
    of a stack, in one compiled pass on threads; None where that is not taken (no numba,
    not a C-contiguous integer ``(N, K, H, W, C)`` array of two frames or more).

    The same integers as ``frames.min(axis=(0, 1))`` and ``.max(axis=(0, 1))``, which
    take a pass each (measured on the Intel machine, 2026-12-07, a 1024×768×3, N = 10,
    K = 8 uint8 stack: the maximum per channel and the two extremes 82–87 ms, this pass
    on two threads 19–23 ms; the saturation levels' detection 105–109 → 45–52 ms).
    """
    if (
        not HAVE_NUMBA
        or frames.ndim != 5
        or frames.shape[0] * frames.shape[1] < 2
        or not frames.flags.c_contiguous
        or frames.dtype.kind not in "iu"
    ):
        return None
    flat = frames.reshape(frames.shape[0] * frames.shape[1], -1)
    lo = np.empty(flat.shape[1], dtype=frames.dtype)
    hi = np.empty(flat.shape[1], dtype=frames.dtype)
    # each position is written by one thread: the same values for any split
    spans = even_spans(flat.shape[1], min(default_workers(), 1 + flat.shape[1] // 65536))
    thread_map(lambda span: _frame_extremes_nb(flat, lo, hi, span.start, span.stop), spans)
    shape = frames.shape[2:]
    return lo.reshape(shape), hi.reshape(shape)


def _stuck_from_extremes(lo: np.ndarray, hi: np.ndarray, min_count: int) -> np.ndarray | None:
    """:func:`_stuck_pixels` from each position's lowest and highest value over the frames
    (``(..., C)``, any leading shape)."""
    n_ch = lo.shape[-1]
    lo, hi = lo.reshape(-1, n_ch), hi.reshape(-1, n_ch)
    const = lo == hi
    if not const.any():
        return None
    out = np.zeros(const.shape, dtype=bool)
    for ch in range(const.shape[1]):
        vals, inv, counts = np.unique(lo[const[:, ch], ch], return_inverse=True, return_counts=True)
        out[const[:, ch], ch] = counts[inv] < min_count
    return out


@dataclass(frozen=True, eq=False)
class ExposureStack:
    """Frames of one static scene at ``K`` exposure times, ``N`` repeats each.

    Parameters
    ----------
    frames : ndarray, shape (N, K, H, W, C)
        Integer pixel values in ``[0, 2**bit_depth - 1]``.
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds: finite, positive and unique. The stack is
        reordered by increasing exposure time.
    bit_depth : int
        Bits per value, 8 to 16.
    saturation_level : ndarray, shape (C,), optional
        Per-channel clipping level. Detected from the data
        (:func:`detect_saturation_levels`) when not given.
    channels : tuple of str
        Channel names, ``("R", "G", "B")`` by default.
    black_level : array_like, shape (C,), optional
        Per-channel black level (the value of a pixel that received no light),
        0 by default; float64, ``0 <= b < saturation_level`` per channel. The
        linear signal is ``c - b``.
    exposure_basis : {"time", "exposure value"}
        What ``exposure_s`` holds: exposure times in seconds (default), or the
        relative exposure value ``t · (S / 100) / N²`` of a bracket whose ISO
        speed ``S`` or f-number ``N`` varies (still proportional to the light
        collected per unit photoquantity, which is all the method needs).

    Raises
    ------
    InputError
        If any field is invalid, including a black level at or above the
        saturation level or *above the data*: more than half of the longest
        exposure's values of a channel at or below its (non-zero) black level,
        which no real bracket does and a mislabelled black level does.
    """

    frames: np.ndarray
    exposure_s: np.ndarray
    bit_depth: int = 8
    saturation_level: np.ndarray | None = None
    channels: tuple[str, ...] = ("R", "G", "B")
    black_level: np.ndarray | None = None
    exposure_basis: str = "time"
    _mean: list = field(default_factory=list, init=False, repr=False)
    _sum: list = field(default_factory=list, init=False, repr=False)
    _extremes: list = field(default_factory=list, init=False, repr=False)
    _masks: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        frames = check_array(self.frames, "frames", ndim=5, kind="iu")
        bit_depth = check_bit_depth(self.bit_depth)
        t = check_exposure_times(self.exposure_s)
        if t.size != frames.shape[1]:
            raise InputError(
                f"`exposure_s` has {t.size} times but `frames` has K={frames.shape[1]} "
                f"exposures (frames shape is (N, K, H, W, C) = {frames.shape})"
            )
        c_max = 2**bit_depth - 1
        # unsigned frames cannot be negative; a dtype that cannot exceed c_max needs no scan
        lo = 0 if frames.dtype.kind == "u" else int(frames.min())
        hi = c_max if np.iinfo(frames.dtype).max <= c_max else int(frames.max())
        if lo < 0 or hi > c_max:
            raise InputError(
                f"`frames` values must lie in [0, {c_max}] for bit_depth={bit_depth}, "
                f"got [{lo}, {hi}]"
            )
        channels = tuple(str(c) for c in self.channels)
        if len(channels) != frames.shape[-1]:
            raise InputError(
                f"`channels` names {len(channels)} channels but `frames` has C={frames.shape[-1]}"
            )
        order = np.argsort(t, kind="stable")
        if not np.array_equal(order, np.arange(t.size)):
            frames = frames[:, order]
            t = t[order]
        if self.saturation_level is None:
            sat = detect_saturation_levels(frames, bit_depth)
        else:
            sat = check_array(
                self.saturation_level, "saturation_level", shape=(frames.shape[-1],), kind="iuf"
            ).astype(np.int64)
            if np.any(sat < 1) or np.any(sat > c_max):
                raise InputError(f"`saturation_level` must lie in [1, {c_max}], got {sat.tolist()}")
        black = _check_black_level(self.black_level, frames, sat, c_max, channels)
        check_choice(self.exposure_basis, "exposure_basis", EXPOSURE_BASES)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "exposure_s", t)
        object.__setattr__(self, "bit_depth", bit_depth)
        object.__setattr__(self, "saturation_level", sat)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "black_level", black)

    def with_exposure_times(self, exposure_s: Sequence[float] | np.ndarray) -> ExposureStack:
        """The same frames labelled with other exposure times (e.g. refined ones).

        Parameters
        ----------
        exposure_s : array_like, shape (K,)
            New times, in the order of this stack's exposures (increasing
            nominal time); the result is re-sorted if their order differs.
        """
        out = self.with_frames(self.frames, exposure_s)
        if out.frames is self.frames:  # same frames, same order: the cached statistics hold
            for name in ("_mean", "_sum", "_extremes"):
                getattr(out, name).extend(getattr(self, name))
            out._masks.update(self._masks)
        return out

    def with_frames(
        self, frames: np.ndarray, exposure_s: Sequence[float] | np.ndarray | None = None
    ) -> ExposureStack:
        """Other frames of the same camera: this stack's bit depth, saturation and black
        levels, channels and exposure basis, with ``exposure_s`` (this stack's times by
        default) for the ``K`` exposures of ``frames`` ``(N, K, H, W, C)``."""
        return ExposureStack(
            frames,
            self.exposure_s if exposure_s is None else np.asarray(exposure_s, dtype=np.float64),
            bit_depth=self.bit_depth,
            saturation_level=self.saturation_level,
            channels=self.channels,
            black_level=self.black_level,
            exposure_basis=self.exposure_basis,
        )

    @classmethod
    def from_frames(
        cls,
        frames: Sequence[np.ndarray] | np.ndarray,
        exposure_s: Sequence[float] | np.ndarray,
        **kwargs: Any,
    ) -> ExposureStack:
        """Build a stack from ``K`` images ``(H, W, C)`` (one repeat each) or ``(K, H, W, C)``."""
        arr = np.asarray(frames)
        if arr.ndim == 3:
            arr = arr[..., None]
        if arr.ndim != 4:
            raise InputError(f"`frames` must be (K, H, W, C) images, got shape {arr.shape}")
        return cls(arr[None], np.asarray(exposure_s, dtype=np.float64), **kwargs)

    @property
    def shape(self) -> tuple[int, int, int, int, int]:
        """``(N, K, H, W, C)``."""
        n, k, h, w, c = self.frames.shape
        return int(n), int(k), int(h), int(w), int(c)

    @property
    def n_repeats(self) -> int:
        return int(self.frames.shape[0])

    @property
    def n_exposures(self) -> int:
        return int(self.frames.shape[1])

    @property
    def image_shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return int(self.frames.shape[2]), int(self.frames.shape[3])

    @property
    def n_channels(self) -> int:
        return int(self.frames.shape[4])

    @property
    def c_max(self) -> int:
        """Nominal maximum value ``2**bit_depth - 1``."""
        return 2**self.bit_depth - 1

    def mean(self) -> np.ndarray:
        """Denoised values ``(K, H, W, C)`` float64, eq. 2 (computed once).

        Equal, to the last bit, to :func:`denoise_mean` of the frames
        (``repeat_sum() / N``: the integer sums are exact).
        """
        if not self._mean:
            if self.n_repeats == 1:
                self._mean.append(self.frames[0].astype(np.float64))
            else:
                self._mean.append(self.repeat_sum() / self.n_repeats)
        return self._mean[0]

    def repeat_sum(self) -> np.ndarray:
        """``(K, H, W, C)`` integer sums of the ``N`` repeats, exact (computed once).

        The dtype is the smallest unsigned integer holding ``N · c_max``; the
        merge looks weights and ``g`` up in tables on this grid
        (:func:`photoquant.merge.merge_stack`).
        """
        if not self._sum and not self._fused_repeat_stats():
            self._sum.append(self.frames.sum(axis=0, dtype=self._sum_dtype()))
        return self._sum[0]

    def integer_sums(self) -> np.ndarray:
        """``(K, H, W, C)`` integers whose quotient by ``N`` is :meth:`mean`, to the bit:
        one repeat's frames themselves (their own dtype, no copy), else :meth:`repeat_sum`."""
        return self.frames[0] if self.n_repeats == 1 else self.repeat_sum()

    def _sum_dtype(self) -> type[np.unsignedinteger[Any]]:
        """The smallest unsigned integer holding ``N · c_max``."""
        top = self.n_repeats * self.c_max
        if top > np.iinfo(np.uint32).max:  # pragma: no cover - 65 536 repeats of 16 bits
            return np.uint64
        return np.uint16 if top <= np.iinfo(np.uint16).max else np.uint32

    def _fused_repeat_stats(self) -> bool:
        """Sums and extremes of the repeats in one compiled pass (False: not available).

        The same integers as ``frames.sum/min/max(axis=0)``; taken when numba
        is there, ``N > 1`` and neither is cached yet (the extremes then cost
        no further pass over the frames).
        """
        frames = self.frames
        if (
            not HAVE_NUMBA
            or self.n_repeats == 1
            or self._sum
            or self._extremes
            or not frames.flags.c_contiguous
            or frames.dtype.kind not in "iu"
        ):
            return False
        flat = frames.reshape(frames.shape[0], -1)
        total = np.empty(flat.shape[1], dtype=self._sum_dtype())
        lo = np.empty(flat.shape[1], dtype=frames.dtype)
        hi = np.empty(flat.shape[1], dtype=frames.dtype)
        _repeat_stats_nb(flat, total, lo, hi)
        shape = frames.shape[1:]
        self._sum.append(total.reshape(shape))
        self._extremes.append((lo.reshape(shape), hi.reshape(shape)))
        return True

    def cached_repeat_statistics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(repeat_sum, lowest, highest)`` repeat (K, H, W, C) if already computed, else None.

        Lets a consumer (the merge) read these instead of the ``N`` frames
        without forcing their computation.
        """
        if self.n_repeats > 1 and self._sum and self._extremes:
            return self._sum[0], self._extremes[0][0], self._extremes[0][1]
        return None

    def _repeat_extremes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per value, the lowest and highest of its ``N`` repeats (computed once)."""
        if not self._extremes and not self._fused_repeat_stats():  # sums too, when compiled
            if self.n_repeats == 1:
                self._extremes.append((self.frames[0], self.frames[0]))
            else:
                self._extremes.append((self.frames.min(axis=0), self.frames.max(axis=0)))
        return self._extremes[0]

    def at_pixels(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(repeat_sum, saturated, dark_clipped)`` at some pixels, ``(K, P, C)`` each.

        ``index`` holds flat pixel indices (row-major over ``(H, W)``). The
        same values as :meth:`repeat_sum`, :meth:`saturated` and
        :meth:`dark_clipped` (the stack's own levels) at those pixels, from
        the cached full-size arrays when there are any, else from the frames
        at those pixels only (nothing full-size is made).
        """
        index = np.asarray(index, dtype=np.intp)
        n, k, h, w, c = self.shape
        sat_thr, dark_thr = _sat_threshold(self.saturation_level), _dark_threshold(self.black_level)
        # np.take, not a[:, index]: a fancy index behind a slice returns a transposed
        # (non-contiguous) layout, and every per-channel pass after it would copy
        if self._sum and self._extremes:
            sums = np.take(self._sum[0].reshape(k, h * w, c), index, axis=1)
            lo = np.take(self._extremes[0][0].reshape(k, h * w, c), index, axis=1)
            hi = np.take(self._extremes[0][1].reshape(k, h * w, c), index, axis=1)
        else:
            sub = np.take(self.frames.reshape(n, k, h * w, c), index, axis=2)
            if n == 1:
                sums, lo, hi = sub[0].astype(self._sum_dtype()), sub[0], sub[0]
            else:
                sums = sub.sum(axis=0, dtype=self._sum_dtype())
                lo, hi = sub.min(axis=0), sub.max(axis=0)
        saturated = _compare_per_channel(np.greater_equal, hi, sat_thr)
        dark = _compare_per_channel(np.less_equal, lo, dark_thr)
        return sums, saturated, dark

    def mean_at_pixels(
        self, index: np.ndarray, *, exact_integers: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """The denoised values and their exclusion at some pixels, channel by channel.

        Returns ``(values, excluded)``, each ``(C, K, P)`` and C-contiguous:
        :meth:`mean` and ``saturated() | dark_clipped()`` at the flat pixel
        indices ``index`` (the same bits as :meth:`at_pixels`' sums divided by
        ``N``), laid out for a consumer that reads one channel at a time (the
        response fit). One compiled pass over the pixels when numba is there.

        ``exact_integers``: for a single repeat (a stack's frames are
        integers) the values come in the frames' own dtype (the same numbers as the float64 mean:
        the frames themselves), an eighth of the memory for 8-bit frames;
        float64 means otherwise.
        """
        n, k, h, w, c = self.shape
        index = np.asarray(index)
        if index.ndim != 1 or index.dtype.kind not in "iu":
            raise InputError(
                f"`index` must be a 1-d array of integers, got {index.dtype} {index.shape}"
            )
        if index.size and not (0 <= index.min() and index.max() < h * w):
            raise InputError(f"`index` must lie in [0, {h * w}) (flat pixel indices of {h}×{w})")
        index = index.astype(np.intp, copy=False)
        sat_thr, dark_thr = _sat_threshold(self.saturation_level), _dark_threshold(self.black_level)
        # the frames' own values (a stack's frames are integers): a single repeat
        integers = exact_integers and n == 1
        if not HAVE_NUMBA or self.frames.dtype.kind not in "iu":
            sums, saturated, dark = self.at_pixels(index)
            sums = sums.astype(self.frames.dtype) if integers else sums / self.n_repeats
            return np.ascontiguousarray(np.moveaxis(sums, -1, 0)), np.ascontiguousarray(
                np.moveaxis(saturated | dark, -1, 0)
            )
        values = np.empty((c, k, index.size), dtype=self.frames.dtype if integers else np.float64)
        excluded = np.empty((c, k, index.size), dtype=bool)
        if self._sum and self._extremes:
            sums = self._sum[0].reshape(k, h * w, c)
            lo = self._extremes[0][0].reshape(k, h * w, c)
            hi = self._extremes[0][1].reshape(k, h * w, c)
            frames = np.zeros((0, k, 1, c), dtype=self.frames.dtype)
        else:
            frames = self.frames.reshape(n, k, h * w, c)
            sums = lo = hi = np.zeros((k, 1, c), dtype=self.frames.dtype)
        # each value is written once, by one thread: the result does not depend on them
        spans = even_spans(index.size, min(default_workers(), 1 + index.size // 4096))
        thread_map(
            lambda span: _gather_by_channel_nb(
                frames,
                sums,
                lo,
                hi,
                index,
                float(self.n_repeats),
                sat_thr,
                dark_thr,
                values,
                excluded,
                span.start,
                span.stop,
            ),
            spans,
        )
        return values, excluded

    def saturated(
        self, saturation_level: np.ndarray | None = None, *, stride: int = 1
    ) -> np.ndarray:
        """``(K, H, W, C)`` bool: any repeat reached the channel's saturation level.

        ``saturation_level`` (C,) overrides the stack's own (e.g. a camera
        model's calibrated levels). Computed once per level (read-only).
        ``stride``: the mask of the pixels ``[::stride, ::stride]`` only, a
        view of the memoised mask where there is one, else computed from those
        pixels alone (nothing full-size is made or memoised).
        """
        level = self.saturation_level if saturation_level is None else saturation_level
        level = check_array(level, "saturation_level", shape=(self.n_channels,), kind="iuf")
        return self._mask("saturated", _sat_threshold(level), np.greater_equal, 1, stride)

    def dark_clipped(
        self, floor: float | np.ndarray | None = None, *, stride: int = 1
    ) -> np.ndarray:
        """``(K, H, W, C)`` bool: any repeat at or below the floor (no measurable light).

        Parameters
        ----------
        floor : float or array_like (C,), optional
            Per-channel floor; the stack's :attr:`black_level` by default (0
            for data without an offset, where this is "any repeat is 0").
            Computed once per floor (read-only).
        stride : int
            As :meth:`saturated`.
        """
        level = self.black_level if floor is None else floor
        level = np.broadcast_to(np.asarray(level, dtype=np.float64), (self.n_channels,))
        return self._mask("dark", _dark_threshold(level), np.less_equal, 0, stride)

    def _mask(
        self, kind: str, thr: np.ndarray, ufunc: np.ufunc, extreme: int, stride: int = 1
    ) -> np.ndarray:
        stride = check_int(stride, "stride", 1)
        key = (kind, tuple(int(x) for x in thr))
        if stride > 1 and key not in self._masks:
            # the grid's values only (a sixteenth of the image or less where the noise fit
            # reads it: the full-size masks took 0.4 s of `photoquant correct` of a
            # 6-megapixel bracket)
            if self._extremes:
                values = self._extremes[0][extreme][:, ::stride, ::stride]
            else:
                grid = self.frames[:, :, ::stride, ::stride]
                reduce = np.maximum if extreme else np.minimum
                values = grid[0] if self.n_repeats == 1 else reduce.reduce(grid, axis=0)
            return _compare_per_channel(ufunc, np.ascontiguousarray(values), thr)
        if key not in self._masks:
            mask = _compare_per_channel(ufunc, self._repeat_extremes()[extreme], thr)
            mask.setflags(write=False)
            self._masks[key] = mask
        mask = self._masks[key]
        return mask if stride == 1 else mask[:, ::stride, ::stride]

    def linear_mean(self) -> np.ndarray:
        """Denoised values above the black level, ``mean() - black_level`` (K, H, W, C).

        For linear (raw) data this is proportional to the exposure ``u·v·t·l``
        of eq. 1 of [PQ]; it is negative where noise took a dark pixel below
        the black level.
        """
        assert self.black_level is not None  # set in __post_init__
        return self.mean() - self.black_level


def _sat_threshold(level: Any) -> np.ndarray:
    """Integer threshold of "at or above ``level``": frames are integers, ``c ≥ ⌈level⌉``."""
    return np.ceil(np.asarray(level).astype(np.float64)).astype(np.int64)


def _dark_threshold(level: Any) -> np.ndarray:
    """Integer threshold of "at or below ``level``": ``c ≤ ⌊level⌋``."""
    return np.floor(np.asarray(level, dtype=np.float64)).astype(np.int64)


def _check_black_level(
    value: object,
    frames: np.ndarray,
    saturation: np.ndarray,
    c_max: int,
    channels: tuple[str, ...],
) -> np.ndarray:
    """Validate a per-channel black level against the bit depth, saturation and data."""
    n_ch = frames.shape[-1]
    if value is None:
        return np.zeros(n_ch, dtype=np.float64)
    arr = np.asarray(value)
    if arr.ndim == 0:
        arr = np.full(n_ch, arr)
    black = check_array(arr, "black_level", shape=(n_ch,), kind="iuf", finite=True).astype(
        np.float64
    )
    if np.any(black < 0) or np.any(black > c_max):
        raise InputError(f"`black_level` must lie in [0, {c_max}], got {black.tolist()}")
    above = black >= saturation
    if np.any(above):
        ch = int(np.argmax(above))
        raise InputError(
            f"`black_level` {black[ch]:g} of channel {channels[ch]} is at or above its "
            f"saturation level {int(saturation[ch])}: no value could carry light"
        )
    # a right black level has the dark values around it (half below, by the noise), a
    # mislabelled one has them below it: most of the longest exposure's values at or below
    # it *and* their median below it by more than noise (2 DN, or 2 % of the range above it).
    # A capture dark by design (a glare source on black, dark frames) sits at the black level.
    longest = frames[:, -1].reshape(-1, n_ch)
    for ch in range(n_ch):
        if black[ch] <= 0:
            continue
        dark = float(np.count_nonzero(longest[:, ch] <= black[ch])) / longest.shape[0]
        median = float(np.median(longest[:, ch])) if dark > 0.5 else float(black[ch])
        allowance = max(2.0, 0.02 * (float(saturation[ch]) - black[ch]))
        if dark > 0.5 and black[ch] - median > allowance:
            raise InputError(
                f"`black_level` {black[ch]:g} of channel {channels[ch]} lies above the data: "
                f"{100 * dark:.0f} % of the longest exposure's values are at or below it "
                f"(median {median:g}); is the black level mislabelled?"
            )
    return black
