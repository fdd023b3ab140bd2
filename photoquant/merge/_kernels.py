"""Private inner loops of the table merge: ``Σ_k w·(g − ln t_k) / Σ_k w`` and ``Σ_k w`` per value.

Two implementations with **bit-identical** results:

* numba (optional, ``pip install numba``; used when it imports): one fused
  pass per pixel, reading each value once and gathering ``w`` and
  ``w·(g − ln t_k)`` from per-exposure float32 tables; ``nogil`` so that the
  merge's row tiles run on every CPU. Measured on a paper-sized stack
  (1024×768×3, K = 8, uint8, one thread, 2026-12-01 on the shared 2-core
  machine): 25 ms against 72 ms for the best numpy formulation below and
  199 ms for the former numpy merge (an intp index plus a length-3 offset
  array, float64 gathers and sums), in the same run; flat ``(K, n)``
  indexing is 2× faster than 4-d indexing. Three channels (and one, as
  three) take a kernel that merges three values a pass with the exposure
  loop unrolled (:func:`_direct_rgb_py`: 7.6 ms on one thread for the same
  stack, 2026-12-02), reading a code's two table entries as one 8-byte pair
  and adding it to the value's two sums by one two-lane float32 vector add
  (an LLVM intrinsic, :func:`_pair_add`: 5.0–5.4 ms).
* numpy (always there): per channel plane and exposure, the codes are cast
  once into a reused intp buffer, gathered with ``take(out=, mode="clip")``
  (no buffering) and added into float32 plane accumulators.

Both add the K terms of a value in the order ``k = 0 … K−1`` starting from
0 in float32 (numba compiles without ``fastmath``, so no reassociation; a
lane of a vector add is the same IEEE float32 add), so they give the same
bits; :mod:`tests.photoquant.test_merge_fast` checks it.

A *code* is what indexes the tables: the integer value (or the sum of its
``N`` repeats), or one of two extra codes past the grid for values that
are excluded because a repeat clipped at the saturation level (``sat_code``)
or at the dark floor (``dark_code``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from photoquant._numba import HAVE_NUMBA, compile_kernel

__all__ = [
    "HAVE_NUMBA",
    "accumulate_codes",
    "accumulate_repeats",
    "accumulate_summaries",
    "three_value_tables",
    "repeat_codes",
    "summary_codes",
]

_compile = compile_kernel

_MAX_UNROLLED_EXPOSURES = 16
"""Most exposures merged by the three-channel kernel, which numba compiles once per K."""


def _direct_py(
    codes: Any,
    start: int,
    w: Any,
    wt: Any,
    clip: Any,
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: ``num = Σ_k wt / Σ_k w``, ``den = Σ_k w`` and the flags per value.

    Flat layouts: ``codes (K, M)``, of which values ``start … start + n`` are
    merged into the outputs ``(n,)``, the channel fastest (``n = h·W·C``); flat
    indexing measured 2× faster than 4-d indexing, and a tile's values read
    from the whole C-contiguous array 1.4× faster than from a strided view of
    the tile (which numba compiles for any layout). A
    value's flags are written only where it is flagged (no weight: rare), into
    outputs zeroed before (:func:`_flat_outputs`), and the test of its
    exposures is in that branch: writing the three flags of every value, and
    the test ahead of the store, made this kernel 2× slower (one thread,
    1024×768×3, K = 8: 40–46 → 17–21 ms, 2026-12-02, quiet machine).
    The table indices are unsigned: numba wraps a negative signed index
    (a test and an add per index), an unsigned one needs neither: 11.9 →
    10.4 ms on one thread, the same stack (2026-12-02).
    """
    n_k = codes.shape[0]
    n = num.size
    n_ch = w.shape[0]
    for p in range(n // n_ch):
        for ch in range(n_ch):
            q = p * n_ch + ch
            uch = np.uint64(ch)
            s = np.float32(0.0)
            d = np.float32(0.0)
            for k in range(n_k):
                uk = np.uint64(k)
                c = codes[uk, np.uint64(start + q)]
                s += wt[uk, uch, c]
                d += w[uch, c]
            den[q] = d
            if d > 0:
                num[q] = s / d
            else:  # flagged (rare)
                _flag_codes(codes, start + q, clip, ch, num, mask, all_sat, all_dark, q)


def _direct_rgb_py(
    rows: Any,
    codes: Any,
    start: int,
    pairs: Any,
    clip: Any,
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: :func:`_direct_py` for three channels, the three values of a pixel at once.

    Three independent pair sums per pass over the exposures, with the
    channels' table rows known at compile time, and no flag work in the
    loop: a value without weight gets ``0 / 0`` there and is flagged by a
    further pass over the tile's ``den``, run only when the tile has one. One
    thread, 1024×768×3, K = 8, alternated in one process (2026-12-02): 10.9–11.0
    → 8.5–8.6 ms. The exposures' codes come as a tuple ``rows`` of K flat
    arrays (the rows of ``codes``), whose length numba compiles in (one
    compilation per K, cached on disk): the loop over the exposures is
    unrolled, 8.4–8.5 → 7.6 ms.

    ``pairs`` (K, C, G) holds each code's ``w·(g − ln t_k)`` and ``w`` side by
    side as one 8-byte entry (:attr:`~photoquant.merge._tiled.MergeTables.pairs`),
    loaded at once and added into a pair of float32 sums by one two-lane
    vector add (:func:`_pair_add`): one load and one add per exposure and
    value instead of two of each. The lanes are IEEE float32 adds in the
    same order as the scalar ones, so the bits are those of
    :func:`_direct_py`; 7.4–7.7 → 5.0–5.4 ms on one thread, the same stack
    (20 alternated repeats, 2026-12-02). The same pairs as numba complex64
    values were not faster (7.46 against 7.40 ms): numba loads and adds a
    complex number's halves apart.

    Measured and not kept: the flags set in the loop (a call the loop must
    keep its registers for: 9.1–9.3 ms); three values at a time for any
    channel count, their table rows computed per pixel (11.1 ms: the gain
    is the constant rows); the run-time channel loop without flag work
    (11.2 ms). Each value's terms are added in the order ``k = 0 … K−1``
    from 0. One channel goes through this kernel as three with the same
    tables (:func:`_direct_compiled`): 12.0 → 7.8 ms for 1024×768×3 values
    of one channel, K = 8, one thread (separate tables).
    """
    n_k = len(rows)
    zero, one, two = np.uint64(0), np.uint64(1), np.uint64(2)
    unweighted = False
    for p in range(num.size // 3):
        q = np.uint64(3 * p)
        v = np.uint64(start) + q
        a0 = 0.0  # the bits of two float32 zeros: (Σ w·(g − ln t), Σ w)
        a1 = 0.0
        a2 = 0.0
        for k in range(n_k):
            uk = np.uint64(k)
            row = rows[k]
            a0 = _pair_add(a0, pairs[uk, zero, row[v]])
            a1 = _pair_add(a1, pairs[uk, one, row[v + one]])
            a2 = _pair_add(a2, pairs[uk, two, row[v + two]])
        d0 = _pair_second(a0)
        d1 = _pair_second(a1)
        d2 = _pair_second(a2)
        den[q] = d0
        den[q + one] = d1
        den[q + two] = d2
        num[q] = _pair_first(a0) / d0  # 0 / 0 without weight: flagged below
        num[q + one] = _pair_first(a1) / d1
        num[q + two] = _pair_first(a2) / d2
        unweighted |= not (d0 > 0 and d1 > 0 and d2 > 0)
    if unweighted:
        _flag_unweighted(codes, start, clip, num, den, mask, all_sat, all_dark)


def _flag_unweighted_py(
    codes: Any,
    start: int,
    clip: Any,
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: flag the values of the outputs whose ``den`` is not positive (no weight)."""
    n_ch = clip.shape[0]
    for q in range(num.size):
        if not den[q] > 0:
            _flag_codes(codes, start + q, clip, q % n_ch, num, mask, all_sat, all_dark, q)


def _store_py(
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
    q: int,
    s: Any,
    d: Any,
    unsat: bool,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: the quotient (NaN without weight), the sum and the three flags.

    Every flag is written (:func:`_direct_py` writes them only where they are
    set, into zeroed outputs: 2× faster there, but 1.7× *slower* in
    :func:`_summary_py`, measured 2026-12-02).
    """
    den[q] = d
    if d > 0:
        num[q] = s / d
        mask[q] = False
        all_sat[q] = False
        all_dark[q] = False
    else:
        _flag(num, mask, all_sat, all_dark, q, unsat)


def _flag_py(
    num: Any, mask: Any, all_sat: Any, all_dark: Any, q: int, unsat: bool
) -> None:  # pragma: no cover - compiled by numba
    """numba body: a value without weight: NaN, masked, all saturated or all dark."""
    num[q] = np.nan
    mask[q] = True
    all_sat[q] = not unsat
    all_dark[q] = unsat


def _flag_codes_py(
    codes: Any,
    v: int,
    clip: Any,
    ch: int,
    num: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
    q: int,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: :func:`_flag_py` for value ``q`` of channel ``ch``, whose codes are
    column ``v`` of ``codes (K, M)``: all dark where some exposure is not clipped."""
    unsat = False
    for k in range(codes.shape[0]):
        if not clip[ch, codes[k, v]]:
            unsat = True
    _flag(num, mask, all_sat, all_dark, q, unsat)


def _repeats_py(
    frames: Any,
    start: int,
    w: Any,
    wt: Any,
    clip: Any,
    sat_thr: Any,
    dark_thr: Any,
    sat_code: int,
    dark_code: int,
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: the codes of ``N`` repeats ``frames (N, K, M)`` (sum, or an exclusion code),
    values ``start … start + n`` into the outputs ``(n,)``.

    Blocked: for a block of values, each frame ``(r, k)`` is read as one
    contiguous run into per-value sums and extremes (one memory stream at a
    time; reading the ``N·K`` frames of one value after another is ``N·K``
    interleaved streams, which the prefetchers do not follow), with narrow
    accumulators and branch-free extremes that vectorise: 1.2 ns per frame
    value against 3.7 before (one thread, 1024×768×3, N = 10, K = 8, uint8;
    2026-12-01 on the shared 2-core machine, loaded).
    Per value the K terms are still added in the order ``k = 0 … K−1``, so
    the bits are those of the numpy kernel.
    """
    n_rep, n_k = frames.shape[0], frames.shape[1]
    n = num.size
    n_ch = w.shape[0]
    block = 2048 * n_ch
    # narrow accumulators (int32 sums: the tables, hence N · c_max, stay below 2²², see
    # merge.debevec1997; extremes in the frames' dtype), branch-free max/min: they vectorise
    tot = np.empty(block, dtype=np.int32)
    hi = np.empty(block, dtype=frames.dtype)
    lo = np.empty(block, dtype=frames.dtype)
    s = np.empty(block, dtype=np.float32)
    d = np.empty(block, dtype=np.float32)
    unsat = np.empty(block, dtype=np.bool_)
    for q0 in range(0, n, block):
        m = min(block, n - q0)
        s[:m] = 0.0
        d[:m] = 0.0
        unsat[:m] = False
        for k in range(n_k):
            for i in range(m):
                f = frames[0, k, start + q0 + i]
                tot[i] = f
                hi[i] = f
                lo[i] = f
            for r in range(1, n_rep):
                for i in range(m):
                    f = frames[r, k, start + q0 + i]
                    tot[i] += np.int32(f)
                    hi[i] = max(hi[i], f)
                    lo[i] = min(lo[i], f)
            uk = np.uint64(k)  # unsigned indices: no wrap of negative ones (_direct_py)
            for p in range(m // n_ch):
                for ch in range(n_ch):
                    j = np.uint64(p * n_ch + ch)
                    uch = np.uint64(ch)
                    if hi[j] >= sat_thr[uch]:
                        c = np.uint64(sat_code)
                    elif lo[j] <= dark_thr[uch]:
                        c = np.uint64(dark_code)
                    else:
                        c = np.uint64(tot[j])
                    s[j] += wt[uk, uch, c]
                    d[j] += w[uch, c]
                    if not clip[uch, c]:
                        unsat[j] = True
        for i in range(m):
            _store(num, den, mask, all_sat, all_dark, q0 + i, s[i], d[i], unsat[i])


def _summary_py(
    total: Any,
    lo: Any,
    hi: Any,
    start: int,
    w: Any,
    wt: Any,
    clip: Any,
    sat_thr: Any,
    dark_thr: Any,
    sat_code: int,
    dark_code: int,
    num: Any,
    den: Any,
    mask: Any,
    all_sat: Any,
    all_dark: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: the codes of :func:`_repeats_py` from the stack's repeat sums and extremes.

    ``total, lo, hi (K, M)`` (values ``start … start + n``): what
    :meth:`ExposureStack.repeat_sum` and its
    extremes already hold (a quarter of the frames' bytes at N = 10, 8 bits);
    the same codes, the same order of the K terms, the same bits.
    """
    n_k = total.shape[0]
    n = num.size
    n_ch = w.shape[0]
    for p in range(n // n_ch):
        for ch in range(n_ch):
            q = p * n_ch + ch
            v = np.uint64(start + q)
            uch = np.uint64(ch)
            s = np.float32(0.0)
            d = np.float32(0.0)
            unsat = False
            for k in range(n_k):
                uk = np.uint64(k)  # unsigned indices: no wrap of negative ones (_direct_py)
                if hi[uk, v] >= sat_thr[uch]:
                    c = np.uint64(sat_code)
                elif lo[uk, v] <= dark_thr[uch]:
                    c = np.uint64(dark_code)
                else:
                    c = np.uint64(total[uk, v])
                s += wt[uk, uch, c]
                d += w[uch, c]
                if not clip[uch, c]:
                    unsat = True
            _store(num, den, mask, all_sat, all_dark, q, s, d, unsat)


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    from llvmlite import ir as _ir  # type: ignore[import-untyped]
    from numba import extending as _extending
    from numba import types as _types

    _intrinsic: Any = _extending.intrinsic  # typed by numba for its own calls only

    _PAIR = _ir.VectorType(_ir.FloatType(), 2)

    @_intrinsic
    def _pair_add(typingctx: Any, a: Any, b: Any) -> Any:
        """``a + b`` lane by lane, each a float64 that carries two float32 (one vector add)."""
        del typingctx
        if a != _types.float64 or b != _types.float64:
            return None

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            del context, signature  # numba's codegen arguments, not needed here
            x, y = (builder.bitcast(arg, _PAIR) for arg in args)
            return builder.bitcast(builder.fadd(x, y), _ir.DoubleType())

        return _types.float64(_types.float64, _types.float64), codegen

    def _pair_lane(lane: int) -> Any:
        @_intrinsic
        def lane_of(typingctx: Any, a: Any) -> Any:
            del typingctx
            if a != _types.float64:
                return None

            def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
                del context, signature
                pair = builder.bitcast(args[0], _PAIR)
                return builder.extract_element(pair, _ir.Constant(_ir.IntType(32), lane))

            return _types.float32(_types.float64), codegen

        return lane_of

    _pair_first = _pair_lane(0)  # the float32 at the lower address
    _pair_second = _pair_lane(1)

    # numpy's error model: s / d needs no zero test (it is taken where d > 0, or, in the
    # three-value kernel, gives 0 / 0 = NaN where d = 0 and the value is flagged after)
    _flag = _compile(_flag_py, inline="always")
    _flag_codes = _compile(_flag_codes_py, inline="always")
    _flag_unweighted = _compile(_flag_unweighted_py)
    _store = _compile(_store_py, inline="always", error_model="numpy")
    _direct_nb = _compile(_direct_py, error_model="numpy")
    _direct_rgb_nb = _compile(_direct_rgb_py, error_model="numpy")
    _repeats_nb = _compile(_repeats_py, error_model="numpy")
    _summary_nb = _compile(_summary_py, error_model="numpy")


def _direct_np(
    codes: np.ndarray,
    w: np.ndarray,
    wt: np.ndarray,
    clip: np.ndarray,
    num: np.ndarray,
    den: np.ndarray,
    mask: np.ndarray,
    all_sat: np.ndarray,
    all_dark: np.ndarray,
) -> None:
    n_k, h, width, n_ch = codes.shape
    index = np.empty((h, width), dtype=np.intp)
    tmp = np.empty((h, width), dtype=np.float32)
    s = np.empty((h, width), dtype=np.float32)
    d = np.empty((h, width), dtype=np.float32)
    for ch in range(n_ch):
        s.fill(0.0)
        d.fill(0.0)
        for k in range(n_k):
            np.copyto(index, codes[k, :, :, ch], casting="unsafe")
            np.take(wt[k, ch], index, out=tmp, mode="clip")  # codes are in range: no checks
            s += tmp
            np.take(w[ch], index, out=tmp, mode="clip")
            d += tmp
        np.divide(s, d, out=s, where=d > 0)
        s[d <= 0] = np.nan
        num[..., ch] = s
        den[..., ch] = d
    # the flags: "clipped" looked up only where no exposure has weight (few values)
    np.less_equal(den, 0, out=mask)
    all_sat.fill(False)
    all_dark.fill(False)
    if mask.any():
        where = np.nonzero(mask)
        unsat = np.zeros(where[0].size, dtype=bool)
        for k in range(n_k):
            unsat |= ~clip[where[-1], codes[k][where]]
        all_sat[where] = ~unsat
        all_dark[where] = unsat


def repeat_codes(
    frames: np.ndarray,
    sat_thr: np.ndarray,
    dark_thr: np.ndarray,
    sat_code: int,
    dark_code: int,
) -> np.ndarray:
    """Codes ``(K, …, C)`` int64 of ``frames (N, K, …, C)``: the repeat sum or an exclusion code.

    ``sat_code`` where any repeat is at or above ``sat_thr`` (per channel),
    else ``dark_code`` where any repeat is at or below ``dark_thr``.
    """
    total = frames.sum(axis=0, dtype=np.int64)
    return summary_codes(
        total, frames.min(axis=0), frames.max(axis=0), sat_thr, dark_thr, sat_code, dark_code
    )


def summary_codes(
    total: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    sat_thr: np.ndarray,
    dark_thr: np.ndarray,
    sat_code: int,
    dark_code: int,
) -> np.ndarray:
    """:func:`repeat_codes` from the repeat sums ``total`` and extremes ``lo``, ``hi`` (K, …, C)."""
    codes = np.where(lo <= dark_thr, np.int64(dark_code), total.astype(np.int64))
    return np.where(hi >= sat_thr, np.int64(sat_code), codes)


def accumulate_codes(
    codes: np.ndarray,
    w: np.ndarray,
    wt: np.ndarray,
    clip: np.ndarray,
    num: np.ndarray,
    den: np.ndarray,
    mask: np.ndarray,
    all_sat: np.ndarray,
    all_dark: np.ndarray,
    *,
    rows: slice | None = None,
    backend: str = "auto",
    flags_zeroed: bool = False,
    three_value: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Merge the codes of a tile: ``ln c``, ``Σ_k w`` and the three flags.

    Parameters
    ----------
    codes : ndarray, shape (K, h, W, C), integer
        Table indices, all in range (not checked here); with ``rows``, the
        whole image's ``(K, H, W, C)``, of which the tile is ``rows``.
    w, wt, clip : ndarray, shapes (C, G), (K, C, G) float32 and (C, G) bool
        The tables (:class:`photoquant.merge._tiled.MergeTables`).
    num, den : ndarray, shape (h, W, C), float32
        Outputs: ``Σ_k wt / Σ_k w`` (NaN where ``Σ_k w = 0``: no exposure with
        weight) and ``Σ_k w``. The float32 quotient is correctly rounded in
        both implementations (IEEE division).
    mask, all_sat, all_dark : ndarray, shape (h, W, C), bool
        Outputs: no exposure with weight; that, with every exposure clipped;
        that, with some exposure not clipped (too dark).
    backend : {"auto", "numba", "numpy"}
    flags_zeroed : bool
        ``mask``, ``all_sat`` and ``all_dark`` are all false already: the
        numba kernel, which sets a flag only where it holds, then writes
        nothing else into them (they are not cleared first).
    three_value : (ndarray, ndarray), optional
        The tables as the numba three-value kernel reads them
        (:func:`three_value_tables`, built once per tables); the same bits
        without.
    """
    if _use_numba(backend):
        outs = _flat_outputs(num, den, mask, all_sat, all_dark, zero_flags=not flags_zeroed)
        flat, start = _flat_span(codes, rows, 1)
        _direct_compiled(flat, start, w, wt, clip, outs, three_value)
    else:
        tile = codes if rows is None else codes[:, rows]
        _direct_np(tile, w, wt, clip, num, den, mask, all_sat, all_dark)


def three_value_tables(
    pairs: np.ndarray | None, clip: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The paired tables and ``clip`` as :func:`_direct_rgb_py` reads them: three channel rows.

    Three channels as they are; one channel's rows repeated three times (the
    kernel merges its values three a pass with the same tables); ``None``
    for other channel counts or without ``pairs`` (tables too large to
    pair), which :func:`_direct_py` merges. Made once per tables
    (:attr:`~photoquant.merge._tiled.MergeTables.three_value`), not per
    tile: a 16-bit table's pairs are megabytes.
    """
    if pairs is None or clip.shape[0] not in (1, 3):
        return None
    if clip.shape[0] == 1:
        return np.tile(pairs, (1, 3, 1)), np.tile(clip, (3, 1))
    return pairs, clip


def _direct_compiled(
    flat: np.ndarray,
    start: int,
    w: np.ndarray,
    wt: np.ndarray,
    clip: np.ndarray,
    outs: list[np.ndarray],
    three_value: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """The numba direct merge of ``flat`` codes from ``start`` into the flat ``outs``.

    Three channels, or one, with their :func:`three_value_tables` go to the
    three-value kernel :func:`_direct_rgb_py` (one channel as three with the
    same tables: three consecutive values a pass, and the last one or two by
    :func:`_direct_py`); other channel counts, more than
    :data:`_MAX_UNROLLED_EXPOSURES` exposures, or no ``three_value`` (tables
    too large to pair) to :func:`_direct_py`. Every path adds a value's
    terms in the same order: the same bits.
    """
    size = outs[0].size
    if three_value is None or flat.shape[0] > _MAX_UNROLLED_EXPOSURES:
        _direct_nb(flat, start, w, wt, clip, *outs)
        return
    body = size - size % 3  # all of it for three channels
    _direct_rgb_nb(tuple(flat), flat, start, *three_value, *(o[:body] for o in outs))
    if body < size:  # one channel: the last one or two values
        _direct_nb(flat, start + body, w, wt, clip, *(o[body:] for o in outs))


def accumulate_repeats(
    frames: np.ndarray,
    w: np.ndarray,
    wt: np.ndarray,
    clip: np.ndarray,
    sat_thr: np.ndarray,
    dark_thr: np.ndarray,
    sat_code: int,
    dark_code: int,
    num: np.ndarray,
    den: np.ndarray,
    mask: np.ndarray,
    all_sat: np.ndarray,
    all_dark: np.ndarray,
    *,
    rows: slice | None = None,
    backend: str = "auto",
) -> None:
    """As :func:`accumulate_codes` for ``frames (N, K, h, W, C)``, coded by :func:`repeat_codes`
    (with ``rows``: the whole ``(N, K, H, W, C)`` and the tile's rows)."""
    flags = (mask, all_sat, all_dark)
    if _use_numba(backend):
        outs = _flat_outputs(num, den, *flags)
        flat, start = _flat_span(frames, rows, 2)
        _repeats_nb(flat, start, w, wt, clip, sat_thr, dark_thr, sat_code, dark_code, *outs)
    else:
        tile = frames if rows is None else frames[:, :, rows]
        codes = repeat_codes(tile, sat_thr, dark_thr, sat_code, dark_code)
        _direct_np(codes, w, wt, clip, num, den, mask, all_sat, all_dark)


def _flat_span(a: np.ndarray, rows: slice | None, lead: int) -> tuple[np.ndarray, int]:
    """``a (*lead, H, W, C)`` as ``(*lead, H·W·C)`` and the flat offset of the tile ``rows``.

    A C-contiguous array is passed whole (a view), so that the kernels see a
    C-contiguous array (numba's code for strided views of a tile was 1.4×
    slower, measured 2026-12-02); otherwise the tile is copied contiguous.
    """
    if rows is not None and a.flags.c_contiguous:
        first = rows.indices(a.shape[lead])[0]
        return a.reshape(*a.shape[:lead], -1), first * a.shape[lead + 1] * a.shape[lead + 2]
    tile = a if rows is None else a[(slice(None),) * lead + (rows,)]
    tile = np.ascontiguousarray(tile)
    return tile.reshape(*tile.shape[:lead], -1), 0


def _flat_outputs(*arrays: np.ndarray, zero_flags: bool = False) -> list[np.ndarray]:
    """Flat views of the outputs (a reshape of a non-contiguous array would be a copy);
    with ``zero_flags`` the boolean ones (the flags) zeroed, for :func:`_direct_py`,
    which sets them only where they hold."""
    if not all(a.flags.c_contiguous for a in arrays):
        raise ValueError("the merge kernels write into C-contiguous outputs only")
    flat = [a.reshape(-1) for a in arrays]
    for a in flat:
        if zero_flags and a.dtype == np.bool_:
            a.fill(False)
    return flat


def _use_numba(backend: str) -> bool:
    if backend == "numpy":
        return False
    if backend == "numba":
        if not HAVE_NUMBA:
            raise ImportError("the numba merge kernels need numba (pip install numba)")
        return True
    return HAVE_NUMBA


def accumulate_summaries(
    total: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    w: np.ndarray,
    wt: np.ndarray,
    clip: np.ndarray,
    sat_thr: np.ndarray,
    dark_thr: np.ndarray,
    sat_code: int,
    dark_code: int,
    num: np.ndarray,
    den: np.ndarray,
    mask: np.ndarray,
    all_sat: np.ndarray,
    all_dark: np.ndarray,
    *,
    rows: slice | None = None,
    backend: str = "auto",
) -> None:
    """As :func:`accumulate_repeats`, from the repeat sums and extremes ``(K, h, W, C)``
    (with ``rows``: the whole ``(K, H, W, C)`` and the tile's rows)."""
    if _use_numba(backend):
        outs = _flat_outputs(num, den, mask, all_sat, all_dark)
        spans = [_flat_span(a, rows, 1) for a in (total, lo, hi)]
        if len({start for _, start in spans}) > 1:  # some whole, some copied: copy all
            spans = [_flat_span(np.ascontiguousarray(a[:, rows]), None, 1) for a in (total, lo, hi)]
        flat = [f for f, _ in spans]
        _summary_nb(*flat, spans[0][1], w, wt, clip, sat_thr, dark_thr, sat_code, dark_code, *outs)
    else:
        if rows is not None:
            total, lo, hi = total[:, rows], lo[:, rows], hi[:, rows]
        codes = summary_codes(total, lo, hi, sat_thr, dark_thr, sat_code, dark_code)
        _direct_np(codes, w, wt, clip, num, den, mask, all_sat, all_dark)
