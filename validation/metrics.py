"""Comparisons of recovered quantities with ground truth.

Photoquantity is defined up to one global scale, and the calibrated camera
outputs *white-balanced* photoquantity (the white chart comes out neutral).
Every comparison here therefore fits exactly what the method cannot know and
nothing else:

* photoquantity (eq. 8): the reference is the true ``l`` divided, per channel,
  by the true photoquantity of the white chart; then one global scale is fitted;
* response: ``g`` is compared after removing its additive gauge;
* sensor LUT and vignetting: compared directly (both are normalised by
  definition: LUT mean 1, vignetting 1 at its centre).

References
----------
.. [PQ] The photoquantity paper, eq. 8 and §6.3.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "ErrorStats",
    "error_stats",
    "relative_error_eq8",
    "fit_global_scale",
    "channel_scale_ratios",
    "response_error",
    "map_relative_error",
    "correlation",
    "NOMINAL_LEVELS",
    "normalised_errors",
    "interval_shares",
    "uncertainty_coverage",
]


@dataclass(frozen=True)
class ErrorStats:
    """``e_max``, ``e_mean``, ``e_std`` of §6.3 of [PQ] (fractions, not %), and the count."""

    e_max: float
    e_mean: float
    e_std: float
    n: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def __str__(self) -> str:
        return (
            f"e_max {100 * self.e_max:.3f} %, e_mean {100 * self.e_mean:.3f} %, "
            f"e_std {100 * self.e_std:.3f} % (n={self.n})"
        )


def error_stats(e: np.ndarray) -> ErrorStats:
    """Statistics of per-pixel errors; ``e_std`` is the sample standard deviation.

    (The paper prints ``1/(#P-1)·sqrt(Σ(e-ē)²)``, evidently for the usual
    ``sqrt(Σ(e-ē)²/(#P-1))``, which is what is computed.)
    """
    e = np.asarray(e, dtype=np.float64).ravel()
    e = e[np.isfinite(e)]
    if e.size == 0:
        return ErrorStats(float("nan"), float("nan"), float("nan"), 0)
    std = float(e.std(ddof=1)) if e.size > 1 else 0.0
    return ErrorStats(float(e.max()), float(e.mean()), std, int(e.size))


def fit_global_scale(reference: np.ndarray, estimate: np.ndarray) -> float:
    """One global scale ``s`` with ``c ≈ s ĉ``, fitted robustly.

    Each pixel's own least-squares scale is ``(c·ĉ)/(ĉ·ĉ)``; ``s`` is their
    median. A least-squares fit over all pixels would let a few pixels at the
    physical limit (deep shadow biased by dark current, say) shift the scale
    and with it the error of every other pixel.
    """
    ref = reference.reshape(-1, reference.shape[-1])
    est = estimate.reshape(-1, estimate.shape[-1])
    return float(np.median(np.sum(ref * est, axis=1) / np.sum(est * est, axis=1)))


def relative_error_eq8(
    reference: np.ndarray,
    estimate: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    fit_scale: bool = True,
) -> tuple[np.ndarray, ErrorStats, float]:
    """Per-pixel relative error ``e_p = ‖c_p − s ĉ_p‖ / ‖c_p‖`` (eq. 8 of [PQ]).

    Parameters
    ----------
    reference, estimate : ndarray, shape (H, W, C)
        Reference and computed colours.
    mask : ndarray, shape (H, W) or (H, W, C) of bool, optional
        Pixels to leave out (flagged by the method, or outside the region).
    fit_scale : bool
        Fit the one global scale ``s`` (photoquantity is defined up to scale).

    Returns
    -------
    e : ndarray (H, W)
        NaN where left out.
    stats : ErrorStats
    scale : float
    """
    ref = np.asarray(reference, dtype=np.float64)
    est = np.asarray(estimate, dtype=np.float64)
    keep = np.all(np.isfinite(est), axis=-1) & np.all(np.isfinite(ref), axis=-1)
    keep &= np.sum(ref**2, axis=-1) > 0
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        keep &= ~(m.any(axis=-1) if m.ndim == ref.ndim else m)
    scale = fit_global_scale(ref[keep], est[keep]) if fit_scale else 1.0
    e = np.full(ref.shape[:-1], np.nan)
    diff = ref[keep] - scale * est[keep]
    e[keep] = np.linalg.norm(diff, axis=-1) / np.linalg.norm(ref[keep], axis=-1)
    return e, error_stats(e[keep]), scale


def channel_scale_ratios(reference: np.ndarray, estimate: np.ndarray, mask=None) -> np.ndarray:
    """Per-channel ``median(ĉ/c)``, divided by the green (index 1) one.

    For a balanced estimate these are 1; ``ratio − 1`` is the balance error.
    """
    ref = np.asarray(reference, dtype=np.float64)
    est = np.asarray(estimate, dtype=np.float64)
    ok = np.isfinite(est) & np.isfinite(ref) & (ref > 0)
    if mask is not None:
        ok &= ~np.asarray(mask, dtype=bool)
    s = np.array(
        [np.median(est[..., c][ok[..., c]] / ref[..., c][ok[..., c]]) for c in range(ref.shape[-1])]
    )
    return s / s[1 if s.size > 1 else 0]


def response_error(
    g_est: np.ndarray, g_true: np.ndarray, weights: np.ndarray
) -> tuple[float, float]:
    """Weighted RMS and max of ``g_est − g_true`` after removing the gauge.

    The gauge (an additive constant) is the weighted mean difference; only
    levels with positive weight count.
    """
    ok = (weights > 0) & np.isfinite(g_true) & np.isfinite(g_est)
    d = (g_est - g_true)[ok]
    w = weights[ok]
    d = d - np.sum(w * d) / np.sum(w)
    return float(np.sqrt(np.sum(w * d**2) / np.sum(w))), float(np.abs(d).max())


def map_relative_error(true_map: np.ndarray, est_map: np.ndarray) -> ErrorStats:
    """``|est − true| / true`` over every pixel and channel."""
    t = np.asarray(true_map, dtype=np.float64)
    e = np.abs(np.asarray(est_map, dtype=np.float64) - t) / t
    return error_stats(e)


def correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Pearson's correlation coefficient of the finite pairs of ``x`` and ``y``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    return float(np.corrcoef(x[ok], y[ok])[0, 1])


NOMINAL_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.68, 0.8, 0.9, 0.95, 0.99)
"""Levels of the central intervals of the reliability diagram."""


def normalised_errors(estimate: np.ndarray, truth: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``z = (ln l̂ − ln l − ŝ_λ)/σ`` of every value with a finite estimate, truth and
    ``σ > 0`` (channels last; ``ŝ_λ`` per channel: the gauge, see
    :mod:`validation.experiments.uncertainty`), as one flat array."""
    out = []
    for ch in range(estimate.shape[-1]):
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.log(estimate[..., ch].astype(np.float64)) - np.log(
                truth[..., ch].astype(np.float64)
            )
        s = sigma[..., ch].astype(np.float64)
        ok = np.isfinite(d) & np.isfinite(s) & (s > 0)
        if not np.any(ok):
            continue
        w = 1.0 / s[ok] ** 2
        d_ok = d[ok] - float(np.sum(w * d[ok]) / np.sum(w))
        out.append(d_ok / s[ok])
    return np.concatenate(out) if out else np.empty(0)


def interval_shares(z: np.ndarray, levels: tuple[float, ...] = NOMINAL_LEVELS) -> np.ndarray:
    """The share of ``z`` inside each central interval of nominal level ``p``."""
    from scipy.special import ndtri

    bounds = ndtri(0.5 + 0.5 * np.asarray(levels, dtype=np.float64))
    if z.size == 0:
        return np.full(len(levels), np.nan)
    return np.array([float(np.mean(np.abs(z) < b)) for b in bounds])


def uncertainty_coverage(
    estimate: np.ndarray, truth: np.ndarray, sigma: np.ndarray
) -> dict[str, float] | None:
    """How well a stated uncertainty covers the truth: ``z_spread`` (1: honest),
    ``within_68`` and ``within_95`` (the shares inside the nominal intervals) and
    ``n``, of :func:`normalised_errors`; ``None`` where no value has one."""
    z = normalised_errors(estimate, truth, sigma)
    if z.size == 0:
        return None
    shares = interval_shares(z, (0.68, 0.95))
    return {
        "z_spread": float(z.std()),
        "within_68": float(shares[0]),
        "within_95": float(shares[1]),
        "n": int(z.size),
    }
