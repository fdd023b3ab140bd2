"""The response fit's compiled kernels give the numpy versions' bits (photoquant.response._kernels).

Random stacks with censoring at both ends, partners that share no pixel
(as in a combination of views), integer and fractional values: the
censored-pair trimming, the histogram sample selection, eq. 7's normal
equations and the whole fit must be equal to the last bit with and without
numba. Without numba the compiled path is not taken and these reduce to the
numpy path against itself, so they are skipped.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.response import _kernels, camera_response_Debevec1997
from photoquant.response.censoring import trim_censored_partners
from photoquant.response.debevec1997 import (
    _at_or_above_by_channel,
    _channel_major,
    _normal_equations,
    select_samples_histogram,
)

pytestmark = pytest.mark.skipif(
    not _kernels.HAVE_NUMBA, reason="numba is not installed (the numpy versions are used)"
)


@contextmanager
def _numpy_only():
    """The numpy versions, as without numba."""
    old = _kernels.HAVE_NUMBA
    _kernels.HAVE_NUMBA = False
    try:
        yield
    finally:
        _kernels.HAVE_NUMBA = old


def _bracket(seed: int, k_count: int, n_pix: int, n_rep: int, split: bool, step: float = 8.0):
    """A random bracket of one channel: values (K, P) clipped at 0 and 255 (censored there),
    exposure times ``step`` apart (about), and the usable mask; ``split``: two groups of exposures that share no
    pixel (another view's exposures are no partners)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.8, 1.25, k_count) * step ** np.arange(k_count)
    radiance = np.exp(rng.uniform(-np.log(t[-1]) - 2.0, 2.0, n_pix))
    raw = 255.0 * np.outer(t, radiance) ** 0.8
    raw *= np.exp(rng.normal(0.0, 0.05, raw.shape))  # a spread that clips part of a level
    raw += rng.normal(0.0, 2.0, raw.shape)
    values = np.clip(np.round(raw * n_rep) / n_rep, 0.0, 255.0)
    valid = (values > 0.0) & (values < 255.0)
    if split and k_count >= 2:
        half = rng.random(n_pix) < 0.5
        valid[: k_count // 2, half] = False
        valid[k_count // 2 :, ~half] = False
    return values, valid, t


def _eq7_rows(rng: np.random.Generator, k_count: int, n_pix: int, top: int):
    """Random data rows of eq. 7 ``(K, P)``: which values are valid (every pixel has one),
    their weights and level positions (values past the top level; an invalid value's
    weight and position garbage)."""
    valid = rng.random((k_count, n_pix)) < 0.7
    valid[0] = True  # every pixel has a valid value
    weights = np.where(valid, rng.random((k_count, n_pix)), rng.normal(0, 1e3, valid.shape))
    knot_pos = np.where(valid, rng.random(valid.shape) * top * 1.1, -rng.random(valid.shape))
    return valid, weights, knot_pos


brackets = st.builds(
    _bracket,
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(2, 9),
    n_pix=st.integers(1, 3000),
    n_rep=st.sampled_from([1, 3, 10]),
    split=st.booleans(),
    step=st.sampled_from([2.0, 8.0, 30.0]),
)


@settings(max_examples=60, deadline=None)
@given(case=brackets, spacing=st.sampled_from([1.0, 0.5, 4.0]))
def test_the_compiled_trim_drops_the_same_partners(case, spacing):
    values, valid, t = case
    fast = trim_censored_partners(values, valid, t, spacing)
    with _numpy_only():
        slow = trim_censored_partners(values, valid, t, spacing)
    assert fast.dtype == slow.dtype == bool
    np.testing.assert_array_equal(fast, slow)


def test_the_compiled_trim_acts_where_partners_clip():
    # not a vacuous equality: on a bracket with clipping, trimming drops values
    values, valid, t = _bracket(3, 6, 3000, 1, False)
    out = trim_censored_partners(values, valid, t)
    assert np.count_nonzero(valid & ~out) > 0
    assert not np.any(out & ~valid)


@settings(max_examples=60, deadline=None)
@given(case=brackets, n_samples=st.integers(2, 400), n_bins=st.sampled_from([64, 48, 7]))
def test_the_compiled_sampler_picks_the_same_pixels(case, n_samples, n_bins):
    values, valid, _ = case
    fast = select_samples_histogram(
        values, valid, 255.0, n_samples, np.random.default_rng(1), n_bins=n_bins
    )
    with _numpy_only():
        slow = select_samples_histogram(
            values, valid, 255.0, n_samples, np.random.default_rng(1), n_bins=n_bins
        )
    np.testing.assert_array_equal(fast, slow)


def test_the_compiled_sampler_takes_integer_values():
    values, valid, _ = _bracket(5, 5, 2500, 1, False)
    ints = values.astype(np.uint8)
    fast = select_samples_histogram(ints, valid, 255.0, 300, np.random.default_rng(2))
    with _numpy_only():
        slow = select_samples_histogram(ints, valid, 255.0, 300, np.random.default_rng(2))
    assert fast.size == 300
    np.testing.assert_array_equal(fast, slow)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(1, 9),
    n_pix=st.integers(1, 60),
    top=st.integers(1, 300),
    layout=st.sampled_from(["C", "F"]),
    per_value_times=st.booleans(),
)
def test_the_compiled_normal_equations_are_the_numpy_ones(
    seed, k_count, n_pix, top, layout, per_value_times
):
    # every array of eq. 7's system, bit for bit: values past the top level, invalid
    # values (whose weights and positions are garbage), the sample's layout either way
    rng = np.random.default_rng(seed)
    valid, weights, knot_pos = _eq7_rows(rng, k_count, n_pix, top)
    log_t = (
        rng.normal(size=(k_count, n_pix)) if per_value_times else np.sort(rng.normal(size=k_count))
    )
    if layout == "F":
        valid, weights, knot_pos = (np.asfortranarray(a) for a in (valid, weights, knot_pos))
        log_t = np.asfortranarray(log_t)
    smooth_w = rng.random(top + 1)
    args = (valid, weights, log_t, knot_pos, top, smooth_w, 10.0 * rng.random(), top // 2)
    fast = _normal_equations(*args)
    with _numpy_only():
        slow = _normal_equations(*args)
    assert fast.keys() == slow.keys()
    for name in fast:
        assert fast[name].dtype == slow[name].dtype, name
        assert fast[name].tobytes() == np.ascontiguousarray(slow[name]).tobytes(), name


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.tuples(st.integers(1, 12), st.integers(1, 300)),
    used_share=st.floats(0.0, 1.0),
    ties=st.booleans(),
    nan=st.booleans(),
)
def test_the_compiled_band_scales_are_the_numpy_ones(seed, shape, used_share, ties, nan):
    # the robust fit's noise scale per band: empty bands, bands of one value, even and
    # odd counts, repeated values, a NaN (numpy's median is NaN then)
    from photoquant.response.robust import LEVEL_BANDS, _band_scales

    rng = np.random.default_rng(seed)
    r = np.abs(rng.normal(size=shape))
    if ties:
        r = np.round(r, 1)
    if nan:
        r[rng.integers(shape[0]), rng.integers(shape[1])] = np.nan
    used = rng.random(shape) < used_share
    band = rng.integers(0, LEVEL_BANDS, shape)
    fast = _band_scales(r, used, band, LEVEL_BANDS)
    with _numpy_only():
        slow = _band_scales(r, used, band, LEVEL_BANDS)
    assert fast.tobytes() == slow.tobytes()


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(2, 6),
    n_rep=st.sampled_from([1, 4]),
    censoring=st.sampled_from(["trimmed", "ignored"]),
)
def test_the_whole_fit_has_the_same_bits(seed, k_count, n_rep, censoring):
    # every kernel at once (trim, sampler, normal equations), three channels, a stack
    # large enough for the thinning (max_pixels) and the monotone solve
    rng = np.random.default_rng(seed)
    vals = np.stack([_bracket(seed + ch, k_count, 48 * 40, n_rep, False)[0] for ch in range(3)], -1)
    t = _bracket(seed, k_count, 1, n_rep, False)[2]
    values = vals.reshape(k_count, 48, 40, 3)
    kwargs = dict(n_samples=int(rng.integers(20, 300)), censoring=censoring, max_pixels=1500)
    fast = camera_response_Debevec1997(values, t, rng=seed, **kwargs)
    with _numpy_only():
        slow = camera_response_Debevec1997(values, t, rng=seed, **kwargs)
    for name in (
        "log_inverse_response",
        "valid_min",
        "n_samples",
        "residual_rms",
        "monotone_constrained",
    ):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_rep=st.integers(1, 4),
    bits=st.sampled_from([8, 12]),
    cached=st.booleans(),
    black=st.booleans(),
    size=st.sampled_from([(9, 7), (90, 110)]),
    threads=st.integers(1, 3),
)
def test_mean_at_pixels_is_the_mean_and_mask_channel_by_channel(
    seed, n_rep, bits, cached, black, size, threads
):
    # the response fit's gather (compiled, in spans of the index on threads above 4096
    # pixels) against the stack's own mean() and masks
    import photoquant.stack as stack_module
    from photoquant.stack import ExposureStack

    rng = np.random.default_rng(seed)
    c_max = 2**bits - 1
    n_pix = size[0] * size[1]
    frames = rng.integers(0, c_max + 1, (n_rep, 3, *size, 3))
    frames[rng.random(frames.shape) < 0.1] = c_max  # clipped repeats
    frames[0, 0, 0, 0, 0] = c_max  # one at pixel 0, always gathered below
    frames = frames.astype(np.uint8 if bits == 8 else np.uint16)
    stack = ExposureStack(
        frames, [0.01, 0.04, 0.16], bit_depth=bits, black_level=3 if black else None
    )
    if cached:
        stack.repeat_sum()
        stack._repeat_extremes()
    index = np.union1d(0, rng.choice(n_pix, size=int(rng.integers(1, n_pix)), replace=False))
    old_workers = stack_module.default_workers
    stack_module.default_workers = lambda: threads
    try:
        values, excluded = stack.mean_at_pixels(index)
    finally:
        stack_module.default_workers = old_workers
    assert values.flags.c_contiguous and excluded.flags.c_contiguous
    mean = stack.mean().reshape(3, n_pix, 3)[:, index]
    mask = (stack.saturated() | stack.dark_clipped()).reshape(3, n_pix, 3)[:, index]
    np.testing.assert_array_equal(values, np.moveaxis(mean, -1, 0))
    np.testing.assert_array_equal(excluded, np.moveaxis(mask, -1, 0))
    assert excluded[0, 0, 0]  # pixel 0's clipped repeat: the mask is not vacuous
    old = stack_module.HAVE_NUMBA
    stack_module.HAVE_NUMBA = False
    try:
        slow = stack.mean_at_pixels(index)
    finally:
        stack_module.HAVE_NUMBA = old
    np.testing.assert_array_equal(values, slow[0])
    np.testing.assert_array_equal(excluded, slow[1])


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(1, 9),
    n_pix=st.integers(1, 80),
    n_levels=st.integers(2, 300),
    unused=st.floats(0.0, 1.0),
)
def test_the_compiled_sandwich_meat_is_the_numpy_one_and_the_dense_scores_product(
    seed, k_count, n_pix, n_levels, unused
):
    # the covariance's meat Σ_p s_p s_pᵀ: the compiled pairs (zero scores skipped) give the
    # numpy pairs' bits, and both are the dense (levels × pixels) score matrix's product
    # with itself up to the rounding of the sums (each entry a sum of at most 4K²P terms)
    from photoquant.response.covariance import _sandwich_meat, _sandwich_meat_numpy

    rng = np.random.default_rng(seed)
    low = rng.integers(0, n_levels - 1, (k_count, n_pix))
    idx = np.concatenate([low, low + 1])
    coef = rng.random((2 * k_count, n_pix)) * (rng.random((2 * k_count, n_pix)) >= unused)
    residual = rng.normal(size=(k_count, n_pix))
    fast = _sandwich_meat(idx, coef, residual, n_levels)
    slow = _sandwich_meat_numpy(idx, coef, residual, n_levels).reshape(n_levels, n_levels)
    assert fast.tobytes() == slow.tobytes()
    scores = np.zeros((n_levels, n_pix))
    np.add.at(
        scores,
        (idx, np.broadcast_to(np.arange(n_pix), idx.shape)),
        coef * np.tile(residual, (2, 1)),
    )
    dense = scores @ scores.T
    bound = 4 * k_count**2 * n_pix * np.finfo(float).eps * np.abs(scores).max() ** 2
    np.testing.assert_allclose(fast, dense, rtol=0, atol=bound)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(1, 9),
    n_pix=st.integers(1, 60),
    top=st.integers(1, 300),
)
def test_the_compiled_back_substitution_is_the_numpy_one(seed, k_count, n_pix, top):
    # ln E_p and the rows' residuals at a solution, from the system of eq. 7 (unused
    # values' garbage weights and positions included), one pixel and many alike
    from photoquant.response.debevec1997 import _back_substitution

    rng = np.random.default_rng(seed)
    valid, weights, knot_pos = _eq7_rows(rng, k_count, n_pix, top)
    log_t = np.sort(rng.normal(size=k_count))
    eq = _normal_equations(valid, weights, log_t, knot_pos, top, rng.random(top + 1), 1.0, 0)
    g = np.cumsum(rng.random(top + 1))
    fast = _back_substitution(eq, g)
    with _numpy_only():
        slow = _back_substitution(eq, g)
    for a, b in zip(fast, slow, strict=True):
        assert a.tobytes() == np.ascontiguousarray(b).tobytes()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 300), seed=st.integers(0, 2**32 - 1), with_prior=st.booleans())
def test_the_compiled_symmetric_part_is_numpys(n, seed, with_prior):
    rng = np.random.default_rng(seed)
    schur = rng.normal(size=(n, n)) * 10.0 ** rng.integers(-3, 4, (n, n))
    prior = rng.normal(size=(n, n)) if with_prior else None
    expected = schur + prior if with_prior else schur
    expected = 0.5 * (expected + expected.T)
    fast = _kernels.symmetric_part(schur, np.empty((0, 0)) if prior is None else prior)
    assert fast.tobytes() == expected.tobytes()


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(4, 600),
    seed=st.integers(0, 2**32 - 1),
    zeros=st.booleans(),
)
def test_the_template_penalty_gram_matrix_is_scipys_sparse_product(n, seed, zeros):
    # wide_steps.template_penalty builds Dᵀ diag(w) D band by band; it must be the bits of
    # the sparse product it replaced (so that calibrations do not move)
    import scipy.sparse

    from photoquant.response.wide_steps import template_penalty

    rng = np.random.default_rng(seed)
    w = rng.random(n - 2) ** 3 * rng.uniform(0.1, 1e4)
    if zeros:
        w[rng.random(n - 2) < 0.3] = 0.0
    g0 = np.log(np.linspace(0.01, 1.0, n))
    diff = scipy.sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n), format="csr")
    gram = (diff.T @ scipy.sparse.diags(w) @ diff).toarray()
    # factor 2: extra = (F − 1) R − (F − 1/F) r rᵀ / (g₀ᵀ r), with R the Gram matrix
    r = gram @ g0
    norm = float(g0 @ r)
    expected = (2.0 - 1.0) * gram
    if norm > 0.0:
        expected -= (2.0 - 0.5) * np.outer(r, r) / norm
    np.testing.assert_array_equal(template_penalty(w, g0, 2.0), expected)
    np.testing.assert_array_equal(template_penalty(w, g0, 1.0), 0.0 * gram)


@given(
    st.integers(1, 4),
    st.integers(1, 40),
    st.sampled_from([np.uint8, np.uint16]),
    st.integers(0, 2**32 - 1),
)
def test_at_or_above_by_channel_is_the_broadcast_comparison(n_ch, n_pix, dtype, seed):
    # channel by channel on the channel-major layout: the values and the layout of
    # `values >= level`, with fractional levels and values on them
    rng = np.random.default_rng(seed)
    top = np.iinfo(dtype).max
    values = rng.integers(0, top, (3, n_pix, n_ch), endpoint=True).astype(dtype)
    level = rng.integers(0, top, n_ch).astype(np.float64) + rng.choice([0.0, 0.5], n_ch)
    values[0, 0] = np.ceil(level).astype(dtype)  # exactly at the (rounded-up) level
    cm = _channel_major(values)
    got = _at_or_above_by_channel(cm, level)
    np.testing.assert_array_equal(got, values >= level)
    assert np.moveaxis(got, -1, 0).flags.c_contiguous or n_ch == 1


@settings(max_examples=100, deadline=None)
@given(
    keys=st.lists(st.integers(0, 5).map(float), min_size=0, max_size=70),
    seed=st.integers(0, 2**32 - 1),
)
def test_stable_order_is_numpys_stable_argsort(keys, seed):
    """The histogram selection's ranking within a bin: the members' order by key, ties in
    their order, as ``np.argsort(kind="mergesort")`` (few distinct keys: many ties)."""
    key = np.array(keys + [9.0, 9.0], dtype=np.float64)  # two pixels not among the members
    members = np.random.default_rng(seed).permutation(len(keys)).astype(np.int64)
    a, b = np.empty(key.size, np.int64), np.empty(key.size, np.int64)
    order = _kernels._stable_order(key, members, a, b)
    np.testing.assert_array_equal(order, np.argsort(key[members], kind="mergesort"))
