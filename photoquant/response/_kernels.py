"""Compiled inner loops of the Debevec 1997 response fit (optional numba).

Three steps of :func:`~photoquant.response.debevec1997.camera_response_Debevec1997`
walk every candidate pixel of every exposure (2¹⁷ pixels × K × C): the
censored-pair trimming (:mod:`photoquant.response.censoring`), the histogram
sample selection
(:func:`~photoquant.response.debevec1997.select_samples_histogram`) and the
normal equations of eq. 7. Their readable numpy versions make a dozen full
passes each (``where``, ``floor``, ``bincount``, ``nonzero`` …); the kernels
here make one or two, reading each value once. They are used when numba
imports (:mod:`photoquant._numba`) and give **the same bits** as the numpy
versions, which stay the reference (``tests/photoquant/test_response_kernels.py``
holds the two to equality on random data):

* integer results (levels, bins, ranks, masks) are the same integers;
* float sums are accumulated in the numpy version's order (``bincount``
  adds its weights in the order of the flattened input, which the loops
  follow), without ``fastmath``, so no reassociation; sums over the
  exposures (numpy's axis-0 reductions) add row after row, which is
  numpy's order for C-ordered arrays (the normal equations' inputs are
  made C-ordered first: along a contiguous axis numpy sums pairwise).

The normal equations (:func:`normal_terms`) are one kernel for all their
arrays, not only the pair sums: each of the four solves of a channel's
robust fit made a dozen numpy passes over its ``(K, P)`` values around
them; the robust reweighting's noise scales (:func:`band_medians`) one
pass and a partial sort per band instead of a mask and a median per band.
Measured 2026-12-06 on a 2-core AMD EPYC (``pq.fit_response`` with its
defaults, min of 15, three interleaved runs): 1024×768, K = 8: 71–83 →
61–72 ms; four 80×60, K = 6, N = 2 stacks: 209–243 → 174–177 ms.

Measured 2026-12-02 on this 2-core machine under a load of 3-4 (per call
for the three channels of the response benchmark's 1024×768×3, K = 8
stack, 2¹⁷ candidates; line profiles, so only the ratios mean much): the
trim 30 → 9 ms (the statistic needs only the pixels with one or two
usable values, and every (exposure, partner, level) cell is counted in the
same pass); the whole ``fit_response`` from the frames 164 → 108 ms of CPU
(min of 9) against OpenCV's 70-sample ``CalibrateDebevec`` at 111-115 ms
in the same processes. On a quiet machine (the benchmark's ``response``
row, ``benchmarks/bench_calibrate.py``): 76.8 ms against OpenCV's 54.3 ms,
whose two threads then have two free cores (README, "Benchmarks").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._select import median_inplace

__all__ = [
    "HAVE_NUMBA",
    "usable_masks",
    "shared_exposures",
    "trim_few",
    "histogram_bins",
    "rank_candidates",
    "normal_blocks",
    "normal_terms",
    "band_medians",
    "sandwich_meat",
    "symmetric_part",
    "back_substitution",
]


# ---------------------------------------------------------------------------
# censored-pair trimming (photoquant.response.censoring)
# ---------------------------------------------------------------------------


def _usable_masks_py(
    values: Any, valid: Any, masks: Any, count: Any
) -> float:  # pragma: no cover - compiled by numba
    """numba body: per pixel, its usable values' count and exposure bit mask (``K ≤ 62``;
    0 otherwise); returns the largest usable value (0 when none)."""
    n_k, n_p = values.shape
    top = 0.0
    with_masks = n_k <= 62
    for k in range(n_k):
        bit = np.int64(1) << k if with_masks else np.int64(0)
        for p in range(n_p):
            if valid[k, p]:
                v = float(values[k, p])
                top = max(top, v)
                count[p] += 1
                masks[p] |= bit
    return top


def _shared_exposures_py(masks: Any, shared: Any) -> None:  # pragma: no cover - compiled
    """numba body: ``shared[k, j]``: some pixel is usable at both ``k`` and ``j`` (from the
    per-pixel bit masks; neighbouring pixels mostly repeat a mask, which is skipped)."""
    n_k = shared.shape[0]
    acc = np.zeros(n_k, dtype=np.int64)
    last = np.int64(0)
    for p in range(masks.size):
        m = masks[p]
        if m == last:
            continue
        last = m
        for k in range(n_k):
            if (m >> k) & 1:
                acc[k] |= m
    for k in range(n_k):
        for j in range(n_k):
            shared[k, j] = (acc[k] >> j) & 1 == 1


def _level_py(v: Any, spacing: float, cap: float) -> Any:  # pragma: no cover - compiled
    """numba body: a value's trim level, ``min(⌊v/spacing⌋, cap)`` (the numpy version's)."""
    return np.int64(min(np.floor(float(v) / spacing), cap))


def _trim_few_py(
    values: Any,
    valid: Any,
    few: Any,
    spacing: float,
    max_bins: int,
    partners: Any,
    longer: Any,
    out: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: :func:`photoquant.response.censoring.trim_censored_partners`'s statistic
    for every (exposure ``k``, partner slot ``s``, level of ``k``) cell at once, over the
    pixels ``few`` (those with one or two usable values: the only ones it trims).

    ``partners (K, 2)``: each exposure's nearest shorter and longer partners
    (−1: none); ``longer (K, 2)``: whether the partner is the longer one. A
    level's partners are ranked by level (from the bottom for a longer
    partner, from the top for a shorter one), ties in pixel order.
    """
    n_k = values.shape[0]
    cap = float(max_bins - 1)
    n_all = np.zeros((n_k, max_bins), dtype=np.int64)
    n_cens = np.zeros((n_k, 2, max_bins), dtype=np.int64)
    for i in range(few.size):
        p = few[i]
        for k in range(n_k):
            if not valid[k, p]:
                continue
            lk = _level(values[k, p], spacing, cap)
            n_all[k, lk] += 1
            for s in range(2):
                j = partners[k, s]
                if j >= 0 and not valid[j, p]:
                    n_cens[k, s, lk] += 1
    # per cell: every partner goes (drop_all), or the partial tail (a row of hist), or none
    row = np.full((n_k, 2, max_bins), -1, dtype=np.int64)
    drop_all = np.zeros((n_k, 2, max_bins), dtype=np.bool_)
    n_rows = 0
    for k in range(n_k):
        for s in range(2):
            for lev in range(max_bins):
                c = n_cens[k, s, lev]
                if c > 0:
                    if c >= n_all[k, lev] - c:
                        drop_all[k, s, lev] = True
                    else:
                        row[k, s, lev] = n_rows
                        n_rows += 1
    hist = np.zeros((n_rows, max_bins), dtype=np.int64)
    thr = np.zeros(n_rows, dtype=np.int64)
    left = np.zeros(n_rows, dtype=np.int64)
    data = (values, valid, few, spacing, cap, partners, longer)
    cells = (drop_all, row, hist, thr, left)
    _trim_visit(data, cells, out, np.bool_(False))  # not a literal: one compilation for both
    if n_rows == 0:
        return
    # per partial cell: the partner level holding its n_cens-th partner, and how many of
    # the partners at that level still go (the first ones in pixel order)
    for k in range(n_k):
        for s in range(2):
            for lev in range(max_bins):
                r = row[k, s, lev]
                if r < 0:
                    continue
                need = n_cens[k, s, lev]
                cum = np.int64(0)
                for lev_j in range(max_bins):
                    prev = cum
                    cum += hist[r, lev_j]
                    if cum >= need:
                        thr[r] = lev_j
                        left[r] = need - prev
                        break
    _trim_visit(data, cells, out, np.bool_(True))


def _trim_visit_py(data: Any, cells: Any, out: Any, final: bool) -> None:  # pragma: no cover
    """numba body: every usable partner value of the pixels ``few``, in pixel order. First
    visit: the partners of drop-all cells go, the partial cells' partner levels are
    counted (``hist``); final visit: the partial cells' partners below their threshold
    level go, and the first ``left`` at it. ``data``: :func:`_trim_few_py`'s arguments,
    ``cells``: its per-cell arrays."""
    values, valid, few, spacing, cap, partners, longer = data
    drop_all, row, hist, thr, left = cells
    n_k = values.shape[0]
    n_lev = hist.shape[1]
    for i in range(few.size):
        p = few[i]
        for k in range(n_k):
            if not valid[k, p]:
                continue
            lk = _level(values[k, p], spacing, cap)
            for s in range(2):
                j = partners[k, s]
                if j < 0 or not valid[j, p]:
                    continue
                if drop_all[k, s, lk]:
                    if not final:
                        out[j, p] = False
                    continue
                r = row[k, s, lk]
                if r < 0:
                    continue
                lj = _level(values[j, p], spacing, cap)
                if not longer[k, s]:
                    lj = np.int64(n_lev - 1) - lj
                if not final:
                    hist[r, lj] += 1
                elif lj < thr[r]:
                    out[j, p] = False
                elif lj == thr[r] and left[r] > 0:
                    out[j, p] = False
                    left[r] -= 1


# ---------------------------------------------------------------------------
# histogram sample selection (select_samples_histogram)
# ---------------------------------------------------------------------------


def _histogram_bins_py(
    values: Any, valid: Any, usable: Any, c_max: float, n_bins: int, bins: Any, counts: Any
) -> None:  # pragma: no cover - compiled by numba
    """numba body: each usable pixel's value bin per exposure (``n_bins`` when unusable) and
    the count of each (exposure, bin) cell; the numpy version's float64 arithmetic.

    The counts go to four sub-histograms in turn: neighbouring pixels mostly
    share a bin, and one histogram would chain their increments.
    """
    n_k, n_p = values.shape
    pow2 = (n_bins & (n_bins - 1)) == 0
    width = c_max / n_bins
    cap = float(n_bins - 1)
    full = np.empty(n_p, dtype=np.int16)
    sub = np.zeros((4, n_bins + 1), dtype=np.int64)
    n_u = usable.size
    n_4 = n_u - n_u % 4
    for k in range(n_k):
        # every pixel's bin in one contiguous pass (it vectorises), then the usable ones:
        # 4.5 -> 2.6 ms a channel of the response benchmark (2026-12-02)
        if pow2:
            for p in range(n_p):
                s = min(float(values[k, p]) / width, cap)
                full[p] = np.int16(s) if valid[k, p] else np.int16(n_bins)
        else:
            for p in range(n_p):
                s = min(float(values[k, p]) / c_max * n_bins, cap)
                full[p] = np.int16(s) if valid[k, p] else np.int16(n_bins)
        for i in range(n_u):
            bins[k, i] = full[usable[i]]
        sub[:] = 0
        for i in range(0, n_4, 4):
            sub[0, bins[k, i]] += 1
            sub[1, bins[k, i + 1]] += 1
            sub[2, bins[k, i + 2]] += 1
            sub[3, bins[k, i + 3]] += 1
        for i in range(n_4, n_u):
            sub[0, bins[k, i]] += 1
        for b in range(n_bins + 1):
            counts[k, b] += sub[0, b] + sub[1, b] + sub[2, b] + sub[3, b]


def _stable_order_py(key: Any, members: Any, a: Any, b: Any) -> Any:  # pragma: no cover
    """numba body: the positions ``0 … n − 1`` of ``members`` ordered by ``key[members]``,
    ties in position order (``np.argsort(key[members], kind="mergesort")``'s order: a stable
    sort's permutation is unique), by a bottom-up merge sort in the scratch arrays ``a`` and
    ``b`` (at least ``n`` long each); returns the one holding the order. numba's own stable
    ``argsort`` gives the same order and cost 1.6 s to compile (2026-12-07); no NaN keys
    (the caller's candidates have ``key < limit``)."""
    n = members.size
    src = a[:n]
    dst = b[:n]
    for i in range(n):
        src[i] = i
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid = min(lo + width, n)
            hi = min(lo + 2 * width, n)
            i = lo
            j = mid
            o = lo
            while i < mid and j < hi:
                if key[members[src[j]]] < key[members[src[i]]]:  # a tie keeps the left first
                    dst[o] = src[j]
                    j += 1
                else:
                    dst[o] = src[i]
                    i += 1
                o += 1
            while i < mid:
                dst[o] = src[i]
                i += 1
                o += 1
            while j < hi:
                dst[o] = src[j]
                j += 1
                o += 1
        src, dst = dst, src
        width *= 2
    return src


def _rank_candidates_py(
    bins: Any, key: Any, limits: Any, n_cells: int, best: Any
) -> None:  # pragma: no cover - compiled by numba
    """numba body: per exposure, the rank by key of each candidate (key below its cell's
    limit) within its value bin; ``best`` keeps each pixel's lowest rank."""
    n_k, n_u = bins.shape
    cand = np.empty(n_u, dtype=np.int64)
    start = np.empty(n_cells + 1, dtype=np.int64)
    fill = np.empty(n_cells, dtype=np.int64)
    grouped = np.empty(n_u, dtype=np.int64)
    scratch_a = np.empty(n_u, dtype=np.int64)
    scratch_b = np.empty(n_u, dtype=np.int64)
    for k in range(n_k):
        n_c = 0
        start[:] = 0
        for i in range(n_u):
            b = bins[k, i]
            if key[i] < limits[k, b]:
                cand[n_c] = i
                n_c += 1
                start[b + 1] += 1
        for b in range(n_cells):
            start[b + 1] += start[b]
        for b in range(n_cells):
            fill[b] = start[b]
        for c in range(n_c):  # a stable counting sort by bin: pixel order within a bin
            i = cand[c]
            b = bins[k, i]
            grouped[fill[b]] = i
            fill[b] += 1
        for b in range(n_cells):
            lo = start[b]
            hi = start[b + 1]
            if hi - lo == 0:
                continue
            members = grouped[lo:hi]
            order = _stable_order(key, members, scratch_a, scratch_b)  # stable: as lexsort
            for r in range(order.size):
                i = members[order[r]]
                if r < best[i]:
                    best[i] = r


# ---------------------------------------------------------------------------
# eq. 7's normal equations (debevec1997._normal_equations)
# ---------------------------------------------------------------------------


def _normal_blocks_py(
    idx: Any,
    coef: Any,
    scaled: Any,
    nge: Any,
    n_k: int,
    n_g: int,
    s_pair: Any,
    s_prod: Any,
    n_gg: Any,
    corr: Any,
) -> None:  # pragma: no cover - compiled by numba
    """numba body: eq. 7's ``N_gg`` (data rows, then the smoothness and gauge terms
    ``s_pair, s_prod``) and the Schur correction ``Σ scaled_a nge_b``, both ``(n_g·n_g,)``.

    Pixel by pixel, the pairs of its entries: the flattened ``(P, 2K, 2K)`` order
    of the numpy version's ``bincount`` weights, so each cell's terms are added in
    the same order. The terms that are zero are skipped: the data terms of two
    different rows, and the pairs with an entry whose coefficient is 0 (an unused
    value, or the upper knot of a value on a level, as every integer value of one
    repeat is: its ``scaled`` and ``nge`` are ``±0.0`` too). Both sums start at
    ``+0.0`` and round to nearest, so neither is ever ``−0.0``, and adding
    ``±0.0`` changes no bit of them. Measured (2026-12-06, 2000 pixels, K = 6,
    256 levels, one repeat of integers): 0.37 → 0.12 ms; half the values between
    levels 0.20 ms; K = 8 0.65 → 0.18 ms.
    """
    two_k, n_p = idx.shape
    level = np.empty(two_k, dtype=np.int64)
    row = np.empty(two_k, dtype=np.int64)
    c = np.empty(two_k)
    sc = np.empty(two_k)
    ng = np.empty(two_k)
    for p in range(n_p):
        m = 0  # the pixel's entries with a coefficient, in order
        for a in range(two_k):
            if coef[a, p] != 0.0:
                level[m] = idx[a, p]
                row[m] = a % n_k
                c[m] = coef[a, p]
                sc[m] = scaled[a, p]
                ng[m] = nge[a, p]
                m += 1
        for x in range(m):
            base = level[x] * n_g
            for y in range(m):
                cell = base + level[y]
                if row[x] == row[y]:
                    n_gg[cell] += c[x] * c[y]
                corr[cell] += sc[x] * ng[y]
    for i in range(s_pair.size):
        n_gg[s_pair[i]] += s_prod[i]


def _normal_terms_py(
    valid: Any,
    weights: Any,
    log_tk: Any,
    knot_pos: Any,
    top: int,
    n_g: int,
    s_pair: Any,
    s_prod: Any,
) -> tuple[Any, ...]:  # pragma: no cover - compiled by numba
    """numba body: every array of eq. 7's normal equations from the data rows ``(K, P)``.

    The elementwise terms of :func:`~photoquant.response.debevec1997._normal_equations`
    (``w``, the two levels ``idx`` and coefficients ``coef`` of each value, ``w ln t``,
    ``d``, ``N_ge``) with the same operations in the same order, and its sums —
    ``d`` and ``rhs_e`` over the exposures, the ``bincount`` sums over the flattened
    ``(2K, P)`` entries, ``N_gg`` and the Schur correction as :func:`_normal_blocks_py`
    — in the numpy version's order: the same bits, one pass instead of a dozen.
    Returns ``w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, support``.
    """
    n_k, n_p = valid.shape
    w = np.empty((n_k, n_p))
    wlt = np.empty((n_k, n_p))
    alpha = np.empty((n_k, n_p))
    idx = np.empty((2 * n_k, n_p), dtype=np.int64)
    coef = np.empty((2 * n_k, n_p))
    i_cap = max(top - 1, 0)
    for k in range(n_k):
        for p in range(n_p):
            ok = valid[k, p]
            wk = weights[k, p] if ok else 0.0
            u = min(knot_pos[k, p] if ok else 0.0, top)
            i0 = np.int64(min(np.floor(u), i_cap))
            alpha[k, p] = u - i0
            w[k, p] = wk
            wlt[k, p] = wk * log_tk[k, p]
            idx[k, p] = i0
            idx[n_k + k, p] = i0 + 1
            coef[k, p] = wk * (1 - alpha[k, p])
            coef[n_k + k, p] = wk * alpha[k, p]
    # sums over the exposures as numpy's axis-0 reduction makes them: the first row, then
    # each next row added
    d = np.empty(n_p)
    rhs_e = np.empty(n_p)
    for p in range(n_p):
        d[p] = w[0, p] * w[0, p]
        rhs_e[p] = w[0, p] * wlt[0, p]
    for k in range(1, n_k):
        for p in range(n_p):
            d[p] += w[k, p] * w[k, p]
            rhs_e[p] += w[k, p] * wlt[k, p]
    for p in range(n_p):
        rhs_e[p] = -rhs_e[p]
    nge = np.empty((2 * n_k, n_p))
    scaled = np.empty((2 * n_k, n_p))
    rhs_g = np.zeros(n_g)
    back = np.zeros(n_g)
    support = np.zeros(n_g + 1)
    for a in range(2 * n_k):  # each sum in the flattened (2K, P) order of its bincount
        k = a % n_k
        for p in range(n_p):
            nge[a, p] = -w[k, p] * coef[a, p]
            scaled[a, p] = nge[a, p] / d[p]
            rhs_g[idx[a, p]] += coef[a, p] * wlt[k, p]
            back[idx[a, p]] += nge[a, p] * (rhs_e[p] / d[p])
            if valid[k, p]:  # an invalid value's 0 leaves the (non-negative) sum as it is
                support[idx[a, p]] += (1 - alpha[k, p]) if a < n_k else alpha[k, p]
    n_gg = np.zeros(n_g * n_g)
    corr = np.zeros(n_g * n_g)
    normal_blocks(idx, coef, scaled, nge, n_k, n_g, s_pair, s_prod, n_gg, corr)
    schur = np.empty((n_g, n_g))
    for i in range(n_g):
        for j in range(n_g):
            schur[i, j] = n_gg[i * n_g + j] - corr[i * n_g + j]
    r_red = np.empty(n_g)
    kept = np.empty(n_g)
    for i in range(n_g):
        r_red[i] = rhs_g[i] - back[i]
        kept[i] = support[i]
    return w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, kept


def _back_substitution_py(
    rhs_e: Any, nge: Any, idx: Any, coef: Any, d: Any, w: Any, wlt: Any, valid: Any, g: Any
) -> tuple[Any, Any]:  # pragma: no cover - compiled by numba
    """numba body: :func:`~photoquant.response.debevec1997._back_substitution`'s
    ``ln E_p`` ``(P,)`` and data rows' residuals ``(K, P)``, each with its numpy
    version's operations in the same order (the sum over the ``2K`` entries row after
    row)."""
    two_k, n_p = idx.shape
    n_k = two_k // 2
    log_e = np.empty(n_p)
    for p in range(n_p):
        acc = nge[0, p] * g[idx[0, p]]
        for a in range(1, two_k):
            acc += nge[a, p] * g[idx[a, p]]
        log_e[p] = (rhs_e[p] - acc) / d[p]
    residual = np.empty((n_k, n_p))
    for k in range(n_k):
        for p in range(n_p):
            if valid[k, p]:
                fitted = coef[k, p] * g[idx[k, p]] + coef[n_k + k, p] * g[idx[n_k + k, p]]
                residual[k, p] = fitted - w[k, p] * log_e[p] - wlt[k, p]
            else:
                residual[k, p] = 0.0
    return log_e, residual


def _symmetric_part_py(schur: Any, prior: Any) -> Any:  # pragma: no cover - compiled by numba
    """numba body: ``0.5 (S + Sᵀ)`` of ``S = schur + prior`` (``prior`` of shape ``(0, 0)``:
    none), each entry as numpy's ``0.5 * (s + s.T)`` makes it (the same bits, one pass
    over each half instead of four passes and a strided transpose)."""
    n = schur.shape[0]
    with_prior = prior.shape[0] == n
    out = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            a = schur[i, j]
            b = schur[j, i]
            if with_prior:
                a = a + prior[i, j]
                b = b + prior[j, i]
            out[i, j] = 0.5 * (a + b)
            out[j, i] = 0.5 * (b + a)
    return out


def _sandwich_meat_py(idx: Any, coef: Any, residual: Any, n_g: int) -> Any:  # pragma: no cover
    """numba body: ``Σ_p s_p s_pᵀ`` (flat ``(n_g·n_g,)``), ``s_p`` pixel ``p``'s score.

    Entry ``a`` of pixel ``p`` (``(2K, P)``: its level ``idx``, coefficient
    ``coef``, its row's residual ``residual[a mod K]``) scores
    ``coef · residual``; the products of every pair of a pixel's entries are
    added in the flattened ``(2K, 2K, P)`` order of the numpy version's
    ``bincount`` (:func:`photoquant.response.covariance._sandwich_meat_numpy`),
    those of an entry scoring 0 skipped (the sum starts at ``+0.0`` and rounds
    to nearest, so it is never ``−0.0``, and adding ``±0.0`` changes no bit of it).
    """
    two_k, n_p = idx.shape
    n_k = residual.shape[0]
    score = np.empty((two_k, n_p))
    for a in range(two_k):
        for p in range(n_p):
            score[a, p] = coef[a, p] * residual[a % n_k, p]
    meat = np.zeros(n_g * n_g)
    for a in range(two_k):
        for b in range(two_k):
            for p in range(n_p):
                sa = score[a, p]
                if sa != 0.0:
                    meat[idx[a, p] * n_g + idx[b, p]] += sa * score[b, p]
    return meat


# ---------------------------------------------------------------------------
# the robust fit's noise scales (robust.robust_weights)
# ---------------------------------------------------------------------------


def _band_medians_py(r: Any, used: Any, band: Any, n_bands: int) -> Any:  # pragma: no cover
    """numba body: the median of the used ``r`` in each band, and each band's count.

    The values are gathered band by band in one pass (a counting sort) and
    each band's middle found by a selection (:func:`photoquant._select.median_inplace`):
    its median is its middle value, or the mean of its two middle values,
    ``(a + b) / 2`` as :func:`numpy.median` takes it (NaN where the band holds a NaN, as there)
    — the same bits as one boolean mask and one :func:`numpy.median` a band,
    which pass over every value once per band.
    """
    counts = np.zeros(n_bands, dtype=np.int64)
    for i in range(r.size):
        if used[i]:
            counts[band[i]] += 1
    starts = np.zeros(n_bands + 1, dtype=np.int64)
    for b in range(n_bands):
        starts[b + 1] = starts[b] + counts[b]
    gathered = np.empty(starts[n_bands])
    fill = starts[:n_bands].copy()
    for i in range(r.size):
        if used[i]:
            gathered[fill[band[i]]] = r[i]
            fill[band[i]] += 1
    medians = np.full(n_bands, np.nan)
    for b in range(n_bands):
        n = counts[b]
        if n == 0:
            continue
        values = gathered[starts[b] : starts[b + 1]]
        if np.isnan(values).any():
            continue
        medians[b] = median_inplace(values)  # the scratch copy's order is not kept
    return medians, counts


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    usable_masks = compile_kernel(_usable_masks_py)
    shared_exposures = compile_kernel(_shared_exposures_py)
    _level = compile_kernel(_level_py)
    _trim_visit = compile_kernel(_trim_visit_py)
    trim_few = compile_kernel(_trim_few_py)
    histogram_bins = compile_kernel(_histogram_bins_py)
    _stable_order = compile_kernel(_stable_order_py)
    rank_candidates = compile_kernel(_rank_candidates_py)
    normal_blocks = compile_kernel(_normal_blocks_py)
    # a pixel without a valid value divides by 0: inf, refused by the caller (no exception)
    normal_terms = compile_kernel(_normal_terms_py, error_model="numpy")
    band_medians = compile_kernel(_band_medians_py)
    sandwich_meat = compile_kernel(_sandwich_meat_py)
    symmetric_part = compile_kernel(_symmetric_part_py)
    back_substitution = compile_kernel(_back_substitution_py)
else:  # pragma: no cover - depends on the environment
    usable_masks = shared_exposures = trim_few = None
    histogram_bins = rank_candidates = normal_blocks = normal_terms = band_medians = None
    sandwich_meat = symmetric_part = back_substitution = None
