"""Censored exposure pairs: symmetric trimming of the partners of a level (Powell 1986).

A response fit pairs the values of one pixel in two exposures ``k`` and ``j``.
When ``j`` is the longer one, its value is *censored* (clipped at the
saturation level, or otherwise excluded) for the brighter pixels: among the
pixels at one level ``c`` of ``k``, only those whose ``j`` value stayed below
the clip remain as pairs, the lower part of the distribution of ``j`` values
given ``c``. Fitting ``g`` to those pairs (eq. 7 of [PQ]_, any per-pixel
least-squares or median statistic) is biased: ``g(c)`` is tied to too dark a
partner. It is the same selection as a regression on a censored response
variable (the Tobit model, [Tobin1958]_), and it is worst exactly where a
level's partners are mostly clipped: there the few pairs left are the far
tail of the distribution, often outliers (a moving or misregistered pixel).
The mirror case is a shorter partner ``j`` whose values are dark-clipped.

Symmetric trimming [Powell1986]_ removes the bias without a model of the
distribution: if ``n_c`` of a level's ``n`` partners are censored in one
tail, the ``n_c`` most extreme partners of the *other* tail are dropped too,
so that what is left is the distribution's central part, symmetric about its
median as the untruncated distribution is (Powell's estimator is consistent
for any symmetric error distribution). A level with half its partners or
more censored keeps none: its median is itself censored, and the pairs
carry no unbiased information. Where nothing is censored nothing changes:
the step acts only on the censored pairs, at the levels where a partner
exposure clips.

The statistic is taken per (exposure ``k``, level of ``k``, partner ``j``),
levels being the response's levels (one per code value at 8 bits; at most
256 over the data), for the *nearest* shorter and longer partners ``j`` of
each exposure (the nearest that shares usable pixels with it: in a
combination of stacks, :func:`photoquant.exposure.combine_stacks`, another
stack's exposures are none of its partners): censoring is monotone in the
exposure time (a pixel clipped
at ``j`` is clipped at every longer one), so a pixel's usable exposures are
contiguous in time and the selection of the pixels that pair with level
``c`` happens at the nearest partner; a farther partner is reached through
the chain of nearer ones (trimming it too would drop most of a long
bracket's data: measured on pqsim's EMoR camera, ``g`` rms 0.0057 → 0.0137).
Only the pixels with at most two usable values are trimmed (and counted):
eq. 7 takes a pixel only when two of its values are usable, so for them the
censoring of the partner decides whether the pixel enters the fit at all,
and its ``ln E_p`` rests on that one pair. A pixel with three or more usable
values has ``ln E_p`` fixed by the others as well; trimming those too costs
more than it removes on clean data (measured on pqsim's CCD preset, 120×160,
N = 4, exact times: test-scene error 1.19 % → 1.32 %, against 1.19 % with
this restriction). A trimmed partner value is excluded from the fit.

References
----------
.. [Powell1986] Powell, J. L. (1986). Symmetrically trimmed least squares
   estimation for Tobit models. *Econometrica* 54(6), 1435-1460.
   doi:10.2307/1914308
.. [Tobin1958] Tobin, J. (1958). Estimation of relationships for limited
   dependent variables. *Econometrica* 26(1), 24-36. doi:10.2307/1907382
.. [PQ] The photoquantity paper, §5.2, eq. 7.
"""

from __future__ import annotations

import numpy as np

from photoquant.errors import InputError
from photoquant.response import _kernels

__all__ = ["CENSORING_MODES", "trim_censored_partners"]

_MAX_BINS = 256
"""Most levels the statistic is taken over (coarser levels above 8 bits)."""

CENSORING_MODES = ("trimmed", "ignored")
"""Treatments of censored partners in the response fit: symmetric trimming
(:func:`trim_censored_partners`) or none (the paper's)."""


def trim_censored_partners(
    values: np.ndarray,
    valid: np.ndarray,
    exposure_s: np.ndarray,
    spacing: float = 1.0,
) -> np.ndarray:
    """Drop the partners of censored exposure pairs symmetrically [Powell1986]_.

    Parameters
    ----------
    values : ndarray, shape (K, P)
        Denoised values of one channel at ``K`` exposures.
    valid : ndarray, shape (K, P) of bool
        Whether each value is usable; an unusable value is censored (clipped
        at the saturation level, dark-clipped, or otherwise excluded).
    exposure_s : ndarray, shape (K,)
        Exposure times (distinct).
    spacing : float
        Width of a level: the statistic is taken per level ``⌊value / spacing⌋``
        (at most 256 levels over the data: coarser above 8 bits).

    Returns
    -------
    ndarray, shape (K, P) of bool
        ``valid`` with, for every exposure ``k``, level ``c`` of ``k`` and
        nearest partner ``j`` (the next shorter and the next longer sharing
        usable pixels with ``k``), among
        the pixels with at most two usable values, the ``n_c`` lowest ``j`` values dropped where ``n_c``
        of the level's pixels have ``j`` censored and ``j`` is longer (the
        ``n_c`` highest where ``j`` is shorter); all of them where
        ``n_c ≥ n/2``. Partners are ranked by their level, and within a level by
        pixel index (deterministic).
    """
    values = np.asarray(values)
    valid = np.asarray(valid, dtype=bool)
    t = np.asarray(exposure_s, dtype=np.float64)
    if values.ndim != 2 or valid.shape != values.shape or t.shape != (values.shape[0],):
        raise InputError(
            "`values` and `valid` must have shape (K, P) and `exposure_s` shape (K,), got "
            f"{values.shape}, {valid.shape} and {t.shape}"
        )
    if not spacing > 0:
        raise InputError(f"`spacing` must be positive, got {spacing}")
    if values.shape[0] < 2:
        return valid.copy()
    if _kernels.HAVE_NUMBA and (values.dtype == np.float64 or values.dtype.kind in "iu"):
        return _trim_compiled(values, valid, t, float(spacing))
    return _trim_numpy(values, valid, t, float(spacing))


def _partners(shared: np.ndarray, t: np.ndarray) -> list[tuple[int, list[int]]]:
    """Each exposure (by increasing time) with its nearest shorter and longer partners
    among the exposures it shares usable pixels with (module notes)."""
    by_time = np.argsort(t, kind="stable")
    out = []
    for rank_k, k in enumerate(by_time):
        shorter = [int(j) for j in by_time[:rank_k][::-1] if shared[k, j]][:1]
        longer = [int(j) for j in by_time[rank_k + 1 :] if shared[k, j]][:1]
        out.append((int(k), shorter + longer))
    return out


def _shared_exposures(valid: np.ndarray) -> np.ndarray:
    """``(K, K)`` bool: some pixel is usable in both exposures. An exposure that shares
    none with ``k`` (another stack's, in a combination of stacks) is no partner of ``k``.

    Bit-packed rows ANDed: a float matrix product here goes through BLAS, whose
    threads made it take 5 ms to 1.9 s on a loaded machine.
    """
    packed = np.packbits(valid, axis=1)
    return np.stack([(packed[k] & packed).any(axis=1) for k in range(valid.shape[0])])


def _trim_compiled(
    values: np.ndarray, valid: np.ndarray, t: np.ndarray, spacing: float
) -> np.ndarray:
    """:func:`_trim_numpy`'s result from the compiled kernels (:mod:`._kernels`): the same
    bits, from one pass over the values and three over the pixels with one or two usable
    values (the only ones trimmed), every (exposure, partner, level) cell at once."""
    k_count, n_p = values.shape
    masks = np.zeros(n_p, dtype=np.int64)
    count = np.zeros(n_p, dtype=np.int64)
    top = _kernels.usable_masks(values, valid, masks, count)
    spacing = max(spacing, top / (_MAX_BINS - 1))  # at most _MAX_BINS levels
    if k_count <= 62:
        shared = np.zeros((k_count, k_count), dtype=bool)
        _kernels.shared_exposures(masks, shared)
    else:  # the kernel's bit masks hold 62 exposures
        shared = _shared_exposures(valid)
    partners = np.full((k_count, 2), -1, dtype=np.int64)
    longer = np.zeros((k_count, 2), dtype=bool)
    for k, nearest in _partners(shared, t):
        for s, j in enumerate(nearest):
            partners[k, s], longer[k, s] = j, t[j] > t[k]
    few = np.flatnonzero((count >= 1) & (count <= 2))
    out = valid.copy()
    _kernels.trim_few(values, valid, few, spacing, _MAX_BINS, partners, longer, out)
    return out


def _trim_numpy(values: np.ndarray, valid: np.ndarray, t: np.ndarray, spacing: float) -> np.ndarray:
    """The readable version of :func:`trim_censored_partners` (numpy passes; the reference
    of the compiled one)."""
    out = valid.copy()
    top = float(np.max(values, where=valid, initial=0.0))
    spacing = max(float(spacing), top / (_MAX_BINS - 1))  # at most _MAX_BINS levels
    level = np.minimum(np.floor(np.where(valid, values, 0.0) / spacing), _MAX_BINS - 1)
    level = level.astype(np.int64)
    n_lev = int(level.max()) + 1
    shared = _shared_exposures(valid)
    # the pixels whose entry into the fit the pair decides: two usable values at most
    few = valid.sum(axis=0) <= 2
    for k, nearest in _partners(shared, t):
        partners = np.array(nearest, dtype=np.int64)
        if partners.size == 0:
            continue
        in_k = np.flatnonzero(valid[k] & few)
        if in_k.size == 0:
            continue
        lev_k = level[k, in_k]
        n_p = partners.size
        partner_ok = valid[partners][:, in_k]  # (n_p, n_k)
        n = np.bincount(lev_k, minlength=n_lev)
        # censored partners per (partner, level of k), one bincount for both
        cell = np.arange(n_p)[:, None] * n_lev + lev_k[None, :]
        n_cens = np.bincount(cell[~partner_ok], minlength=n_p * n_lev).reshape(n_p, n_lev)
        if not n_cens.any():
            continue
        # levels with half or more censored: every remaining partner goes
        drop_all = (n_cens > 0) & (n_cens >= n[None, :] - n_cens)
        partial = (n_cens > 0) & ~drop_all
        rows, pos = np.nonzero(partner_ok & drop_all[:, lev_k])
        out[partners[rows], in_k[pos]] = False
        rows, pos = np.nonzero(partner_ok & partial[:, lev_k])
        if rows.size == 0:
            continue
        jj, pix = partners[rows], in_k[pos]
        cell_c = rows * n_lev + lev_k[pos]
        # the partner's level, counted from the tail opposite the censored one:
        # the lowest values of a longer partner (it clips at the top), the
        # highest of a shorter one
        lev_j = level[jj, pix]
        lev_j = np.where(t[jj] > t[k], lev_j, n_lev - 1 - lev_j)
        # per cell, the partner level holding its n_cens-th partner (a counting
        # sort: the histogram of partner levels, cumulated)
        hist = np.bincount(cell_c * n_lev + lev_j, minlength=n_p * n_lev * n_lev)
        cum = np.cumsum(hist.reshape(n_p * n_lev, n_lev), axis=1)
        need = n_cens.ravel()
        thr = np.argmax(cum >= need[:, None], axis=1)  # cells without candidates: unused
        below = np.where(thr > 0, cum[np.arange(cum.shape[0]), thr - 1], 0)
        t_c = thr[cell_c]
        out[jj[lev_j < t_c], pix[lev_j < t_c]] = False
        # at the threshold level, the first (need − below) partners in pixel order
        at = np.flatnonzero(lev_j == t_c)
        if at.size:
            order = at[np.argsort(cell_c[at], kind="stable")]  # candidates: pixel order
            c_sorted = cell_c[order]
            rank = np.arange(order.size) - np.searchsorted(c_sorted, c_sorted, side="left")
            drop = order[rank < (need - below)[c_sorted]]
            out[jj[drop], pix[drop]] = False
    return out
