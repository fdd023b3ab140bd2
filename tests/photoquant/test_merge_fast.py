"""The fast table merge against its readable float64 reference, and numba against numpy.

* ``merge_stack_Debevec1997`` (float32 tables, codes for clipped repeats, row
  tiles) equals the reference merge of the stack's means with the stack's
  saturation and dark masks: the same values excluded and flagged, ``ln c``
  within the float32 bound ``(2K + 3)·2⁻²⁴·max|g − ln t|`` derived in
  :mod:`photoquant.merge._tiled`.
* The numba and numpy kernels give the same bits; tiles and threads do not
  change a bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from photoquant.merge import (
    DebevecMergeOptions,
    merge_Debevec1997,
    merge_photoquantity_Debevec1997,
    merge_stack_Debevec1997,
)
from photoquant.merge._kernels import HAVE_NUMBA
from photoquant.merge._tiled import PAIRED_TABLE_SIZE, merge_tiles, merge_tiles_linear
from photoquant.merge.debevec1997 import _check_inputs, _table_plan, plan_stack_Debevec1997
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

WEIGHTINGS = ["hat", "hat-quantisation", "uniform"]


def f32_atol(g: np.ndarray, exposure_s: np.ndarray) -> float:
    """The float32 bound on ``ln c`` of :mod:`photoquant.merge._tiled` (over every table entry)."""
    t = np.asarray(exposure_s, dtype=float)
    return (2 * t.size + 3) * 2.0**-24 * float(np.max(np.abs(g[..., None] - np.log(t))))


@st.composite
def stacks(draw):
    """A small random stack and response: N, K, shape, bit depth, black and saturation levels."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(1, 4))
    k = draw(st.integers(1, 5))
    h, w, c = draw(st.integers(1, 7)), draw(st.integers(1, 6)), draw(st.integers(1, 3))
    bits = draw(st.sampled_from([8, 10, 12]))
    c_max = 2**bits - 1
    black = draw(st.sampled_from([0.0, 3.0, 16.5]))
    frames = rng.integers(0, c_max + 1, size=(n, k, h, w, c))
    # pile some values at the extremes, as clipped data do
    frames[rng.random(frames.shape) < 0.1] = c_max
    frames[rng.random(frames.shape) < 0.1] = int(black)
    # the longest exposure above the black level (a stack whose data lie below it is refused)
    frames[:, -1] = rng.integers(int(black) + 1, c_max + 1, size=(n, h, w, c))
    dtype = np.uint8 if bits == 8 else np.uint16
    t = np.sort(rng.uniform(0.5, 2.0, k)) * np.geomspace(1e-3, 1.0, k)
    sat = np.full(c, float(c_max)) - draw(st.sampled_from([0.0, 5.0, 40.5]))
    stack = ExposureStack(
        frames.astype(dtype),
        t,
        bit_depth=bits,
        saturation_level=sat,
        black_level=black,
        channels=("R", "G", "B")[:c],
    )
    levels = np.linspace(0.0, c_max, draw(st.sampled_from([16, 256])))
    steps = rng.uniform(0.01, 1.0, (c, levels.size))
    span = draw(st.floats(1.0, 30.0))  # ln exposure spanned by the response (cameras: < 60)
    g = span * np.cumsum(steps, axis=1) / steps.sum(axis=1, keepdims=True) - 5.0
    valid_min = rng.uniform(0, 0.2 * c_max, c) if draw(st.booleans()) else None
    response = ResponseModel(
        "given", levels, g, sat, valid_min=valid_min, black_level=np.full(c, black)
    )
    weighting = draw(st.sampled_from(WEIGHTINGS))
    exclude = draw(st.booleans())
    return stack, response, DebevecMergeOptions(weighting, exclude)


def _reference(stack: ExposureStack, response: ResponseModel, opts: DebevecMergeOptions):
    """eq. 6 on the float means with the stack's masks: the per-pixel float64 reference."""
    return merge_Debevec1997(
        stack.mean(),
        stack.exposure_s,
        response.levels,
        response.log_inverse_response,
        saturation_level=response.saturation_level,
        saturated=stack.saturated(response.saturation_level),
        dark_clipped=stack.dark_clipped(),
        min_level=response.valid_min if opts.exclude_below_valid_min else None,
        weighting=opts.weighting,
        c_min=np.asarray(response.black_level, dtype=np.float64),
    )


@settings(max_examples=60, deadline=None)
@given(case=stacks())
def test_table_merge_of_a_stack_equals_the_reference_within_the_float32_bound(case):
    stack, response, opts = case
    fast = merge_stack_Debevec1997(stack, response, opts)
    ref = _reference(stack, response, opts)
    assert ref.log_photoquantity.dtype == np.float64
    assert fast.log_photoquantity.dtype == np.float32 and fast.weight_sum.dtype == np.float32
    for field in ("mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(fast, field), getattr(ref, field), err_msg=field)
    atol = f32_atol(response.log_inverse_response, stack.exposure_s)
    np.testing.assert_allclose(fast.log_photoquantity, ref.log_photoquantity, rtol=0, atol=atol)
    # Σw: one float32 rounding per term and per partial sum
    rtol = (stack.n_exposures + 1) * 2.0**-24
    np.testing.assert_allclose(fast.weight_sum, ref.weight_sum, rtol=rtol, atol=0)


@settings(max_examples=25, deadline=None)
@given(case=stacks(), tile_rows=st.integers(1, 4), workers=st.integers(1, 3))
def test_tiles_and_threads_change_no_bit(case, tile_rows, workers):
    stack, response, opts = case
    whole = merge_stack_Debevec1997(stack, response, opts, tile_rows=10**6, workers=1)
    tiled = merge_stack_Debevec1997(stack, response, opts, tile_rows=tile_rows, workers=workers)
    for field in ("log_photoquantity", "weight_sum", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(tiled, field), getattr(whole, field), err_msg=field)


def _run(stack, response, opts, backend, tile_rows=2):
    plan = plan_stack_Debevec1997(stack, response, opts)
    assert plan is not None
    shape = stack.image_shape + (stack.n_channels,)
    out = [np.empty(shape, np.float32), np.empty(shape, bool), np.empty(shape, bool)]
    out.append(np.empty(shape, bool))
    weight = np.empty(shape, np.float32)
    merge_tiles(*plan, *out, weight_out=weight, tile_rows=tile_rows, workers=1, backend=backend)
    return [*out, weight]


@settings(max_examples=25, deadline=None)
@given(case=stacks())
def test_flags_made_zero_or_cleared_by_the_merge_alike(case):
    # flags_zeroed: the caller's flags are all false (np.zeros) and only the set ones are
    # written; otherwise the merge clears them first (here: all true before)
    stack, response, opts = case
    plan = plan_stack_Debevec1997(stack, response, opts)
    assert plan is not None
    shape = stack.image_shape + (stack.n_channels,)
    results = []
    for zeroed in (True, False):
        flags = [(np.zeros if zeroed else np.ones)(shape, bool) for _ in range(3)]
        log_c = np.empty(shape, np.float32)
        merge_tiles(*plan, log_c, *flags, tile_rows=2, workers=2, flags_zeroed=zeroed)
        results.append([log_c, *flags])
    for a, b in zip(*results, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed (the numpy kernels are used)")
@settings(max_examples=40, deadline=None)
@given(case=stacks())
def test_numba_and_numpy_kernels_give_the_same_bits(case):
    stack, response, opts = case
    for a, b in zip(
        _run(stack, response, opts, "numba"), _run(stack, response, opts, "numpy"), strict=True
    ):
        np.testing.assert_array_equal(a, b)


def test_numpy_kernel_is_used_without_numba():
    # the fallback is complete on its own: forcing it gives a full, finite result
    stack = ExposureStack(
        np.random.default_rng(1).integers(1, 250, (2, 3, 4, 5, 3)).astype(np.uint8),
        [0.01, 0.1, 1.0],
        saturation_level=np.full(3, 255),
    )
    levels = np.arange(256.0)
    resp = ResponseModel("given", levels, np.tile(np.log(levels + 1), (3, 1)), np.full(3, 255.0))
    log_c, mask, *_ = _run(stack, resp, DebevecMergeOptions("hat", False), "numpy")
    assert not mask.any() and np.isfinite(log_c).all()


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed (the numpy kernels are used)")
def test_blocked_repeat_kernel_across_blocks_gives_the_numpy_bits():
    # more values than one block of the repeat kernel (2048 pixels × C), a partial last one
    rng = np.random.default_rng(7)
    frames = rng.integers(0, 256, size=(3, 4, 37, 71, 3))
    frames[rng.random(frames.shape) < 0.05] = 255
    frames[rng.random(frames.shape) < 0.05] = 0
    stack = ExposureStack(frames.astype(np.uint8), [1e-3, 4e-3, 1.6e-2, 6.4e-2], bit_depth=8)
    levels = np.arange(256.0)
    g = np.log(np.linspace(1e-3, 1.0, 256))[None].repeat(3, axis=0)
    response = ResponseModel("given", levels, g, np.full(3, 255.0))
    opts = DebevecMergeOptions("hat", True)
    numba_out = _run(stack, response, opts, "numba", tile_rows=37)  # one tile: 7881 values
    numpy_out = _run(stack, response, opts, "numpy", tile_rows=37)
    assert np.isfinite(numba_out[0]).mean() > 0.5  # mostly merged values, not all flags
    for a, b in zip(numba_out, numpy_out, strict=True):
        np.testing.assert_array_equal(a, b)


@settings(max_examples=40, deadline=None)
@given(case=stacks(), backend=st.sampled_from(["numpy", "numba"] if HAVE_NUMBA else ["numpy"]))
def test_merge_from_the_cached_repeat_statistics_gives_the_same_bits(case, backend):
    # a stack that holds its repeat sums and extremes is merged from them (SummaryCodes),
    # a fresh one from its frames (RepeatCodes): the same codes, the same bits
    stack, response, opts = case

    def fresh() -> ExposureStack:
        return ExposureStack(
            stack.frames,
            stack.exposure_s,
            bit_depth=stack.bit_depth,
            saturation_level=stack.saturation_level,
            black_level=stack.black_level,
            channels=stack.channels,
        )

    plain, summarised = fresh(), fresh()
    summarised.repeat_sum()
    summarised.saturated()  # the extremes
    expected = "SummaryCodes" if stack.n_repeats > 1 else "DirectCodes"
    assert type(plan_stack_Debevec1997(summarised, response, opts)[0]).__name__ == expected
    assert plain.cached_repeat_statistics() is None
    for a, b in zip(
        _run(plain, response, opts, backend), _run(summarised, response, opts, backend), strict=True
    ):
        np.testing.assert_array_equal(a, b)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed (the numpy kernels are used)")
@pytest.mark.parametrize("zeroed", [True, False])
@pytest.mark.parametrize("n_ch", [1, 3])
def test_three_value_kernel_gives_the_bits_of_the_any_channel_kernel(zeroed, n_ch, monkeypatch):
    # the three-value kernel (RGB, or one channel three values a pass and a tail of one or
    # two; paired tables and vector adds; flags set by a second pass) against the per-value
    # kernel: tiles that start inside the array, values flagged all saturated and all dark,
    # in some tiles only
    from photoquant.merge import _kernels

    calls = []
    rgb = _kernels._direct_rgb_nb
    monkeypatch.setattr(_kernels, "_direct_rgb_nb", lambda *args: calls.append(1) or rgb(*args))

    rng = np.random.default_rng(11)
    k, h, width = 5, 23, 17  # 17 values a row for one channel: tiles end mid-triple
    codes = rng.integers(1, 255, size=(k, h, width, n_ch)).astype(np.uint8)
    codes[:, 3, 4, -1] = 255  # every exposure clipped
    codes[:, 9, 2, 0] = 0  # every exposure at the floor
    codes[:, 9, 5, :] = 0
    codes[:, 20, :, -1] = 255
    levels = np.arange(256.0)
    sat = np.full(n_ch, 255.0)
    g = np.log(np.linspace(1e-3, 1.0, 256))[None].repeat(n_ch, axis=0)
    g += np.array([[0.0], [0.3], [-0.2]])[:n_ch]
    plan = plan_stack_Debevec1997(
        ExposureStack(
            codes[None],
            np.geomspace(1e-3, 1e-1, k),
            bit_depth=8,
            saturation_level=sat,
            channels=("R", "G", "B")[:n_ch] if n_ch == 3 else ("Y",),
        ),
        ResponseModel("given", levels, g, sat, black_level=np.zeros(n_ch)),
        DebevecMergeOptions("hat", False),
    )
    assert plan is not None
    tables = plan[1]
    flat = codes.reshape(k, -1)
    results = []
    assert tables.pairs is not None and tables.three_value is not None
    assert tables.three_value is tables.three_value  # made once per tables, not per tile
    kernels = (
        lambda *args: _kernels._direct_compiled(*args[:5], list(args[5:]), tables.three_value),
        _kernels._direct_nb,
    )
    for kernel in kernels:
        outs = [np.full(flat.shape[1], -1.0, np.float32), np.empty(flat.shape[1], np.float32)]
        outs += [(np.zeros if zeroed else np.ones)(flat.shape[1], bool) for _ in range(3)]
        for rows in (slice(0, 4), slice(4, 10), slice(10, 20), slice(20, 23)):
            start, stop = rows.start * width * n_ch, rows.stop * width * n_ch
            tile = [o[start:stop] for o in outs]
            if not zeroed:
                for f in tile[2:]:
                    f.fill(False)
            kernel(flat, start, tables.w, tables.wt, tables.clip, *tile)
        results.append(outs)
    assert len(calls) == 4  # the three-value kernel merged every tile
    log_c, _, mask, all_sat, all_dark = results[0]
    assert mask[n_ch * (3 * width + 4) + n_ch - 1] and all_sat[n_ch * (3 * width + 4) + n_ch - 1]
    assert mask[n_ch * (9 * width + 2)] and all_dark[n_ch * (9 * width + 2)]
    assert np.isnan(log_c[mask]).all() and np.isfinite(log_c[~mask]).all()
    assert 0 < mask.sum() < mask.size // 4
    for a, b in zip(*results, strict=True):
        np.testing.assert_array_equal(a, b)


@settings(max_examples=20, deadline=None)
@given(case=stacks())
def test_paired_tables_hold_the_tables_side_by_side(case):
    # each 8-byte entry: the float32 w·(g − ln t_k) at the lower address, then w
    stack, response, opts = case
    # the stack's plan pairs the tables of single frames only (repeat sums: kernels that
    # read w and wt apart); the array merge pairs those of any integer values
    assert (plan_stack_Debevec1997(stack, response, opts)[1].pairs is None) == (stack.n_repeats > 1)
    args, kw = _array_merge_arguments(case, False)
    checked = _check_inputs(
        *args,
        kw["saturation_level"],
        None,
        None,
        kw["min_level"],
        kw["weighting"],
        kw["c_min"],
        kw["repeats"],
    )
    tables = _table_plan(checked)[1]
    assert tables.pairs is not None and tables.pairs.dtype == np.float64
    assert tables.pairs.flags.c_contiguous and tables.pairs.shape == tables.wt.shape
    halves = tables.pairs.view(np.float32).reshape(tables.wt.shape + (2,))
    np.testing.assert_array_equal(halves[..., 0], tables.wt)
    np.testing.assert_array_equal(halves[..., 1], np.broadcast_to(tables.w, tables.wt.shape))


def test_tables_past_the_paired_size_are_not_paired_and_merge_alike():
    # codes above 16 bits: no pairs (their memory), the per-value kernel, the numpy bits
    rng = np.random.default_rng(5)
    values = rng.integers(0, 70_000, size=(3, 4, 5, 3)).astype(np.uint32)
    values[-1] = rng.integers(1, 60_000, size=(4, 5, 3))
    levels = np.linspace(0.0, 70_000.0, 64)
    g = np.tile(np.linspace(-6.0, 4.0, 64), (3, 1))
    inputs = _check_inputs(
        values, [1e-3, 1e-2, 1e-1], levels, g, None, None, None, None, "hat", 0.0, 1
    )
    source, tables = _table_plan(inputs)
    assert tables.pairs is None and tables.w.shape[1] > PAIRED_TABLE_SIZE
    outs = []
    for backend in ("numpy", "numba") if HAVE_NUMBA else ("numpy",):
        out = [np.empty((4, 5, 3), np.float32), np.zeros((4, 5, 3), bool)]
        out += [np.zeros((4, 5, 3), bool), np.zeros((4, 5, 3), bool)]
        weight = np.empty((4, 5, 3), np.float32)
        merge_tiles(source, tables, *out, weight_out=weight, tile_rows=2, backend=backend)
        outs.append([*out, weight])
    assert np.isfinite(outs[0][0]).mean() > 0.5
    for a, b in zip(outs[0], outs[-1], strict=True):
        np.testing.assert_array_equal(a, b)


def _array_merge_arguments(case, as_float, **kw):  # noqa: ANN001, ANN003, ANN202
    """``merge_Debevec1997``'s arguments for a drawn stack: its repeat sums (or their float
    means) and the stack's response and options, plus ``kw``."""
    stack, response, opts = case
    values = stack.repeat_sum()
    if as_float:
        values = values / stack.n_repeats
    kw |= {
        "saturation_level": response.saturation_level,
        "min_level": response.valid_min if opts.exclude_below_valid_min else None,
        "weighting": opts.weighting,
        "c_min": np.asarray(response.black_level, dtype=np.float64),
        "repeats": 1 if as_float else stack.n_repeats,
    }
    return (values, stack.exposure_s, response.levels, response.log_inverse_response), kw


@settings(max_examples=30, deadline=None)
@given(
    case=stacks(),
    tile_rows=st.integers(1, 4),
    workers=st.integers(1, 3),
    out_dtype=st.sampled_from([np.float32, np.float64]),
    as_float=st.booleans(),
)
def test_photoquantity_out_holds_the_results_photoquantity_to_the_bit(
    case, tile_rows, workers, out_dtype, as_float
):
    """Tile by tile (integer values) or after the float merge: ``photoquantity()``, in out's dtype."""
    args, kw = _array_merge_arguments(case, as_float, tile_rows=tile_rows, workers=workers)
    values = args[0]
    out = np.full(values.shape[1:], -1.0, dtype=out_dtype)  # every value must be written
    res = merge_Debevec1997(*args, photoquantity_out=out, **kw)
    np.testing.assert_array_equal(out, res.photoquantity().astype(out_dtype))
    plain = merge_Debevec1997(*args, **kw)  # the output changes nothing else
    for field in ("log_photoquantity", "weight_sum", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(res, field), getattr(plain, field), err_msg=field)


@settings(max_examples=30, deadline=None)
@given(
    case=stacks(),
    tile_rows=st.integers(1, 4),
    workers=st.integers(1, 3),
    out_dtype=st.sampled_from([None, np.float32, np.float64]),
    as_float=st.booleans(),
)
def test_merge_photoquantity_is_the_results_photoquantity_to_the_bit(
    case, tile_rows, workers, out_dtype, as_float
):
    """The image alone: ``merge_Debevec1997(...).photoquantity()``, NaN where flagged, in
    out's dtype (without out: the result's dtype, float32 from integer values)."""
    args, kw = _array_merge_arguments(case, as_float, tile_rows=tile_rows, workers=workers)
    values = args[0]
    expected = merge_Debevec1997(*args, **kw).photoquantity()
    if out_dtype is None:
        image = merge_photoquantity_Debevec1997(*args, **kw)
        assert image.dtype == (np.float64 if as_float else np.float32)
    else:
        out = np.full(values.shape[1:], -1.0, dtype=out_dtype)  # every value must be written
        image = merge_photoquantity_Debevec1997(*args, out=out, **kw)
        assert image is out
        expected = expected.astype(out_dtype)
    np.testing.assert_array_equal(image, expected)


@settings(max_examples=30, deadline=None)
@given(
    case=stacks(),
    backend=st.sampled_from(["numpy", "numba"] if HAVE_NUMBA else ["numpy"]),
    tile_rows=st.integers(1, 4),
    summarised=st.booleans(),
)
def test_linear_tiles_are_the_exponential_of_the_tiles_log(case, backend, tile_rows, summarised):
    # every code source (single frames, repeat sums from the frames or from the stack's
    # cached statistics) and kernel: exp of merge_tiles' ln c, NaN where it flags
    stack, response, opts = case
    if summarised:
        stack.saturated()  # caches the repeat sums and extremes (SummaryCodes when N > 1)
    plan = plan_stack_Debevec1997(stack, response, opts)
    assert plan is not None
    log_c, mask, *_ = _run(stack, response, opts, backend, tile_rows=tile_rows)
    out = np.full(log_c.shape, -1.0, np.float32)
    merge_tiles_linear(*plan, out, tile_rows=tile_rows, workers=2, backend=backend)
    np.testing.assert_array_equal(out, np.exp(log_c))
    assert np.isnan(out[mask]).all() and np.isfinite(out[~mask]).all()


@pytest.mark.parametrize(
    ("make_out", "match"),
    [
        (lambda v: [[0.0]], "must be a numpy array, got list"),
        (lambda v: np.empty((2, 3, 3), np.float32), r"shape \(2, 4, 3\), got float32 \(2, 3, 3\)"),
        (lambda v: np.empty((2, 4, 3), np.int32), "float32 or float64 array"),
        (lambda v: np.broadcast_to(np.float32(0), (2, 4, 3)), "read-only"),
        (lambda v: v[0].view(np.float32), "may overlap the merge's inputs"),
    ],
)
@pytest.mark.parametrize(
    ("merge", "name"),
    [(merge_Debevec1997, "photoquantity_out"), (merge_photoquantity_Debevec1997, "out")],
)
def test_bad_photoquantity_out_is_named(make_out, match, merge, name):
    values = np.full((2, 2, 4, 3), 100, dtype=np.uint32)
    g = np.tile(np.linspace(-5.0, 5.0, 256), (3, 1))
    with pytest.raises(InputError, match=f"^`{name}` .*{match}"):
        merge(values, [1.0, 2.0], np.arange(256.0), g, **{name: make_out(values)})
