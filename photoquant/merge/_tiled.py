"""Private engine of the fast table merge: per-exposure float32 tables, row tiles, threads.

The weighted mean of eq. 6, ``ln c = Σ_k w (g − ln t_k) / Σ_k w``, depends on
a value only through its integer code (the value, or the sum of its ``N``
repeats: the mean lies on the grid ``j / N``). Per exposure ``k`` and
channel two tables are built once, ``w`` and ``w·(g − ln t_k)`` on every grid
point, and each value is looked up once per frame
(:mod:`photoquant.merge._kernels`). Values excluded because a repeat
clipped get two extra codes with zero weight. The image is merged in row
tiles (bounded memory: each tile's work space is a few MiB; the result is
written into the caller's arrays), on threads.

Float32 accumulation, the error analysis
----------------------------------------
The terms are rounded to float32 (relative error ``ε = 2⁻²⁴``) and summed
in float32 in the order ``k = 0 … K−1``. With ``M = max_k |g − ln t_k|`` over
the values with weight, ``Σ_k |w (g − ln t_k)| ≤ M Σ_k w``, so the sums carry
absolute errors ``≤ (K+1) ε M Σw`` and ``≤ (K+1) ε Σw`` (one rounding per term
and per partial sum), and the float32 quotient one more ``ε |ln c| ≤ ε M``:

    |ln c (float32) − ln c (exact)| ≤ (2K + 3) · ε · M.

For K = 8 exposures and ``M ≈ 15`` (``g`` spans ~10 in ln, ``ln t`` another
~8) that is 1.7·10⁻⁵ in ``ln c``, a relative error of 1.7·10⁻⁵ in the
photoquantity: 200× below one 8-bit quantisation step at mid-range
(``Δ ln c ≈ 1/128``) and far below the shot noise the validation's
tolerances come from. A weight below float32's smallest normal (1.2·10⁻³⁸)
would round to 0; no weighting function of photoquant comes near it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

from photoquant._checks import check_workers
from photoquant._threads import BackgroundMap, thread_map
from photoquant.merge._kernels import (
    accumulate_codes,
    accumulate_repeats,
    accumulate_summaries,
    three_value_tables,
)

__all__ = [
    "MergeTables",
    "CodeSource",
    "DirectCodes",
    "RepeatCodes",
    "SummaryCodes",
    "TileMerge",
    "row_tiles",
    "merge_tiles",
    "merge_tiles_linear",
    "start_merge_tiles",
]

PAIRED_TABLE_SIZE = (1 << 16) + 2
"""Most codes per table (the grid and the two exclusion codes) for which the tables are also
kept paired (:attr:`MergeTables.pairs`): single frames of up to 16 bits (a K = 8, RGB
stack's pairs: 12.6 MB at 16 bits, 50 KB at 8)."""

TILE_BYTES = 2 << 20
"""Input bytes per row tile when the caller gives no ``tile_rows`` (2 MiB: the tile's
frames, codes and accumulators stay in the cache, and a 1024×768 image gives
enough tiles to keep every CPU busy)."""


@dataclass(frozen=True, eq=False)
class MergeTables:
    """Per channel and code: the weight, ``w·(g − ln t_k)`` per exposure, and "clipped".

    ``w`` (C, G+2) and ``wt`` (K, C, G+2) float32, ``clip`` (C, G+2) bool; codes
    ``0 … G−1`` are the grid, ``sat_code = G`` a value with a repeat at
    saturation (no weight, clipped) and ``dark_code = G+1`` one with a repeat
    at the dark floor (no weight, not clipped).

    ``pairs`` (K, C, G+2) float64, up to :data:`PAIRED_TABLE_SIZE` codes
    (``None`` above): the same tables paired, each entry the 8 bytes of the
    float32 ``wt[k, ch, code]`` followed by ``w[ch, code]``, so that the
    numba three-value kernel loads both at once and adds them to its two sums
    in one vector add (the same float32 adds: the same bits). Not float64
    numbers: only those kernels read them.
    """

    w: np.ndarray
    wt: np.ndarray
    clip: np.ndarray
    sat_code: int
    dark_code: int
    pairs: np.ndarray | None = None

    @cached_property
    def three_value(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``pairs`` and ``clip`` as the three-value kernel reads them
        (:func:`~photoquant.merge._kernels.three_value_tables`), made on first use."""
        return three_value_tables(self.pairs, self.clip)

    @classmethod
    def build(
        cls,
        grid: np.ndarray,
        weights: Callable[[np.ndarray, int], np.ndarray],
        log_inverse: Callable[[np.ndarray, int], np.ndarray],
        saturation: np.ndarray,
        log_t: np.ndarray,
        *,
        dark_below: np.ndarray | None = None,
        paired: bool = True,
    ) -> MergeTables:
        """Tables on ``grid`` (the mean each code stands for).

        ``weights(grid, ch)`` and ``log_inverse(grid, ch)`` are evaluated in
        float64 and each term ``w·(g − ln t_k)`` is rounded to float32 once.
        ``dark_below`` (C,): codes ``≤`` it get no weight (single frames,
        where "a repeat at the dark floor" is a function of the value).
        ``paired``: also build :attr:`pairs` (when small enough), which only
        the kernel of single frames' codes (:class:`DirectCodes`) reads.
        """
        n_ch, size = saturation.size, grid.size
        w = np.zeros((n_ch, size + 2), dtype=np.float32)
        wt = np.zeros((log_t.size, n_ch, size + 2), dtype=np.float32)
        clip = np.zeros((n_ch, size + 2), dtype=bool)
        for ch in range(n_ch):
            w64 = np.asarray(weights(grid, ch), dtype=np.float64)
            if dark_below is not None:
                w64 = np.where(grid <= dark_below[ch], 0.0, w64)
            g64 = np.asarray(log_inverse(grid, ch), dtype=np.float64)
            w[ch, :size] = w64
            for k, lt in enumerate(log_t):
                wt[k, ch, :size] = w64 * (g64 - lt)
            clip[ch, :size] = grid >= saturation[ch]
        clip[:, size] = True
        pairs = None
        if paired and size + 2 <= PAIRED_TABLE_SIZE:
            both = np.empty(wt.shape + (2,), dtype=np.float32)
            both[..., 0] = wt
            both[..., 1] = w
            pairs = both.view(np.float64).reshape(wt.shape)
        return cls(w, wt, clip, size, size + 1, pairs)


class CodeSource(Protocol):
    """Where a tile's codes come from."""

    shape: tuple[int, int, int]  # (H, W, C)
    bytes_per_row: int

    def accumulate(
        self,
        rows: slice,
        tables: MergeTables,
        num: np.ndarray,
        den: np.ndarray,
        flags: tuple[np.ndarray, np.ndarray, np.ndarray],
        backend: str,
        flags_zeroed: bool = False,
    ) -> None: ...


class DirectCodes:
    """Integer values ``(K, H, W, C)`` that are their own codes, with optional exclusion masks."""

    def __init__(
        self,
        values: np.ndarray,
        saturated: np.ndarray | None = None,
        dark_clipped: np.ndarray | None = None,
        *,
        sat_code: int = 0,
        dark_code: int = 0,
    ) -> None:
        self.values = values
        self.saturated = saturated
        self.dark = dark_clipped
        self.sat_code, self.dark_code = sat_code, dark_code
        self.shape = (int(values.shape[1]), int(values.shape[2]), int(values.shape[3]))
        self.bytes_per_row = int(values.shape[0] * values.shape[2] * values.shape[3])
        self.bytes_per_row *= values.itemsize

    def _override(
        self, codes: np.ndarray, sat: np.ndarray | None, dark: np.ndarray | None
    ) -> np.ndarray:
        if sat is None and dark is None:
            return codes
        codes = codes.astype(np.int64)
        if dark is not None:
            codes[dark] = self.dark_code
        if sat is not None:
            codes[sat] = self.sat_code  # a saturated repeat wins: the value is clipped
        return codes

    def accumulate(
        self,
        rows: slice,
        tables: MergeTables,
        num: np.ndarray,
        den: np.ndarray,
        flags: tuple[np.ndarray, np.ndarray, np.ndarray],
        backend: str,
        flags_zeroed: bool = False,
    ) -> None:
        w, wt, clip = tables.w, tables.wt, tables.clip
        if self.saturated is None and self.dark is None:
            # the values are the codes: the whole array and the tile's rows (no view of it)
            accumulate_codes(
                self.values,
                w,
                wt,
                clip,
                num,
                den,
                *flags,
                rows=rows,
                backend=backend,
                flags_zeroed=flags_zeroed,
                three_value=tables.three_value,
            )
            return
        codes = self._override(
            self.values[:, rows],
            None if self.saturated is None else self.saturated[:, rows],
            None if self.dark is None else self.dark[:, rows],
        )
        accumulate_codes(
            codes,
            w,
            wt,
            clip,
            num,
            den,
            *flags,
            backend=backend,
            flags_zeroed=flags_zeroed,
            three_value=tables.three_value,
        )


class RepeatCodes:
    """Frames ``(N, K, H, W, C)``: code = the repeat sum, or an exclusion code."""

    def __init__(
        self, frames: np.ndarray, sat_thr: np.ndarray, dark_thr: np.ndarray, tables: MergeTables
    ) -> None:
        self.frames = frames
        self.sat_thr = np.ascontiguousarray(sat_thr, dtype=np.int64)
        self.dark_thr = np.ascontiguousarray(dark_thr, dtype=np.int64)
        self.sat_code, self.dark_code = tables.sat_code, tables.dark_code
        n, k, _, width, n_ch = frames.shape
        self.shape = (int(frames.shape[2]), int(width), int(n_ch))
        self.bytes_per_row = int(n * k * width * n_ch * frames.itemsize)

    def accumulate(
        self,
        rows: slice,
        tables: MergeTables,
        num: np.ndarray,
        den: np.ndarray,
        flags: tuple[np.ndarray, np.ndarray, np.ndarray],
        backend: str,
        flags_zeroed: bool = False,
    ) -> None:
        del flags_zeroed  # this kernel writes every flag
        accumulate_repeats(
            self.frames,
            tables.w,
            tables.wt,
            tables.clip,
            self.sat_thr,
            self.dark_thr,
            tables.sat_code,
            tables.dark_code,
            num,
            den,
            *flags,
            rows=rows,
            backend=backend,
        )


class SummaryCodes:
    """A stack's repeat sums and extremes ``(K, H, W, C)``: the codes of :class:`RepeatCodes`.

    Used where the stack holds them already (computed for its masks, the
    defect detection or the response): the merge then reads
    ``sizeof(sum) + 2 · sizeof(frame)`` bytes per value instead of the ``N``
    frames, with the same codes and bits.
    """

    def __init__(
        self,
        total: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        sat_thr: np.ndarray,
        dark_thr: np.ndarray,
    ) -> None:
        self.total, self.lo, self.hi = total, lo, hi
        self.sat_thr = np.ascontiguousarray(sat_thr, dtype=np.int64)
        self.dark_thr = np.ascontiguousarray(dark_thr, dtype=np.int64)
        k, _, width, n_ch = total.shape
        self.shape = (int(total.shape[1]), int(width), int(n_ch))
        self.bytes_per_row = int(k * width * n_ch * (total.itemsize + lo.itemsize + hi.itemsize))

    def accumulate(
        self,
        rows: slice,
        tables: MergeTables,
        num: np.ndarray,
        den: np.ndarray,
        flags: tuple[np.ndarray, np.ndarray, np.ndarray],
        backend: str,
        flags_zeroed: bool = False,
    ) -> None:
        del flags_zeroed  # this kernel writes every flag
        accumulate_summaries(
            self.total,
            self.lo,
            self.hi,
            tables.w,
            tables.wt,
            tables.clip,
            self.sat_thr,
            self.dark_thr,
            tables.sat_code,
            tables.dark_code,
            num,
            den,
            *flags,
            rows=rows,
            backend=backend,
        )


def row_tiles(
    height: int, bytes_per_row: int, tile_rows: int | None = None, workers: int = 1
) -> list[slice]:
    """Row slices covering ``[0, height)``: ``tile_rows`` each, or about :data:`TILE_BYTES` of
    input, as many tiles as a multiple of ``workers`` (no thread left with one more tile
    than the others: 9 tiles on 2 threads took as long as 10)."""
    if tile_rows is None:
        rows = max(1, TILE_BYTES // max(1, bytes_per_row))
        n_tiles = -(-height // rows)
        if workers > 1:
            n_tiles = -(-n_tiles // workers) * workers
        tile_rows = max(1, -(-height // n_tiles))
    return [slice(r, min(r + tile_rows, height)) for r in range(0, height, tile_rows)]


def merge_tiles(
    source: CodeSource,
    tables: MergeTables,
    log_out: np.ndarray,
    mask_out: np.ndarray,
    all_saturated_out: np.ndarray,
    all_dark_out: np.ndarray,
    *,
    weight_out: np.ndarray | None = None,
    tile_rows: int | None = None,
    workers: int | None = None,
    on_tile: Callable[[slice, np.ndarray, np.ndarray], None] | None = None,
    backend: str = "auto",
    flags_zeroed: bool = False,
) -> None:
    """Merge ``source`` tile by tile into the caller's ``(H, W, C)`` arrays.

    ``log_out`` (float32) receives ``ln c`` (NaN where ``mask``),
    ``weight_out`` (float32, optional) ``Σ_k w``; the masks as in
    :class:`~photoquant.merge.MergeResult`. ``on_tile(rows, log_c, mask)`` is
    called on each finished tile (e.g. to turn ``ln c`` into the corrected
    photoquantity in place). ``flags_zeroed``: the three flag outputs are all
    false already (made by ``np.zeros``), so the direct kernel, which writes a
    flag only where it is set, leaves the rest of their memory untouched (a
    fresh ``np.zeros`` array is mapped page by page on first write: 7 MiB of
    flags for 1024×768×3 are not written at all).
    """
    start_merge_tiles(
        source,
        tables,
        log_out,
        mask_out,
        all_saturated_out,
        all_dark_out,
        weight_out=weight_out,
        tile_rows=tile_rows,
        workers=workers,
        on_tile=on_tile,
        backend=backend,
        flags_zeroed=flags_zeroed,
    ).finish()


@dataclass(frozen=True, eq=False)
class TileMerge:
    """A :func:`merge_tiles` begun on ``workers − 1`` threads (:func:`start_merge_tiles`)
    while the caller does something else."""

    tiles: list[slice]
    _run: BackgroundMap[None, tuple[CodeSource, MergeTables]]

    def switch(self, source: CodeSource, tables: MergeTables) -> None:
        """Merge the tiles left, and again those begun already, from ``source`` and
        ``tables`` (the same stack with other exposure times): each tile merged again
        writes all its outputs, its flags too."""
        self._run.switch((source, tables))

    def finish(self) -> None:
        """Merge the tiles left beside the threads and wait for them (raising as
        :func:`merge_tiles` does)."""
        self._run.finish()

    def stop(self) -> None:
        """Begin no more tiles and wait for those begun (what the outputs hold then is
        not a result)."""
        self._run.stop()


def start_merge_tiles(
    source: CodeSource,
    tables: MergeTables,
    log_out: np.ndarray,
    mask_out: np.ndarray,
    all_saturated_out: np.ndarray,
    all_dark_out: np.ndarray,
    *,
    weight_out: np.ndarray | None = None,
    tile_rows: int | None = None,
    workers: int | None = None,
    on_tile: Callable[[slice, np.ndarray, np.ndarray], None] | None = None,
    backend: str = "auto",
    flags_zeroed: bool = False,
) -> TileMerge:
    """:func:`merge_tiles` begun on ``workers − 1`` threads, returned at once: the caller
    then :meth:`~TileMerge.finish` es it (working on the tiles left as its
    ``workers``-th thread), after a :meth:`~TileMerge.switch` of its tables where
    they turned out wrong, or :meth:`~TileMerge.stop` s it. Each tile is written
    by the same kernel whichever thread takes it, so the result is that of
    :func:`merge_tiles` from the last tables, bit for bit."""
    height = source.shape[0]
    n_workers = check_workers(workers)
    tiles = row_tiles(height, source.bytes_per_row, tile_rows, n_workers)

    def job(rows: slice, plan: tuple[CodeSource, MergeTables], again: bool) -> None:
        num = log_out[rows]
        shape = num.shape
        den = weight_out[rows] if weight_out is not None else np.empty(shape, dtype=np.float32)
        flags = (mask_out[rows], all_saturated_out[rows], all_dark_out[rows])
        # num: ln c (NaN: no weight); a tile merged again may hold flags of its first merge
        plan[0].accumulate(rows, plan[1], num, den, flags, backend, flags_zeroed and not again)
        if on_tile is not None:
            on_tile(rows, num, flags[0])

    n_threads = min(n_workers, len(tiles)) - 1
    return TileMerge(tiles, BackgroundMap(job, tiles, (source, tables), n_threads))


def merge_tiles_linear(
    source: CodeSource,
    tables: MergeTables,
    out: np.ndarray,
    *,
    tile_rows: int | None = None,
    workers: int | None = None,
    backend: str = "auto",
) -> None:
    """Merge ``source`` tile by tile into the linear photoquantity ``out`` (H, W, C) alone.

    ``out[rows] = exp(ln c)`` of each tile, NaN where no exposure has weight:
    the values :func:`merge_tiles` gives ``ln c``, exponentiated as
    :meth:`~photoquant.merge.MergeResult.photoquantity` does. A tile's
    ``ln c``, ``Σ_k w`` and flags live in tile-sized work arrays (about a MiB
    each for the default tiles), so ``out`` is the only
    image-sized memory the merge writes. Writing ``ln c`` and ``Σ_k w`` into
    image-sized arrays as well, first touched by this merge, cost 1.6–3.9 ms
    more in the paired median (1024×768×3, K = 8, 2 cores, 20–40 alternated
    repeats, 2026-12-02): this virtual machine maps fresh memory slowly.
    """
    height = source.shape[0]
    tiles = row_tiles(height, source.bytes_per_row, tile_rows, check_workers(workers))

    def job(rows: slice) -> None:
        target = out[rows]
        shape = target.shape
        num = np.empty(shape, dtype=np.float32)
        den = np.empty(shape, dtype=np.float32)
        flags = (np.zeros(shape, bool), np.zeros(shape, bool), np.zeros(shape, bool))
        source.accumulate(rows, tables, num, den, flags, backend, True)
        np.exp(num, out=target)  # NaN where no weight (the kernels' 0 / 0)

    thread_map(job, tiles, workers)
