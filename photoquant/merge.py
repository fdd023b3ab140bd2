"""HDR merge of an exposure stack into log photoquantities, eq. 6 of the paper.

``ln c_pλ = Σ_k w(c_pkλ) [g_λ(c_pkλ) − ln t_k] / Σ_k w(c_pkλ)``

A pixel whose every exposure has zero weight (all saturated, or all at the
dark floor) has no valid exposure: it is *flagged* in the result's mask and
its value is NaN, never a silently wrong number.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, eq. 6.
   doi:10.1145/258734.258884
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, eq. 5-6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoquant._checks import check_array, check_exposure_times
from photoquant.errors import InputError
from photoquant.stack import ExposureStack
from photoquant.weighting import WeightingFunction, weighting_function

__all__ = ["MergeResult", "merge_Debevec1997", "merge_stack", "apply_log_inverse_response"]


@dataclass(frozen=True, eq=False)
class MergeResult:
    """An HDR merge.

    Attributes
    ----------
    log_photoquantity : ndarray, shape (H, W, C), float64
        ``ln c_pλ``; NaN where ``mask`` is set.
    mask : ndarray, shape (H, W, C), bool
        True where the pixel has no valid exposure.
    all_saturated : ndarray, shape (H, W, C), bool
        Flagged because every exposure was saturated (too bright).
    all_dark : ndarray, shape (H, W, C), bool
        Flagged because no exposure rose above the dark floor (too dark).
    weight_sum : ndarray, shape (H, W, C), float64
        ``Σ_k w``: a confidence of each merged value.
    """

    log_photoquantity: np.ndarray
    mask: np.ndarray
    all_saturated: np.ndarray
    all_dark: np.ndarray
    weight_sum: np.ndarray

    def photoquantity(self) -> np.ndarray:
        """``exp(ln c)``: linear photoquantity, NaN at flagged pixels."""
        return np.exp(self.log_photoquantity)


def apply_log_inverse_response(
    values: np.ndarray, levels: np.ndarray, log_inverse_response: np.ndarray
) -> np.ndarray:
    """Evaluate ``g_λ`` at pixel values ``(..., C)`` by linear interpolation."""
    out = np.empty(values.shape, dtype=np.float64)
    for ch in range(values.shape[-1]):
        out[..., ch] = np.interp(values[..., ch], levels, log_inverse_response[ch])
    return out


def merge_Debevec1997(
    values: np.ndarray,
    exposure_s: np.ndarray,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    *,
    saturation_level: np.ndarray | None = None,
    saturated: np.ndarray | None = None,
    dark_clipped: np.ndarray | None = None,
    min_level: np.ndarray | None = None,
    weighting: str | WeightingFunction = "hat",
    c_min: float = 0.0,
) -> MergeResult:
    """Merge ``K`` exposures into log photoquantities (eq. 6 of [PQ]_).

    Parameters
    ----------
    values : ndarray, shape (K, H, W, C)
        Denoised pixel values (eq. 2).
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds (positive, unique).
    levels : ndarray, shape (L,)
        Pixel values at which ``log_inverse_response`` is tabulated (increasing).
    log_inverse_response : ndarray, shape (C, L)
        ``g_λ`` per channel (balance may be folded in by adding ``ln a_λ``).
    saturation_level : ndarray, shape (C,), optional
        Clipping level per channel; the top level when not given.
    saturated : ndarray, shape (K, H, W, C) of bool, optional
        Values known to be clipped (any repeat at the saturation level).
    dark_clipped : ndarray, shape (K, H, W, C) of bool, optional
        Values clipped at the floor (any repeat at ``c_min``): the mean of
        partly clipped repeats is biased, so they get no weight either.
    min_level : ndarray, shape (C,), optional
        Per channel, values below it get no weight: the response was not
        measured there (see ``ResponseRecovery.valid_min``).
    weighting : str or callable
        Weighting function, the paper's hat by default.
    c_min : float
        Lowest value the camera outputs.

    Returns
    -------
    MergeResult

    Notes
    -----
    The result does not depend on the order of the exposures, and scaling
    every exposure time by ``s`` shifts ``ln c`` by ``−ln s``.
    """
    values = check_array(values, "values", ndim=4, kind="iuf", finite=True)
    t = check_exposure_times(exposure_s)
    k_count, _, _, n_ch = values.shape
    if t.size != k_count:
        raise InputError(
            f"`exposure_s` has {t.size} times but `values` has K={k_count} exposures"
        )
    levels = check_array(levels, "levels", ndim=1, kind="iuf", finite=True).astype(np.float64)
    if levels.size < 2 or np.any(np.diff(levels) <= 0):
        raise InputError("`levels` must be at least two increasing values")
    g = check_array(
        log_inverse_response, "log_inverse_response", shape=(n_ch, levels.size), kind="f"
    )
    if not np.all(np.isfinite(g)):
        raise InputError("`log_inverse_response` contains NaN or infinite values")
    if saturation_level is None:
        sat = np.full(n_ch, levels[-1])
    else:
        sat = check_array(saturation_level, "saturation_level", shape=(n_ch,), kind="iuf")
        sat = sat.astype(np.float64)
    if saturated is not None:
        saturated = check_array(saturated, "saturated", shape=values.shape, kind="b")
    if dark_clipped is not None:
        dark_clipped = check_array(dark_clipped, "dark_clipped", shape=values.shape, kind="b")
    if min_level is not None:
        min_level = check_array(min_level, "min_level", shape=(n_ch,), kind="iuf").astype(float)
    wfun = weighting_function(weighting)

    num = np.zeros(values.shape[1:], dtype=np.float64)
    den = np.zeros(values.shape[1:], dtype=np.float64)
    any_unsat = np.zeros(values.shape[1:], dtype=bool)
    log_t = np.log(t)
    step_table = None
    if getattr(wfun, "uses_log_step", False):
        step_table = np.stack(
            [np.interp(levels + 0.5, levels, g[ch]) - np.interp(levels - 0.5, levels, g[ch])
             for ch in range(n_ch)]
        )
    if values.dtype.kind in "iu":
        # integer values (a single repeat): weights and g by table look-up
        full = np.arange(int(levels[-1]) + 1, dtype=np.float64)
        w_lut = np.empty((n_ch, full.size))
        g_lut = np.empty((n_ch, full.size))
        for ch in range(n_ch):
            g_lut[ch] = np.interp(full, levels, g[ch])
            if step_table is None:
                w_lut[ch] = wfun(full, c_min, sat[ch])
            else:
                step = np.interp(full, levels, step_table[ch])
                w_lut[ch] = wfun(full, c_min, sat[ch], log_step=step)
            w_lut[ch, full >= sat[ch]] = 0.0
            if min_level is not None:
                w_lut[ch, full < min_level[ch]] = 0.0
        offsets = np.arange(n_ch) * full.size
        w_flat, g_flat = w_lut.ravel(), g_lut.ravel()

        def weights_and_log(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            index = np.minimum(v, full.size - 1).astype(np.intp) + offsets
            return w_flat[index], g_flat[index]
    else:

        def weights_and_log(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            if step_table is None:
                w = wfun(v, c_min, sat)
            else:
                w = wfun(v, c_min, sat, log_step=apply_log_inverse_response(v, levels, step_table))
            w = np.where(v >= sat, 0.0, w)
            if min_level is not None:
                w = np.where(v < min_level, 0.0, w)
            return w, apply_log_inverse_response(v, levels, g)

    for k in range(k_count):
        v = values[k]
        w, gv = weights_and_log(v)
        clipped = v >= sat
        if saturated is not None:
            clipped |= saturated[k]
            w = np.where(saturated[k], 0.0, w)
        if dark_clipped is not None:
            w = np.where(dark_clipped[k], 0.0, w)
        any_unsat |= ~clipped
        num += w * (gv - log_t[k])
        den += w
    mask = den <= 0
    with np.errstate(invalid="ignore", divide="ignore"):
        log_c = np.where(mask, np.nan, num / np.where(mask, 1.0, den))
    return MergeResult(
        log_photoquantity=log_c,
        mask=mask,
        all_saturated=mask & ~any_unsat,
        all_dark=mask & any_unsat,
        weight_sum=den,
    )


def merge_stack(
    stack: ExposureStack,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray,
    *,
    min_level: np.ndarray | None = None,
    weighting: str = "hat",
) -> MergeResult:
    """Denoise (eq. 2) and merge (eq. 6) a stack with a known response.

    A value is left out when any of its repeats is clipped: at the saturation
    level, or at the floor 0; and when it lies below ``min_level``, where the
    response was not measured.
    """
    # a single repeat stays integer: the merge then looks weights and g up in tables
    values = stack.frames[0] if stack.n_repeats == 1 else stack.mean()
    return merge_Debevec1997(
        values,
        stack.exposure_s,
        levels,
        log_inverse_response,
        saturation_level=np.asarray(saturation_level, dtype=np.float64),
        saturated=stack.saturated(saturation_level),
        dark_clipped=stack.dark_clipped(),
        min_level=min_level,
        weighting=weighting,
    )
