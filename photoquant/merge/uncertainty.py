"""The noise part of a merged photoquantity's uncertainty, pixel by pixel.

Eq. 6 merges each pixel's exposures into a weighted mean of their estimates
``ln E_k = g(c̄_k) − ln t_k``. With independent noise in the exposures, the
variance of the merged ``ln Ê`` is that of a weighted mean with the merge's
*actual* weights [JCGM100]_ (§5.1.2, the law of propagation of uncertainty):

    Var(ln Ê) = Σ_k w_k² Var(ln E_k) / (Σ_k w_k)²,

whatever the weights are (the hat of Debevec & Malik is not an inverse
variance; with the noise-aware merge's weights ``w_k = 1 / Var(ln E_k)`` it
reduces to ``1 / Σ_k w_k``). ``Var(ln E_k)`` is the noise model of
:mod:`photoquant.merge.noise_aware`: shot noise ``K·y`` and read noise
``σ_r²`` on the camera's linear DN scale, passed through the slope of ``g``,
quantisation after the response, the mean of ``N`` repeats; evaluated at the
observed mean value (first order). The gain ``K`` and read noise ``σ_r`` come
from a photon-transfer fit (:func:`~photoquant.merge.noise_aware.estimate_noise_parameters`):
of the scene's own repeats where it has ``N ≥ 2``, else of the camera's
calibration captures (stored in the camera).

This is the *noise* component: it varies from pixel to pixel and averages
down with more repeats. The calibration's own errors (the response, the
sensor LUT, the vignetting, the balance, refined exposure times) are common
to every scene corrected with the camera and are not in it. The division by
``u·v`` adds nothing to it (``ln l = ln Ê − ln(u·v)``).

References
----------
.. [JCGM100] JCGM 100:2008, Evaluation of measurement data — Guide to the
   expression of uncertainty in measurement (GUM), §5.1.2.
.. [Granados2010] Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel,
   H.-P., & Lensch, H. P. A. (2010). Optimal HDR reconstruction with linear
   digital cameras. CVPR 2010, 215-222. doi:10.1109/CVPR.2010.5540208
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from photoquant._interp import at_interval, interp, interp_slopes, interval
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._threads import even_spans, thread_map
from photoquant.errors import InputError
from photoquant.merge._tables import ValueTables, fits_tables
from photoquant.merge.debevec1997 import DebevecMergeOptions, _check_inputs
from photoquant.merge.noise_aware import NoiseParameters, _log_variance, _Scale
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "MergeWeights",
    "compiled_passes_apply",
    "merge_weights_Debevec1997",
    "log_variance_Debevec1997",
    "log_variance_exposure_Debevec1997",
    "log_variance_response_Debevec1997",
    "log_variance_weighting_bias_Debevec1997",
    "WEIGHTING_BIAS_BAND",
    "response_error_of_merge_Debevec1997",
    "response_loadings_Debevec1997",
    "noise_parameters_from_record",
    "noise_record",
]


def noise_record(params: NoiseParameters) -> dict[str, Any]:
    """The JSON record of noise parameters stored in a camera (``parameters["noise"]``)."""
    return {
        "gain_dn_per_e": [float(v) for v in params.gain],
        "read_noise_dn": [float(v) for v in params.read_noise],
        "source": params.source,
    }


def noise_parameters_from_record(record: Any, n_channels: int) -> NoiseParameters | None:
    """The noise parameters of a camera's record (``None``: none stored, or unreadable)."""
    if not isinstance(record, dict):
        return None
    try:
        gain = np.asarray(record["gain_dn_per_e"], dtype=np.float64)
        read = np.asarray(record["read_noise_dn"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        return None
    if gain.shape != (n_channels,) or read.shape != (n_channels,):
        return None
    if not (np.all(np.isfinite(gain)) and np.all(gain > 0) and np.all(np.isfinite(read))):
        return None
    source = f"camera's calibration ({record.get('source', 'estimated')})"
    return NoiseParameters(gain, np.maximum(read, 0.0), source)


def log_variance_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    noise: NoiseParameters,
    options: DebevecMergeOptions | None = None,
    *,
    weights: MergeWeights | None = None,
) -> np.ndarray:
    """``Var(ln Ê)`` of :func:`~photoquant.merge.debevec1997.merge_stack_Debevec1997` per pixel.

    Parameters
    ----------
    stack : ExposureStack
        The merged frames (``N`` repeats are averaged, as the merge does).
    response : ResponseModel
        The response the merge used (an additive constant, such as a folded
        balance, does not change the variance).
    noise : NoiseParameters
        Gain and read noise per channel, on the response's linear DN scale.
    options : DebevecMergeOptions, optional
        The merge's weighting and ``valid_min`` rule (the defaults when not given).
    weights : MergeWeights, optional
        The merge's weights, when already computed (:func:`merge_weights_Debevec1997`).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        The variance in ``ln`` units; NaN where no exposure has weight (the
        merge's mask).
    """
    if not isinstance(noise, NoiseParameters):
        raise InputError(f"`noise` must be NoiseParameters, got {type(noise).__name__}")
    n = stack.n_repeats
    scale = _Scale(response)
    read2 = np.asarray(noise.read_noise, dtype=np.float64) ** 2

    def variance(v: np.ndarray, ch: int) -> np.ndarray:
        y = scale.linear(scale.log_inverse(v, ch), ch)
        return _log_variance(y, scale.slope(v, ch), float(noise.gain[ch]), float(read2[ch]), n)

    if weights is None and _weighted_variance_nb is not None:
        setup = _weight_setup(stack, response, options)
        if setup[0].tabulated:  # one compiled pass over the values, the same arithmetic
            return _fused_log_variance(stack, setup, variance)
    tables, per_exposure, den = weights or merge_weights_Debevec1997(stack, response, options)
    variance_table = tables.table(variance)
    num = np.zeros_like(den)
    for k, w in enumerate(per_exposure):
        num += np.where(w > 0, w * w * tables.take(variance_table, k), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den * den, 1.0), np.nan)


WEIGHTING_BIAS_BAND = 0.25
"""Width in ``ln Ê`` of the bands over which the weighting's bias is averaged
(:func:`log_variance_weighting_bias_Debevec1997`): wide beside the noise of a patch of
constant light, so that a band holds the patch's values whole (``Δ`` and ``ln Ê`` are
read from the same values: a band narrower than the noise would select values by their
noise, and its mean of ``Δ`` would follow it)."""


def log_variance_weighting_bias_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions,
    reference: DebevecMergeOptions | None = None,
) -> np.ndarray:
    """The bias a merge's weighting leaves against a reference weighting, as a variance
    per pixel: an *uncorrected bias* stated as an uncertainty [Phillips1997]_.

    The two merges of the same values differ by
    ``Δ = Σ_k (a_k − a'_k) (g(c̄_k) − ln t_k)`` (``a_k = w_k / Σ_k w_k`` the
    merge's normalised weights, ``a'_k`` the reference's). ``Δ`` holds the
    merge's bias against the reference, a function of the exposure ``E``
    that the bracket's values are read from, and the noise of the values the
    two weight differently, which is not a bias. The bias is the mean of
    ``Δ`` over the pixels of the same exposure: per channel, the values are
    grouped in bands of the merge's ``ln Ê`` :data:`WEIGHTING_BIAS_BAND`
    wide, and each value is stated its band's ``b² = max(Δ̄² − s²/n, 0)``
    (the squared mean less its sampling variance). E.g. the paper's hat weights the values of one or two DN,
    where one DN is a coarse step in ``ln`` exposure and ``g`` is least
    known, as much as its slope allows; the default ``"hat-quantisation"``
    weighting hardly uses them, and in a scene's shadows the two differ by
    several percent.

    Parameters
    ----------
    stack : ExposureStack
        The merged frames.
    response : ResponseModel
        The response both merges use.
    options : DebevecMergeOptions
        The merge's options.
    reference : DebevecMergeOptions, optional
        The reference's (the defaults when not given).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``b²`` of each value's band; NaN where either merge gives no value a
        weight.

    References
    ----------
    .. [Phillips1997] Phillips, S. D., Eberhardt, K. R., & Parry, B. (1997).
       Guidelines for expressing the uncertainty of measurement results
       containing uncorrected bias. J. Res. NIST 102(5), 577-585.
    """
    log_e, delta = _weighting_difference(stack, response, options, reference)
    out = np.full(delta.shape, np.nan)
    for ch in range(delta.shape[-1]):
        ok = np.isfinite(delta[..., ch])
        if np.any(ok):
            out[..., ch][ok] = _banded_bias_square(log_e[..., ch][ok], delta[..., ch][ok])
    return out


def _weighting_difference(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions,
    reference: DebevecMergeOptions | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The merge's ``ln Ê`` and ``Δ``, its difference from the reference weighting's
    merge of the same values, ``(H, W, C)`` each (NaN where either merges nothing)."""
    scale = _Scale(response)
    tables, own_table, own = _weight_setup(stack, response, options)
    _, reference_table, ref = _weight_setup(stack, response, reference or DebevecMergeOptions())
    g_table = tables.table(scale.log_inverse)

    sums = [np.zeros(_value_shape(stack)), np.zeros(_value_shape(stack))]
    for k in range(stack.n_exposures):
        sums[0] += _exposure_weight(tables, own_table, own, k)
        sums[1] += _exposure_weight(tables, reference_table, ref, k)
    merged = (sums[0] > 0) & (sums[1] > 0)
    inv = [np.where(merged, 1.0 / np.where(merged, total, 1.0), 0.0) for total in sums]
    log_e, delta = np.zeros_like(sums[0]), np.zeros_like(sums[0])
    ln_t = np.log(np.asarray(stack.exposure_s, dtype=np.float64))
    for k in range(stack.n_exposures):
        a = _exposure_weight(tables, own_table, own, k) * inv[0]
        a_ref = _exposure_weight(tables, reference_table, ref, k) * inv[1]
        used = (a != 0.0) | (a_ref != 0.0)  # g only where a weight is (finite there)
        log_e_k = np.where(used, tables.take(g_table, k) - ln_t[k], 0.0)
        log_e += a * log_e_k
        delta += (a - a_ref) * log_e_k
    return np.where(merged, log_e, np.nan), np.where(merged, delta, np.nan)


def _banded_bias_square(log_e: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``max(Δ̄² − s²/n, 0)`` of each value's band of ``log_e`` (1-D), bands of width
    :data:`WEIGHTING_BIAS_BAND` (a band averages whole patches of a scene)."""
    band = np.floor((log_e - log_e.min()) / WEIGHTING_BIAS_BAND).astype(np.intp)
    n_bins = int(band.max()) + 1
    count = np.bincount(band, minlength=n_bins).astype(np.float64)
    filled = np.maximum(count, 1.0)
    mean = np.bincount(band, delta, n_bins) / filled
    spread = np.maximum(np.bincount(band, delta * delta, n_bins) / filled - mean * mean, 0.0)
    sampling = spread / np.maximum(count - 1.0, 1.0)
    return np.maximum(mean * mean - sampling, 0.0)[band]


class MergeWeights(NamedTuple):
    """The ``"Debevec 1997"`` merge's weights of a stack, shared by the uncertainty's parts."""

    tables: ValueTables
    """The stack's value tables (quantities of every possible mean value)."""
    per_exposure: list[np.ndarray]
    """``w_k`` ``(H, W, C)`` of each exposure, 0 where the merge leaves the value out."""
    total: np.ndarray
    """``Σ_k w_k``."""


def merge_weights_Debevec1997(
    stack: ExposureStack, response: ResponseModel, options: DebevecMergeOptions | None = None
) -> MergeWeights:
    """The merge's weight of every value (computed once for all the uncertainty's parts)."""
    tables, weight_table, inp = _weight_setup(stack, response, options)
    weights: list[np.ndarray] = []
    total = None
    for k in range(stack.n_exposures):
        w = _exposure_weight(tables, weight_table, inp, k)
        weights.append(w)
        # Σ_k w_k in exposure order, as a sum over a stacked axis adds (the same bits,
        # without a (K, H, W, C) copy)
        total = w.copy() if total is None else np.add(total, w, out=total)
    assert total is not None  # a stack has at least one exposure
    return MergeWeights(tables, weights, total)


def _exposure_weight(tables: ValueTables, weight_table: Any, inp: Any, k: int) -> np.ndarray:
    """The merge's weight of exposure ``k``'s values ``(H, W, C)``, 0 where a repeat is
    clipped (a new array)."""
    w = tables.take(weight_table, k)  # a new array: zeroed in place
    for mask in (inp.saturated, inp.dark_clipped):
        if mask is not None:
            w[mask[k]] = 0.0
    return w


def compiled_passes_apply(stack: ExposureStack) -> bool:
    """Whether the uncertainty's parts of ``stack`` run as compiled passes over its values
    (numba installed, the values on :class:`~photoquant.merge._tables.ValueTables`): they
    then look the merge's weights up themselves, and precomputed
    :func:`merge_weights_Debevec1997` would only cost time."""
    return HAVE_NUMBA and fits_tables(stack)


def _weight_setup(
    stack: ExposureStack, response: ResponseModel, options: DebevecMergeOptions | None
) -> tuple[ValueTables, Any, Any]:
    """The stack's value tables, the merge's weight on them and the checked inputs."""
    opts = options or DebevecMergeOptions()
    n = stack.n_repeats
    values = stack.integer_sums()
    inp = _check_inputs(
        values,
        stack.exposure_s,
        response.levels,
        response.log_inverse_response,
        response.saturation_level,
        stack.saturated(response.saturation_level),
        stack.dark_clipped(),
        response.valid_min if opts.exclude_below_valid_min else None,
        opts.weighting,
        np.asarray(response.black_level, dtype=np.float64),
        n,
    )
    # the weights of every possible mean value, looked up per exposure (the noise-aware
    # merge's tables): no interpolation per pixel
    tables = ValueTables(stack)
    return tables, tables.table(inp.weights), inp


def _value_shape(stack: ExposureStack) -> tuple[int, int, int]:
    """``(H, W, C)``: the shape of a per-value result of ``stack``."""
    return (*stack.image_shape, stack.n_channels)


def _fused_arguments(
    stack: ExposureStack, setup: tuple[ValueTables, Any, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The compiled passes' values ``(K, H·W, C)`` (sums of the repeats: the tables'
    indices), saturated and dark masks (empty where none) and output ``(H·W, C)``."""
    inp = setup[2]
    values = stack.integer_sums()
    k, h, w, c = values.shape
    none = np.zeros((0, 0, 0), dtype=bool)
    sat = none if inp.saturated is None else inp.saturated.reshape(k, h * w, c)
    dark = none if inp.dark_clipped is None else inp.dark_clipped.reshape(k, h * w, c)
    return values.reshape(k, h * w, c), sat, dark, np.empty((h * w, c))


def _run_in_spans(
    kernel: Any,
    values: np.ndarray,
    sat: np.ndarray,
    dark: np.ndarray,
    out: np.ndarray,
    *tables: Any,
    per_span: Callable[[slice], tuple[Any, ...]] | None = None,
) -> None:
    """``kernel(values, *tables, *per_span(part), sat, dark, out)`` over spans ``part`` of
    the pixels on every CPU (the kernels release the GIL; each value's result depends on
    that value alone); ``per_span`` gives a span's own arguments (none by default)."""

    def span(part: slice) -> None:
        kernel(
            values[:, part],
            *tables,
            *(per_span(part) if per_span is not None else ()),
            sat[:, part] if sat.size else sat,
            dark[:, part] if dark.size else dark,
            out[part],
        )

    thread_map(span, even_spans(values.shape[1], 4 * (os.cpu_count() or 1)))


def _fused_log_variance(
    stack: ExposureStack, setup: tuple[ValueTables, Any, Any], variance: Any
) -> np.ndarray:
    """:func:`log_variance_Debevec1997` in one compiled pass (tabulated stacks)."""
    tables, weight_table, _ = setup
    values, sat, dark, out = _fused_arguments(stack, setup)
    size = tables.grid.size  # values per channel on the tables
    _run_in_spans(
        _weighted_variance_nb, values, sat, dark, out, size, weight_table, tables.table(variance)
    )
    return out.reshape(_value_shape(stack))


def _interpolated_table(tables: ValueTables, levels: np.ndarray, rows: np.ndarray) -> Any:
    """``rows`` (C, L), given at the response's ``levels``, on the stack's value tables,
    interpolated as ``g`` is (the function itself where the stack has no tables)."""
    return tables.table(lambda v, ch: np.interp(v, levels, rows[ch]))


def _fused_response_variance(
    stack: ExposureStack,
    setup: tuple[ValueTables, Any, Any],
    levels: np.ndarray,
    factor: np.ndarray,
    rest: np.ndarray,
    held_out_level: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`log_variance_response_Debevec1997` in one compiled pass (tabulated stacks):
    the factor's columns and the rest of the diagonal tabulated as ``g`` is interpolated;
    with ``held_out_level``, each span's read-back terms interpolated at its levels first
    (as the numpy path's, a span at a time: no ``(R, H, W, C)`` array)."""
    tables, weight_table, _ = setup
    factor_tables = np.stack(
        [_interpolated_table(tables, levels, factor[:, r]) for r in range(factor.shape[1])]
    )
    values, sat, dark, out = _fused_arguments(stack, setup)
    size = tables.grid.size
    n_ch = stack.n_channels
    if held_out_level is None:
        held: tuple[np.ndarray, ...] = (np.zeros((0, 0)),) + (np.zeros((0, 0, 0)),) * 2
    else:  # the factor's rows and the rest, read back at each value's level in the kernel
        rows = np.ascontiguousarray(np.concatenate([np.moveaxis(factor, 1, 0), rest[None]]))
        held = (held_out_level.reshape(-1, n_ch), rows, interp_slopes(levels, rows))

    def held_out_terms(part: slice) -> tuple[np.ndarray, ...]:
        level, rows, slopes = held
        return (level[part] if level.size else level, levels, rows, slopes)

    _run_in_spans(
        _response_variance_nb,
        values,
        sat,
        dark,
        out,
        size,
        weight_table,
        factor_tables.reshape(-1, size * n_ch),
        _interpolated_table(tables, levels, rest),
        per_span=held_out_terms,
    )
    return out.reshape(_value_shape(stack))


def _rows_at(level: np.ndarray, levels: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``rows`` (C, L), given at ``levels``, at ``level`` (..., C), as ``g`` is interpolated."""
    return np.stack(
        [interp(level[..., ch], levels, rows[ch]) for ch in range(rows.shape[0])], axis=-1
    )


def _weighted_variance_py(  # pragma: no cover - compiled by numba
    values: Any, size: int, w_table: Any, v_table: Any, sat: Any, dark: Any, out: Any
) -> None:
    """numba body: ``Σ w_k² v_k / (Σ w_k)²`` per value, the merge's weights (0 where
    saturated or dark) and the variances looked up on the value tables, summed in
    exposure order as :func:`log_variance_Debevec1997`'s numpy path does."""
    n_k, n_p, n_c = values.shape
    use_sat = sat.size > 0
    use_dark = dark.size > 0
    for p in range(n_p):
        for c in range(n_c):
            num = 0.0
            den = 0.0
            for k in range(n_k):
                idx = np.intp(values[k, p, c]) + c * size
                wk = w_table[idx]
                if (use_sat and sat[k, p, c]) or (use_dark and dark[k, p, c]):
                    wk = 0.0
                den = wk if k == 0 else den + wk
                if wk > 0:
                    num += wk * wk * v_table[idx]
            out[p, c] = num / (den * den) if den > 0 else np.nan


_weighted_variance_nb: Any = compile_kernel(_weighted_variance_py) if HAVE_NUMBA else None


def _weights_py(  # pragma: no cover - compiled by numba
    values: Any, p: int, c: int, size: int, w_table: Any, sat: Any, dark: Any, wk: Any
) -> float:
    """numba body: the merge's weights ``wk (K,)`` of value ``(p, c)`` (0 where saturated
    or dark) and their sum in exposure order (as :func:`merge_weights_Debevec1997`)."""
    n_k = values.shape[0]
    den = 0.0
    for k in range(n_k):
        w = w_table[np.intp(values[k, p, c]) + c * size]
        if (sat.size > 0 and sat[k, p, c]) or (dark.size > 0 and dark[k, p, c]):
            w = 0.0
        wk[k] = w
        den = w if k == 0 else den + w
    return den


def _response_variance_py(  # pragma: no cover - compiled by numba
    values: Any,
    size: int,
    w_table: Any,
    f_tables: Any,
    d_table: Any,
    held_level: Any,
    levels: Any,
    held_rows: Any,
    held_slopes: Any,
    sat: Any,
    dark: Any,
    out: Any,
) -> None:
    """numba body: ``Σ_r (Σ_k w_k F_r(c̄_k) / Σ_k w_k − F_r(ẑ))² + Σ_k w_k² D(c̄_k) /
    (Σ_k w_k)² + D(ẑ)`` per value, in the order of
    :func:`log_variance_response_Debevec1997`'s numpy path. ``held_level (P, C)`` are
    the held-out levels ``ẑ`` (empty: no read-back, the terms at ``ẑ`` left out);
    ``held_rows (R + 1, C, L)`` the factor's rows and ``D`` on the response's
    ``levels``, read at ``ẑ`` as ``np.interp`` reads them (each value located once,
    :func:`photoquant._interp.interval`), with their ``held_slopes``."""
    n_k, n_p, n_c = values.shape
    held = held_level.size > 0
    n_f = f_tables.shape[0]
    wk = np.empty(n_k)
    idx = np.empty(n_k, dtype=np.intp)
    for p in range(n_p):
        for c in range(n_c):
            den = _weights_nb(values, p, c, size, w_table, sat, dark, wk)
            if not den > 0:
                out[p, c] = np.nan
                continue
            for k in range(n_k):
                idx[k] = np.intp(values[k, p, c]) + c * size
            case, j = interval(held_level[p, c], levels) if held else (0, 0)
            inv = 1.0 / den
            total = 0.0
            for r in range(n_f):
                acc = 0.0
                for k in range(n_k):
                    acc += wk[k] * f_tables[r, idx[k]]
                moved = acc * inv
                if held:
                    moved = moved - at_interval(
                        held_level[p, c], levels, held_rows[r, c], held_slopes[r, c], case, j
                    )
                total += moved * moved
            acc = 0.0
            for k in range(n_k):
                acc += wk[k] * wk[k] * d_table[idx[k]]
            total = total + acc * (inv * inv)
            if held:
                total = total + at_interval(
                    held_level[p, c], levels, held_rows[n_f, c], held_slopes[n_f, c], case, j
                )
            out[p, c] = total


def _exposure_variance_py(  # pragma: no cover - compiled by numba
    values: Any, size: int, w_table: Any, rows: Any, sat: Any, dark: Any, out: Any
) -> None:
    """numba body: ``Σ_q (Σ_k w_k R_qk / Σ_k w_k)²`` per value (``Cov(ln t) = Rᵀ R``), in
    the order of :func:`log_variance_exposure_Debevec1997`'s numpy path."""
    n_k, n_p, n_c = values.shape
    wk = np.empty(n_k)
    for p in range(n_p):
        for c in range(n_c):
            den = _weights_nb(values, p, c, size, w_table, sat, dark, wk)
            if not den > 0:
                out[p, c] = np.nan
                continue
            total = 0.0
            for q in range(rows.shape[0]):
                acc = 0.0
                for k in range(n_k):
                    acc += wk[k] * rows[q, k]
                moved = acc / den
                total += moved * moved
            out[p, c] = total


_weights_nb: Any = compile_kernel(_weights_py) if HAVE_NUMBA else None
_response_variance_nb: Any = compile_kernel(_response_variance_py) if HAVE_NUMBA else None
_exposure_variance_nb: Any = compile_kernel(_exposure_variance_py) if HAVE_NUMBA else None


def log_variance_response_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions | None = None,
    *,
    weights: MergeWeights | None = None,
    held_out_level: np.ndarray | None = None,
) -> np.ndarray:
    """The response's part of ``Var(ln Ê)`` after the ``"Debevec 1997"`` merge, per pixel.

    ``ln Ê = Σ_k w_k (g(c̄_k) − ln t_k) / Σ_k w_k`` moves by ``Σ_k a_k δg(c̄_k)``
    (``a_k = w_k / Σ_k w_k``) when ``g`` is off by ``δg``. With
    ``Cov(g) = Fᵀ F + D`` (the response's low-rank factor and the rest of its
    diagonal, :mod:`photoquant.response.covariance`)::

        Var = Σ_r (Σ_k a_k F_r(c̄_k))² + Σ_k a_k² D(c̄_k),

    the factor interpolated between levels as ``g`` is. The errors of ``g``
    are common to every pixel and every scene corrected with the camera (a
    *calibration* component): they do not average down over repeats.

    Parameters
    ----------
    stack : ExposureStack
        The merged frames.
    response : ResponseModel
        The response the merge used, with its covariance (``covariance_factor``).
    options : DebevecMergeOptions, optional
        The merge's weighting and ``valid_min`` rule.
    weights : MergeWeights, optional
        The merge's weights, when already computed (:func:`merge_weights_Debevec1997`).
    held_out_level : ndarray, shape (H, W, C), optional
        A level per value at which the prediction of another exposure reads
        ``g`` back (``ẑ`` with ``g(ẑ) = ln Ê + ln t``): the variance is then
        that of ``ln Ê − g(ẑ)``, ``Σ_r (Σ_k a_k F_r(c̄_k) − F_r(ẑ))² + Σ_k a_k²
        D(c̄_k) + D(ẑ)``, the same error of ``g`` entering both (the held-out
        prediction of :mod:`photoquant.crossval`).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        The variance in ``ln`` units; NaN where no exposure has weight.

    Raises
    ------
    InputError
        If the response carries no covariance.
    """
    factor, rest = response.covariance_parts()
    levels = response.levels
    if weights is None and _response_variance_nb is not None:
        setup = _weight_setup(stack, response, options)
        if setup[0].tabulated:  # one compiled pass over the values, the same arithmetic
            return _fused_response_variance(stack, setup, levels, factor, rest, held_out_level)
    tables, per_exposure, den = weights or merge_weights_Debevec1997(stack, response, options)

    def at_level(rows: np.ndarray) -> np.ndarray:
        """``rows`` (C, L) at ``held_out_level`` (H, W, C), as ``g`` is interpolated."""
        assert held_out_level is not None
        return _rows_at(held_out_level, levels, rows)

    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), np.nan)
        total = np.zeros_like(den)
        for r in range(factor.shape[1]):
            table = _interpolated_table(tables, levels, factor[:, r])
            moved = sum(w * tables.take(table, k) for k, w in enumerate(per_exposure)) * inv
            if held_out_level is not None:
                moved = moved - at_level(factor[:, r])
            total += moved**2
        table = _interpolated_table(tables, levels, rest)
        total += sum(w * w * tables.take(table, k) for k, w in enumerate(per_exposure)) * inv**2
        if held_out_level is not None:
            total += at_level(rest)
    return np.where(den > 0, total, np.nan)


def response_error_of_merge_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """How the response's error moves the ``"Debevec 1997"`` merge of ``stack``, on average
    over its pixels: the reference a covariance of ``g`` can be made relative to.

    With ``Cov(g) = Fᵀ F + D`` (:func:`log_variance_response_Debevec1997`) the
    merged ``ln Ê`` of a pixel moves by ``Σ_r ξ_r Σ_k a_k F_r(c̄_k) + η``
    (``ξ_r`` independent standard variates, ``η`` the uncorrelated rest, of
    variance ``Σ_k a_k² D(c̄_k)``). Averaged over the stack's pixels with a
    weight (a uniform target, e.g. the white chart the balance reads): the
    mean loadings ``B_r`` and the mean variance of ``η``.

    Returns
    -------
    loadings : ndarray, shape (C, R)
    rest : ndarray, shape (C,)
        NaN for a channel where no pixel has weight.

    Raises
    ------
    InputError
        If the response carries no covariance.
    """
    factor, rest_of_diagonal = response.covariance_parts()
    levels = response.levels
    tables, per_exposure, den = merge_weights_Debevec1997(stack, response, options)
    weighted = (den > 0).reshape(-1, den.shape[-1])
    n_ch, n_rows = factor.shape[0], factor.shape[1]

    def pixel_mean(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(-1, n_ch)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(weighted, flat, 0.0).sum(axis=0) / weighted.sum(axis=0)

    loadings = np.full((n_ch, n_rows), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), 0.0)
        for r in range(n_rows):
            table = _interpolated_table(tables, levels, factor[:, r])
            moved = sum(w * tables.take(table, k) for k, w in enumerate(per_exposure)) * inv
            loadings[:, r] = pixel_mean(moved)
        rest_table = _interpolated_table(tables, levels, rest_of_diagonal)
        rest = sum(w * w * tables.take(rest_table, k) for k, w in enumerate(per_exposure))
    return loadings, pixel_mean(rest * inv**2)


def response_loadings_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions | None,
    rows: np.ndarray,
    cols: np.ndarray,
) -> np.ndarray:
    """How each of the response's independent error variates moves the ``"Debevec 1997"``
    merge of ``stack`` at a few pixels.

    With ``Cov(g) = Fᵀ F + D`` (:func:`log_variance_response_Debevec1997`), the
    merged ``ln Ê`` of a pixel moves by ``Σ_r ξ_r Σ_k a_k F_r(c̄_k)`` (``ξ_r``
    independent standard variates, ``a_k = w_k / Σ_k w_k``): the loadings
    ``Σ_k a_k F_r(c̄_k)`` at the pixels ``(rows, cols)``, merged from those
    pixels' values alone (no full-size array is made). The uncorrelated rest
    ``D`` is left out: it moves each value on its own.

    Returns
    -------
    ndarray, shape (P, C, R)
        0 where no exposure of the pixel has weight.

    Raises
    ------
    InputError
        If the response carries no covariance.
    """
    factor, _ = response.covariance_parts()
    n_ch, n_rows = factor.shape[0], factor.shape[1]
    rows, cols = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
    n, k, h, w, c = stack.frames.shape
    # np.take on the (N·K, H·W, C) view: ~4× faster than fancy indexing of two middle axes
    flat = np.take(stack.frames.reshape(n * k, h * w, c), rows * w + cols, axis=1)
    sub = stack.with_frames(flat.reshape(n, k, rows.size, 1, c))
    tables, per_exposure, den = merge_weights_Debevec1997(sub, response, options)
    moved = np.zeros((rows.size, 1, n_ch, n_rows))
    if tables.tabulated:  # every row's table at once: one gather of R numbers per value
        stacked = np.stack(
            [_interpolated_table(tables, response.levels, factor[:, r]) for r in range(n_rows)],
            axis=-1,
        )
        for k, w in enumerate(per_exposure):
            rows_k = tables.take_rows(stacked, k)  # a new array: weighted in place
            rows_k *= w[..., None]
            moved += rows_k
    else:
        for r in range(n_rows):
            table = _interpolated_table(tables, response.levels, factor[:, r])
            moved[..., r] = sum(w * tables.take(table, k) for k, w in enumerate(per_exposure))
    inv = np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), 0.0)
    return (moved * inv[..., None])[:, 0]


def log_variance_exposure_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    log_cov: np.ndarray,
    options: DebevecMergeOptions | None = None,
    *,
    weights: MergeWeights | None = None,
) -> np.ndarray:
    """The exposure times' part of ``Var(ln Ê)`` after the ``"Debevec 1997"`` merge.

    ``ln Ê = Σ_k a_k (g(c̄_k) − ln t_k)`` (``a_k = w_k / Σ_k w_k``) moves by
    ``−Σ_k a_k δ ln t_k`` when the times are off, so ``Var = aᵀ Cov(ln t) a``
    per pixel, with ``Cov(ln t)`` e.g. the covariance of refined times
    (:attr:`photoquant.exposure.ExposureRefinement.log_cov`; NaN entries, the
    rows of exposures kept at their labels, count as 0). The times are
    common to every pixel of the scene: the errors are correlated across
    pixels (a component apart from the noise). ``weights``: the merge's, when
    already computed (:func:`merge_weights_Debevec1997`).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        NaN where no exposure has weight.
    """
    k = stack.n_exposures
    cov = np.nan_to_num(np.asarray(log_cov, dtype=np.float64))
    if cov.shape != (k, k):
        raise InputError(f"`log_cov` must be ({k}, {k}) for the stack's exposures, got {cov.shape}")
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    rows = (vecs * np.sqrt(np.clip(vals, 0.0, None))).T  # Cov = rowsᵀ rows
    if weights is None and _exposure_variance_nb is not None:
        setup = _weight_setup(stack, response, options)
        if setup[0].tabulated:  # one compiled pass over the values, the same arithmetic
            values, sat, dark, out = _fused_arguments(stack, setup)
            _run_in_spans(
                _exposure_variance_nb, values, sat, dark, out, setup[0].grid.size, setup[1], rows
            )
            return out.reshape(_value_shape(stack))
    _, per_exposure, den = weights or merge_weights_Debevec1997(stack, response, options)
    total = np.zeros_like(den)
    with np.errstate(invalid="ignore", divide="ignore"):
        for row in rows:
            moved = sum(w * float(r) for w, r in zip(per_exposure, row, strict=True))
            total += (moved / den) ** 2
    return np.where(den > 0, total, np.nan)
