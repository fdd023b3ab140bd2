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
.. [PQ] The photoquantity paper, eq. 5-6.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from photoquant._checks import (
    UNCORRECTED_BIAS_MODES,
    check_array,
    check_choice,
    check_exposure_times,
    check_int,
)
from photoquant.errors import InputError
from photoquant.merge._base import MergeResult, apply_log_inverse_response
from photoquant.merge._tiled import (
    CodeSource,
    DirectCodes,
    MergeTables,
    RepeatCodes,
    SummaryCodes,
    merge_tiles,
    merge_tiles_linear,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack
from photoquant.weighting import WeightingFunction, weighting_function

__all__ = [
    "DebevecMergeOptions",
    "plan_stack_Debevec1997",
    "merge_Debevec1997",
    "merge_photoquantity_Debevec1997",
    "merge_stack_Debevec1997",
]


_MAX_TABLE_SIZE = 1 << 22
"""Largest integer value (per channel) for which the merge uses look-up tables."""

_KEPT_TABLE_BYTES = 32 << 20
"""Largest merge tables a camera keeps for the next scene of the same bracket (32 MiB:
single 16-bit frames' tables, K = 8, are 19 MiB; 8-bit ones a few tens of kB)."""

_KEPT_TABLES = 2
"""How many merge tables a camera keeps: its bracket's and the last refined times'."""


@dataclass(frozen=True, eq=False)
class _Inputs:
    """The checked inputs of a merge and the per-value functions of eq. 6."""

    values: np.ndarray
    log_t: np.ndarray
    levels: np.ndarray
    g: np.ndarray
    sat: np.ndarray
    saturated: np.ndarray | None
    dark_clipped: np.ndarray | None
    weights: Callable[[np.ndarray, int | slice], np.ndarray]
    repeats: int

    def log_inverse(self, v: np.ndarray, ch: int) -> np.ndarray:
        return np.interp(v, self.levels, self.g[ch])


def _check_inputs(
    values: np.ndarray,
    exposure_s: np.ndarray,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray | None,
    saturated: np.ndarray | None,
    dark_clipped: np.ndarray | None,
    min_level: np.ndarray | None,
    weighting: str | WeightingFunction,
    c_min: float | np.ndarray,
    repeats: int,
) -> _Inputs:
    values = check_array(values, "values", ndim=4, kind="iuf", finite=True)
    t = check_exposure_times(exposure_s)
    k_count, _, _, n_ch = values.shape
    if t.size != k_count:
        raise InputError(f"`exposure_s` has {t.size} times but `values` has K={k_count} exposures")
    repeats = check_int(repeats, "repeats", 1)
    if repeats > 1 and values.dtype.kind not in "iu":
        raise InputError(
            f"`repeats` = {repeats} needs the integer sums of the frames, got {values.dtype} values"
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
    floor = np.broadcast_to(np.asarray(c_min, dtype=np.float64), (n_ch,))

    step_table = None
    if getattr(wfun, "uses_log_step", False):
        step_table = np.stack(
            [
                np.interp(levels + 0.5, levels, g[ch]) - np.interp(levels - 0.5, levels, g[ch])
                for ch in range(n_ch)
            ]
        )

    def weights(v: np.ndarray, ch: int | slice) -> np.ndarray:
        """Weights of (mean) values ``v`` of channel(s) ``ch``: none at saturation or below min."""
        s = sat[ch]
        if step_table is None:
            w = wfun(v, floor[ch], s)
        else:
            step = (
                apply_log_inverse_response(v, levels, step_table[ch])
                if isinstance(ch, slice)
                else np.interp(v, levels, step_table[ch])
            )
            w = cast(Callable[..., np.ndarray], wfun)(v, floor[ch], s, log_step=step)
        w = np.where(v >= s, 0.0, w)
        if min_level is not None:
            w = np.where(v < min_level[ch], 0.0, w)
        return w

    return _Inputs(
        values, np.log(t), levels, g, sat, saturated, dark_clipped, weights, int(repeats)
    )


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
    c_min: float | np.ndarray = 0.0,
    repeats: int = 1,
    tile_rows: int | None = None,
    workers: int | None = None,
    photoquantity_out: np.ndarray | None = None,
) -> MergeResult:
    """Merge ``K`` exposures into log photoquantities (eq. 6 of [PQ]_).

    Parameters
    ----------
    values : ndarray, shape (K, H, W, C)
        Denoised pixel values (eq. 2), or with ``repeats > 1`` the integer sums
        of the ``N = repeats`` frames of each exposure (the mean is
        ``values / repeats``).
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
    c_min : float or ndarray, shape (C,)
        Lowest value the camera outputs: the black level (per channel), where
        the hat weights are anchored.
    repeats : int
        ``N`` when ``values`` are sums of ``N`` integer frames; 1 otherwise.
    tile_rows : int, optional
        Rows per tile of the integer (table) merge; about 2 MiB of input per
        tile by default. The result does not depend on it.
    workers : int, optional
        Threads over the tiles (every CPU by default); the result does not
        depend on it.
    photoquantity_out : ndarray, shape (H, W, C), float32 or float64, optional
        Receives the linear photoquantity, the values of
        :meth:`MergeResult.photoquantity` (NaN where flagged) in its dtype;
        the integer (table) merge exponentiates each row tile as soon as it
        is merged, while it is in the cache, instead of in a later pass
        over the whole image (1024×768×3, K = 8, 2 cores: 0.45 ms less in
        the median of 60 alternated repeats, 2026-12-02). It must not
        overlap the inputs.

    Returns
    -------
    MergeResult
        Float32 ``log_photoquantity`` and ``weight_sum`` for integer values
        (the table merge), float64 otherwise.

    Notes
    -----
    The result does not depend on the order of the exposures, and scaling
    every exposure time by ``s`` shifts ``ln c`` by ``−ln s``.

    Integer ``values`` (single frames, or sums of ``N`` frames) take the
    weight and ``w·(g − ln t_k)`` of every possible value from per-exposure
    float32 tables built once per channel — the mean of ``N`` integer frames
    lies on the grid ``j / N`` — looked up once per frame and summed in
    float32 in row tiles on threads (:mod:`photoquant.merge._tiled`, which
    gives the error bound: ``(2K + 3)·2⁻²⁴·max|g − ln t|`` in ``ln c``, about
    2·10⁻⁵ for K = 8). Float values are merged by the float64 reference
    (:func:`_merge_reference`), evaluated per pixel.
    """
    inp = _check_inputs(
        values,
        exposure_s,
        levels,
        log_inverse_response,
        saturation_level,
        saturated,
        dark_clipped,
        min_level,
        weighting,
        c_min,
        repeats,
    )
    linear_out = _check_photoquantity_out(photoquantity_out, inp, "photoquantity_out")
    plan = _table_plan(inp)
    if plan is None:
        result = _merge_reference(inp)
        if linear_out is not None:
            np.exp(result.log_photoquantity, out=linear_out)
        return result
    return _run_tiles(*plan, tile_rows, workers, linear_out)


def merge_photoquantity_Debevec1997(
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
    c_min: float | np.ndarray = 0.0,
    repeats: int = 1,
    tile_rows: int | None = None,
    workers: int | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The linear photoquantity ``exp(ln c)`` of eq. 6 of [PQ]_ alone: an HDR image.

    The values of ``merge_Debevec1997(...).photoquantity()`` to the bit, with
    the same parameters: NaN where no exposure has weight. Only the image is
    kept, as OpenCV's ``MergeDebevec`` gives its radiance map: the integer
    (table) merge keeps each row tile's ``ln c``, ``Σ_k w`` and flags in
    tile-sized work arrays and exponentiates the tile into the output while
    it is in the cache, so the output is the only image-sized array written
    (1024×768×3, K = 8, 2 cores: 1.6–3.9 ms less in the paired median than
    the whole :class:`MergeResult` with ``photoquantity_out``, 2026-12-02).
    Use :func:`merge_Debevec1997` where the flags or ``Σ_k w`` are needed.

    Parameters
    ----------
    values, exposure_s, levels, log_inverse_response
        As in :func:`merge_Debevec1997`.
    saturation_level, saturated, dark_clipped, min_level, weighting, c_min, repeats
        As in :func:`merge_Debevec1997`.
    tile_rows, workers : int, optional
        As in :func:`merge_Debevec1997`; the result does not depend on them.
    out : ndarray, shape (H, W, C), float32 or float64, optional
        Where to write the photoquantity (in its dtype); it must not overlap
        the inputs. A new array when not given: float32 for integer values
        (the table merge), float64 for float values.

    Returns
    -------
    ndarray, shape (H, W, C)
        ``out``, or the new array.
    """
    inp = _check_inputs(
        values,
        exposure_s,
        levels,
        log_inverse_response,
        saturation_level,
        saturated,
        dark_clipped,
        min_level,
        weighting,
        c_min,
        repeats,
    )
    linear = _check_photoquantity_out(out, inp, "out")
    plan = _table_plan(inp)
    if plan is None:
        log_c = _merge_reference(inp).log_photoquantity
        if linear is None:
            return np.exp(log_c)
        np.exp(log_c, out=linear)
        return linear
    if linear is None:
        linear = np.empty(inp.values.shape[1:], dtype=np.float32)
    merge_tiles_linear(*plan, linear, tile_rows=tile_rows, workers=workers)
    return linear


def _table_plan(inp: _Inputs) -> tuple[DirectCodes, MergeTables] | None:
    """The table merge of checked inputs: codes and tables (``None``: not integer, or too many
    levels for tables; the float64 reference merges those)."""
    values = inp.values
    top = -1
    if values.dtype.kind in "iu" and values.size:
        # unsigned values need no scan for negatives, 8-bit ones none for the top either
        lo = 0 if values.dtype.kind == "u" else int(values.min())
        hi = 255 if values.dtype == np.uint8 else int(values.max())
        top = max(hi, inp.repeats * int(np.ceil(inp.levels[-1]))) if lo >= 0 else -1
    if not 0 <= top < _MAX_TABLE_SIZE:
        return None
    tables = MergeTables.build(
        np.arange(top + 1, dtype=np.float64) / inp.repeats,
        inp.weights,
        inp.log_inverse,
        inp.sat,
        inp.log_t,
    )
    source = DirectCodes(
        values,
        inp.saturated,
        inp.dark_clipped,
        sat_code=tables.sat_code,
        dark_code=tables.dark_code,
    )
    return source, tables


def _check_photoquantity_out(out: np.ndarray | None, inp: _Inputs, name: str) -> np.ndarray | None:
    """``out`` (the parameter ``name``) checked: a writable ``(H, W, C)`` float array apart from
    the inputs."""
    if out is None:
        return None
    shape = inp.values.shape[1:]
    if not isinstance(out, np.ndarray):
        raise InputError(f"`{name}` must be a numpy array, got {type(out).__name__}")
    if out.shape != shape or out.dtype not in (np.float32, np.float64):
        raise InputError(
            f"`{name}` must be a float32 or float64 array of shape {shape}, "
            f"got {out.dtype} {out.shape}"
        )
    if not out.flags.writeable:
        raise InputError(f"`{name}` is read-only")
    inputs = (inp.values, inp.saturated, inp.dark_clipped)
    if any(a is not None and np.may_share_memory(out, a) for a in inputs):
        raise InputError(f"`{name}` may overlap the merge's inputs (it lies in their memory)")
    return out


def _run_tiles(
    source: CodeSource,
    tables: MergeTables,
    tile_rows: int | None,
    workers: int | None,
    linear_out: np.ndarray | None = None,
) -> MergeResult:
    shape = source.shape
    log_c = np.empty(shape, dtype=np.float32)
    weight = np.empty(shape, dtype=np.float32)
    # zeroed flags, set only where they hold (mapped on first write; see merge_tiles)
    mask = np.zeros(shape, dtype=bool)
    all_sat = np.zeros(shape, dtype=bool)
    all_dark = np.zeros(shape, dtype=bool)
    merge_tiles(
        source,
        tables,
        log_c,
        mask,
        all_sat,
        all_dark,
        weight_out=weight,
        tile_rows=tile_rows,
        workers=workers,
        on_tile=None if linear_out is None else _exp_into(linear_out),
        flags_zeroed=True,
    )
    return MergeResult(
        log_photoquantity=log_c,
        mask=mask,
        all_saturated=all_sat,
        all_dark=all_dark,
        weight_sum=weight,
    )


def _exp_into(out: np.ndarray) -> Callable[[slice, np.ndarray, np.ndarray], None]:
    """A tile callback writing ``exp(ln c)`` of the tile's rows into ``out``."""

    def exp_tile(rows: slice, log_c: np.ndarray, mask: np.ndarray) -> None:
        del mask  # ln c is NaN there already, and so is its exp
        np.exp(log_c, out=out[rows])

    return exp_tile


def _merge_reference(inp: _Inputs) -> MergeResult:
    """The readable float64 merge of eq. 6: weights and ``g`` evaluated per pixel.

    The reference of the table merge (which equals it within the float32
    bound of :mod:`photoquant.merge._tiled`), and the merge of float values.
    """
    values = inp.values
    if inp.repeats > 1:
        values = values / inp.repeats
    num = np.zeros(values.shape[1:], dtype=np.float64)
    den = np.zeros(values.shape[1:], dtype=np.float64)
    any_unsat = np.zeros(values.shape[1:], dtype=bool)
    for k in range(values.shape[0]):
        v = values[k]
        w = inp.weights(v, slice(None))
        term = w * (apply_log_inverse_response(v, inp.levels, inp.g) - inp.log_t[k])
        clipped = v >= inp.sat
        excluded = None
        if inp.saturated is not None:
            clipped |= inp.saturated[k]
            excluded = inp.saturated[k]
        if inp.dark_clipped is not None:
            dark = inp.dark_clipped[k]
            excluded = dark if excluded is None else excluded | dark
        if excluded is not None:
            np.putmask(w, excluded, 0.0)
            np.putmask(term, excluded, 0.0)
        any_unsat |= ~clipped
        num += term
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


@dataclass(frozen=True)
class DebevecMergeOptions:
    """Options of the ``"Debevec 1997"`` merge (eq. 6).

    Attributes
    ----------
    weighting : str
        A weighting function of :data:`photoquant.weighting.WEIGHTING_FUNCTIONS`:
        ``"hat-quantisation"`` (default, the hat reduced where one DN is a
        coarse step in ``ln`` exposure) or ``"hat"`` (the paper's).
    exclude_below_valid_min : bool
        Give no weight to values below the response's ``valid_min``, where
        the response fit had no data (default); the paper uses every value.
    uncorrected_bias : {"ignored", "stated"}
        With ``"stated"`` (the paper's profile) and options that depart from
        these defaults, a correction's stated uncertainty also covers the
        bias the chosen weighting leaves against the defaults' on the same
        values (:func:`~photoquant.merge.uncertainty.log_variance_weighting_bias_Debevec1997`);
        the merge itself is unchanged.
    """

    weighting: str = "hat-quantisation"
    exclude_below_valid_min: bool = True
    uncorrected_bias: str = "ignored"

    def __post_init__(self) -> None:
        check_choice(self.uncorrected_bias, "uncorrected_bias", UNCORRECTED_BIAS_MODES)
        weighting_function(self.weighting)
        if not isinstance(self.exclude_below_valid_min, bool):
            raise InputError(
                "`exclude_below_valid_min` must be true or false, "
                f"got {self.exclude_below_valid_min!r}"
            )


def plan_stack_Debevec1997(
    stack: ExposureStack, response: ResponseModel, options: DebevecMergeOptions | None = None
) -> tuple[CodeSource, MergeTables] | None:
    """The table merge of a stack: its code source and tables (``None``: too many levels).

    Single frames are their own codes; the weight of values at or below the
    black level (a repeat at the dark floor) is zero in the tables, and that
    of values at or above the saturation level is zero by the weighting.
    Sums of ``N > 1`` repeats get an exclusion code where any repeat is
    clipped (:class:`~photoquant.merge._tiled.RepeatCodes`). Nothing of size
    ``(K, H, W, C)`` is made: the stack's own saturation and dark masks are
    not needed.
    """
    opts = options or DebevecMergeOptions()
    if stack.n_repeats * stack.c_max >= _MAX_TABLE_SIZE:
        return None
    n_ch = stack.n_channels
    sat_level = np.asarray(response.saturation_level, dtype=np.float64)
    black = np.broadcast_to(np.asarray(stack.black_level, dtype=np.float64), (n_ch,))
    tables = _merge_tables(stack, response, opts, black)
    source: CodeSource
    if stack.n_repeats == 1:
        source = DirectCodes(stack.frames[0])
    else:
        # integer repeats: c >= level  <=>  c >= ceil(level);  c <= b  <=>  c <= floor(b)
        cached = stack.cached_repeat_statistics()
        if cached is not None:  # the stack holds its repeat sums and extremes: read those
            source = SummaryCodes(*cached, np.ceil(sat_level), np.floor(black))
        else:
            source = RepeatCodes(stack.frames, np.ceil(sat_level), np.floor(black), tables)
    return source, tables


def _merge_tables(
    stack: ExposureStack,
    response: ResponseModel,
    opts: DebevecMergeOptions,
    black: np.ndarray,
) -> MergeTables:
    """The tables of :func:`plan_stack_Debevec1997`: the last :data:`_KEPT_TABLES` used
    are kept in the response's ``_cache`` with what they depend on beside the response
    (the options, the exposure times, the number of repeats, the code range and the
    stack's black level), and made again when none matches. A camera corrects many
    scenes of one bracket: building them was 0.3 ms of a 1024×768×3, K = 4 correction's
    3.4 ms with the nominal times (interleaved, 2026-12-07). Two, because a correction
    that tests a scene's times merges with the nominal ones while it tests them
    (:func:`photoquant.correction.correct`) and again with the refined ones where the
    test refines them: the bracket's tables stay kept beside the last scene's. No more,
    so that scenes of ever-changing times (an automatic exposure) do not pile tables up,
    and only tables of at most :data:`_KEPT_TABLE_BYTES` (the sums of many 16-bit
    repeats have tables of hundreds of MB, which a camera should not hold between
    scenes)."""
    key = (opts, stack.exposure_s.tobytes(), stack.n_repeats, stack.c_max, black.tobytes())
    cache = getattr(response, "_cache", None)
    kept: tuple[tuple[Any, MergeTables], ...] = ()
    if isinstance(cache, dict):
        kept = cache.get("merge_tables") or ()
        for i, (kept_key, found) in enumerate(kept):
            if kept_key == key:  # the last used first
                cache["merge_tables"] = (kept[i], *kept[:i], *kept[i + 1 :])
                return found
    n_ch = stack.n_channels
    top = stack.n_repeats * stack.c_max
    inp = _check_inputs(
        np.zeros((stack.n_exposures, 1, 1, n_ch), dtype=np.uint8),  # shapes only
        stack.exposure_s,
        response.levels,
        response.log_inverse_response,
        response.saturation_level,
        None,
        None,
        response.valid_min if opts.exclude_below_valid_min else None,
        opts.weighting,
        np.asarray(response.black_level, dtype=np.float64),
        stack.n_repeats,
    )
    grid = np.arange(top + 1, dtype=np.float64) / stack.n_repeats
    single = stack.n_repeats == 1
    tables = MergeTables.build(
        grid,
        inp.weights,
        inp.log_inverse,
        inp.sat,
        inp.log_t,
        dark_below=black if single else None,
        paired=single,  # repeat sums are merged by kernels that read w and wt apart
    )
    if isinstance(cache, dict):
        size = sum(
            a.nbytes for a in (tables.w, tables.wt, tables.clip, tables.pairs) if a is not None
        )
        if size <= _KEPT_TABLE_BYTES:
            cache["merge_tables"] = ((key, tables), *kept)[:_KEPT_TABLES]
    return tables


def merge_stack_Debevec1997(
    stack: ExposureStack,
    response: ResponseModel,
    options: DebevecMergeOptions | None = None,
    *,
    tile_rows: int | None = None,
    workers: int | None = None,
) -> MergeResult:
    """The ``"merge"`` step by eq. 6 of [PQ]_: denoise (eq. 2) and merge a stack with ``response``.

    A value is left out when any of its repeats is clipped (at the response's
    saturation level, or at the dark floor) and, with
    ``exclude_below_valid_min``, when it lies below the response's
    ``valid_min``. The merge works on the integer sums of the ``N`` repeats
    through look-up tables, in row tiles (``tile_rows``, about 2 MiB of
    frames each by default) on ``workers`` threads, which is the merge of
    the denoised means within the float32 bound of
    :func:`merge_Debevec1997`; neither parameter changes the result.
    """
    opts = options or DebevecMergeOptions()
    plan = plan_stack_Debevec1997(stack, response, opts)
    if plan is not None:
        return _run_tiles(plan[0], plan[1], tile_rows, workers)
    values = stack.integer_sums()
    return merge_Debevec1997(
        values,
        stack.exposure_s,
        response.levels,
        response.log_inverse_response,
        saturation_level=response.saturation_level,
        saturated=stack.saturated(response.saturation_level),
        dark_clipped=stack.dark_clipped(),
        min_level=response.valid_min if opts.exclude_below_valid_min else None,
        weighting=opts.weighting,
        c_min=np.asarray(response.black_level, dtype=np.float64),
        repeats=stack.n_repeats,
    )
