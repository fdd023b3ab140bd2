"""The uncertainty of a recovered response ``g``: its covariance, as a low-rank factor.

A response is estimated from a few thousand sampled pixels; another sample
(or another capture of the same scene) gives another ``g``. The spread of
``g`` is the response's part of every photoquantity's *calibration*
uncertainty: it is common to every scene corrected with the camera, and
strongly correlated across levels (an error in the slope of ``g`` moves
every level), so it does not average down over a pixel's exposures or over
repeats.

Covariance of eq. 7's least-squares solution
--------------------------------------------
Eq. 7 of Debevec & Malik is a linear least-squares problem in ``g`` and the
per-pixel ``ln E_p``; with the pixel unknowns eliminated its normal matrix is
the Schur complement ``S`` (data, smoothness prior and gauge). The
data rows of one pixel share its ``ln E_p`` and its scene content (motion,
glare, a defect), and their noise differs from level to level (hat weights
are not inverse variances), so the textbook ``σ² S⁻¹`` would be wrong twice.
The *cluster-robust sandwich* [Huber1967]_ [White1980]_ [Liang1986]_ with
the pixel as the cluster holds under both::

    Cov(g) = S⁻¹ M S⁻¹,   M = P/(P − 1) · Σ_p s_p s_pᵀ,

``s_p = A_pᵀ r_p`` the score of pixel ``p`` (its rows' coefficients on the
levels times their residuals at the solution; the ``ln E_p`` column is
orthogonal to it there). The smoothness prior enters the bread ``S`` and not
the meat ``M``: it is treated as known. What the sandwich does not contain
is the prior's own bias (a smooth ``g`` where the true one bends) and the
exposure times' errors; both are systematic and appear in the validation
against the truth (``tests/photoquant/test_response_covariance.py``).

Every score is orthogonal to a constant shift of ``g`` (``Σ_k w_k r_pk = 0``
at each pixel's optimum), so ``Cov(g)`` carries no variance along the
gauge: the covariance is that of ``g`` relative to the level where the fit
fixed ``g = 0`` — the absolute scale of a photoquantity is not measured by a
response, only ratios are.

What the sandwich misses, and the exposure jackknife
----------------------------------------------------
The sandwich is the statistical part of ``g``'s error only. Against the
truth, Debevec's ``g`` is also *biased* by the noise: the levels are a noisy
regressor (errors in variables, each pixel's ``ln E_p`` estimated from its
own noisy values), and the bias is a ripple with the bracket's step plus a
drift that grows with the noise — relative to the gauge about three stated
standard deviations at 2 DN (``tools/response_bias.py``). Its pattern is
tied to where the exposures fall on ``ln X``. :func:`exposure_jackknife_factor`
states ``Cov(g)`` as the delete-one jackknife over the exposures [Efron1981]_
[Shao1995]_, ``(K − 1)/K · Σ_k (g₋ₖ − ḡ)(g₋ₖ − ḡ)ᵀ``, as a factor of ``K``
rows: ``"Debevec 1997"`` with ``covariance="exposure jackknife"`` fits ``g``
``K`` more times, each without one exposure and drawing its own sample
(``K ≥`` :data:`MIN_JACKKNIFE_EXPOSURES`). It is an empirical statement of
the total error, measured, not a model of the bias. Measured against the
truth (2026-12-04):

* analytic brackets (K = 8, γ 2.2, 60×80, 10 captures), ``g`` at eight
  levels relative to the gauge: at 0.7 DN of noise 96 % within 1.96 stated
  σ (the sandwich: 70 %; rms ``z`` 0.94 against 1.73), at 2 DN 74 % (30 %;
  1.70 against 3.17);
* pqsim through the whole pipeline (``tools/parameter_coverage.py``, 64×48,
  N = 2, V = 3, seeds 0–49): the corrected test scene's channel scale over
  its stated σ, which the response's error relative to the white chart
  dominates — see the correct guide for the figures.

The same sample held (one solve per exposure left out, the robust rounds'
row weights kept) states far less (at 2 DN 40 % within 1.96 σ): the
jackknife's spread comes with each fit's own sample, robust weights and
prior, not from the left-out exposure's rows alone. Its cost is ``K``
fits: at 1024×768 one view's calibration 0.25 → 0.69 s (K = 4) and
0.82 s (K = 8), hence not the default. Where a fit without one exposure
fails (a gap no pixel bridges), the sandwich is kept and the report says
why.

An uncorrected bias, stated
---------------------------
A fit whose options leave a known bias in ``g`` (the paper's eq. 7 as
written: regression dilution in the noise, a random sample of 500 pixels,
the toe and censored pairs untreated) can keep its ``g`` and still state
an honest uncertainty: :func:`uncorrected_bias_factor` takes the
difference ``δg = g − g_ref`` from a fit of the same frames that corrects
those biases, in ``g``'s gauge, as one more row of the factor — the
bias's direction from the data, its size stated as one standard
uncertainty. This is the RSSu treatment of an uncorrected bias
[Phillips1997]_ (GUM F.2.4.5): ``u² = u_c² + b²``, ``g`` itself
unchanged. Its own error is the reference fit's, a small part of it
(``"Debevec 1997"`` with ``uncorrected_bias="stated"``; the paper's
profile).

Low-rank factor
---------------
``Cov(g)`` is kept as ``F`` with ``Cov ≈ Fᵀ F`` (the leading eigenvectors,
scaled by the square roots of their eigenvalues, until :data:`KEPT_FRACTION`
of the trace), so that propagating it through a merge costs one table
look-up per component and exposure (:mod:`photoquant.merge.uncertainty`).

References
----------
.. [Huber1967] Huber, P. J. (1967). The behavior of maximum likelihood
   estimates under nonstandard conditions. Proc. Fifth Berkeley Symposium
   on Mathematical Statistics and Probability 1, 221-233.
.. [White1980] White, H. (1980). A heteroskedasticity-consistent covariance
   matrix estimator and a direct test for heteroskedasticity. Econometrica
   48(4), 817-838. doi:10.2307/1912934
.. [Liang1986] Liang, K.-Y., & Zeger, S. L. (1986). Longitudinal data
   analysis using generalized linear models. Biometrika 73(1), 13-22.
   doi:10.1093/biomet/73.1.13
.. [Efron1981] Efron, B., & Stein, C. (1981). The jackknife estimate of
   variance. The Annals of Statistics 9(3), 586-596.
   doi:10.1214/aos/1176345462
.. [Shao1995] Shao, J., & Tu, D. (1995). *The Jackknife and Bootstrap*.
   Springer, ch. 2 (the delete-one jackknife variance estimator).
.. [Phillips1997] Phillips, S. D., Eberhardt, K. R., & Parry, B. (1997).
   Guidelines for expressing the uncertainty of measurement results
   containing uncorrected bias. J. Res. NIST 102(5), 577-585.
   doi:10.6028/jres.102.038
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from photoquant.errors import InputError
from photoquant.response import _kernels

__all__ = [
    "KEPT_FRACTION",
    "MAX_RANK",
    "MIN_JACKKNIFE_EXPOSURES",
    "cluster_sandwich_covariance",
    "exposure_jackknife_factor",
    "low_rank_factor",
    "uncorrected_bias_factor",
]

MIN_JACKKNIFE_EXPOSURES = 4
"""The fewest exposures the exposure jackknife takes: each of its fits keeps ``K − 1 ≥ 3``
(a fit of two exposures relates one pair of levels per pixel, and its ``g`` is the
prior's between them)."""

KEPT_FRACTION = 0.999
"""Share of ``trace(Cov(g))`` the low-rank factor keeps."""

MAX_RANK = 12
"""Most components of the factor (per channel)."""


def cluster_sandwich_covariance(
    cho: tuple[np.ndarray, bool],
    idx: np.ndarray,
    coef: np.ndarray,
    residual: np.ndarray,
    n_levels: int,
) -> np.ndarray:
    """``S⁻¹ M S⁻¹`` with the pixel as the cluster (module notes).

    Parameters
    ----------
    cho : tuple
        Cholesky factor of the reduced normal matrix ``S`` (:func:`scipy.linalg.cho_factor`).
    idx : ndarray of int, shape (2K, P)
        Levels each value's data row touches (its two interpolation knots).
    coef : ndarray, shape (2K, P)
        The row's coefficients on those levels (0 where the value is unused).
    residual : ndarray, shape (K, P)
        Each data row's residual at the solution (0 where unused).
    n_levels : int
        Unknown levels ``n_g``.

    Returns
    -------
    ndarray, shape (n_g, n_g)
    """
    n_pix = residual.shape[1]
    meat = _sandwich_meat(idx, coef, residual, n_levels) * (n_pix / max(n_pix - 1, 1))
    inverse = _inverse_from_cholesky(cho)
    if inverse is None:  # pragma: no cover - a factor LAPACK made is invertible
        # the factor is a finished factorisation's and the meat is summed from finite
        # residuals: LAPACK's input check would scan both matrices twice more
        half = scipy.linalg.cho_solve(cho, meat, check_finite=False)
        cov = scipy.linalg.cho_solve(cho, half.T, check_finite=False)
    else:
        cov = inverse @ meat @ inverse
    return 0.5 * (cov + cov.T)


def _inverse_from_cholesky(cho: tuple[np.ndarray, bool]) -> np.ndarray | None:
    """``S⁻¹`` from the Cholesky factor of ``S`` (LAPACK's ``potri``), ``None`` where it fails.

    The sandwich ``S⁻¹ M S⁻¹`` as ``S⁻¹`` (``n³/3`` flops past the factor) and
    two matrix products, rather than two solves with ``M`` as the right-hand
    side (four triangular solves of ``n³`` flops each): measured (256 levels,
    one thread, 2026-12-06) 3.5 ms against 8.5 ms, the same matrix to
    ``1.4e-15`` relative. ``S`` is the reduced normal matrix of a fit whose
    factorisation succeeded, so forming its inverse loses nothing the solves
    would keep (both are backward stable to ``cond(S) ε``).
    """
    factor, lower = cho
    inverse, info = scipy.linalg.lapack.dpotri(factor, lower=int(bool(lower)))
    if info != 0:  # pragma: no cover - see the caller
        return None
    part = np.tril(inverse) if lower else np.triu(inverse)
    return part + (np.tril(part, -1).T if lower else np.triu(part, 1).T)


def _sandwich_meat(
    idx: np.ndarray, coef: np.ndarray, residual: np.ndarray, n_levels: int
) -> np.ndarray:
    """``Σ_p s_p s_pᵀ`` ``(n_g, n_g)``: the products of every pair of a pixel's entries,
    each scoring ``coef · residual`` of its row, summed at their two levels.

    A pixel's score touches the ``2K`` levels of its rows only: summed pair by
    pair over the pixels, not as the product of a dense ``(n_g, P)`` score
    matrix with itself (256 levels, 2000 pixels, K = 6, 40 % of the entries
    unused, one thread: 0.4 ms against 5.5 ms for the score matrix and its
    product; the same sums to rounding). Compiled where numba is
    (:func:`photoquant.response._kernels.sandwich_meat`, the same bits).
    """
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    coef = np.ascontiguousarray(coef, dtype=np.float64)
    residual = np.ascontiguousarray(residual, dtype=np.float64)
    if _kernels.HAVE_NUMBA:
        meat = _kernels.sandwich_meat(idx, coef, residual, n_levels)
    else:
        meat = _sandwich_meat_numpy(idx, coef, residual, n_levels)
    return meat.reshape(n_levels, n_levels)


def _sandwich_meat_numpy(
    idx: np.ndarray, coef: np.ndarray, residual: np.ndarray, n_levels: int
) -> np.ndarray:
    """The readable version of :func:`_sandwich_meat` (flat ``(n_g·n_g,)``): one
    :func:`numpy.bincount` over the flattened ``(2K, 2K, P)`` pairs of entries."""
    score = coef * np.concatenate([residual, residual])  # each entry's row residual
    pair = (idx[:, None] * n_levels + idx[None, :]).reshape(-1)
    return np.bincount(pair, (score[:, None] * score[None, :]).reshape(-1), n_levels * n_levels)


def low_rank_factor(
    cov: np.ndarray, fraction: float = KEPT_FRACTION, max_rank: int = MAX_RANK
) -> np.ndarray:
    """``F`` (``(R, n)``) with ``Fᵀ F`` the leading part of ``cov`` (module notes).

    The eigenvectors' signs are fixed (largest entry positive) so that the
    factor is deterministic.
    """
    n = cov.shape[0]
    total = float(np.trace(cov))
    if not total > 0.0:
        return np.zeros((1, n))
    top = min(max_rank, n)
    # the leading eigenpairs only (LAPACK's syevr): a fraction of a full decomposition
    vals, vecs = scipy.linalg.eigh(cov, subset_by_index=[n - top, n - 1])
    vals, vecs = np.clip(vals[::-1], 0.0, None), vecs[:, ::-1]
    rank = int(np.searchsorted(np.cumsum(vals) / total, fraction) + 1)
    rank = max(1, min(rank, top))
    vecs = vecs[:, :rank]
    sign = np.sign(vecs[np.argmax(np.abs(vecs), axis=0), np.arange(rank)])
    return (vecs * np.where(sign == 0, 1.0, sign) * np.sqrt(vals[:rank])).T


def exposure_jackknife_factor(g_left_out: np.ndarray) -> np.ndarray:
    """The delete-one jackknife of ``g`` over the exposures, as a covariance factor.

    Parameters
    ----------
    g_left_out : ndarray, shape (K, C, L)
        ``g`` recovered ``K`` times, each without one exposure, all in the same
        gauge (the level where the fits fixed ``g = 0``).

    Returns
    -------
    ndarray, shape (C, K, L)
        ``F`` with ``Fᵀ F = (K − 1)/K · Σ_k (g₋ₖ − ḡ)(g₋ₖ − ḡ)ᵀ`` per channel
        (module notes, *the exposure jackknife*).

    Raises
    ------
    InputError
        With fewer than two fits, or a value that is not finite.
    """
    g = np.asarray(g_left_out, dtype=np.float64)
    if g.ndim != 3 or g.shape[0] < 2:
        raise InputError(f"`g_left_out` must be (K ≥ 2, C, L), got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise InputError("`g_left_out` must be finite at every level")
    k = g.shape[0]
    rows = np.sqrt((k - 1) / k) * (g - g.mean(axis=0))
    return np.ascontiguousarray(np.moveaxis(rows, 0, 1))


def uncorrected_bias_factor(
    g: np.ndarray, g_reference: np.ndarray, variance: np.ndarray | None = None
) -> np.ndarray:
    """The bias of ``g`` against a reference fit, as one factor row per channel.

    Parameters
    ----------
    g : ndarray, shape (C, L)
        The response kept (natural log, gauge ``g = 0`` at one level).
    g_reference : ndarray, shape (C, L)
        A fit of the same frames at the same levels that corrects the biases
        ``g``'s method leaves (any additive gauge).
    variance : ndarray, shape (C, L), optional
        The statistical variance of the difference at each level (the two
        fits' stated variances): the squared difference holds it beside the
        bias's square, and it is taken away, level by level,
        ``b² = max(δg² − variance, 0)``, so that the row does not state the
        fits' noise a second time. ``None``: the difference as it is.

    Returns
    -------
    ndarray, shape (C, 1, L)
        ``δg = g − g_ref`` less its value at the level where ``g`` crosses 0
        (the gauge of ``g``'s covariance, module notes), shrunk to ``b`` with
        its sign: appended to a factor ``F``, ``Fᵀ F`` gains ``b bᵀ`` (module
        notes, *An uncorrected bias, stated*).

    Raises
    ------
    InputError
        If the shapes differ or a value is not finite.
    """
    g = np.asarray(g, dtype=np.float64)
    ref = np.asarray(g_reference, dtype=np.float64)
    if g.ndim != 2 or ref.shape != g.shape:
        raise InputError(
            f"`g` and `g_reference` must both be (C, L), got shapes {g.shape} and {ref.shape}"
        )
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(ref))):
        raise InputError("`g` and `g_reference` must be finite at every level")
    bias = g - ref
    gauge = np.argmin(np.abs(g), axis=1)
    bias -= bias[np.arange(g.shape[0]), gauge][:, None]
    if variance is not None:
        var = np.asarray(variance, dtype=np.float64)
        if var.shape != g.shape or not np.all(np.isfinite(var)) or np.any(var < 0):
            raise InputError(
                f"`variance` must be (C, L) = {g.shape}, finite and non-negative, "
                f"got shape {var.shape}"
            )
        bias = np.sign(bias) * np.sqrt(np.maximum(bias * bias - var, 0.0))
    return bias[:, None, :]
