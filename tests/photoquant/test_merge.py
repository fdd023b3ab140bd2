"""HDR merge (eq. 6): accuracy, invariances, flagged pixels, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from photoquant.merge import merge_Debevec1997

from .analytic import capture, log_uniform_scene, true_g

BALANCE = (0.85, 1.0, 0.75)
EXPOSURES = np.geomspace(0.5, 500.0, 8)
LEVELS = np.arange(256.0)


def f32_atol(g, exposure_s):
    """The table merge's float32 bound on ``ln c`` (photoquant.merge._tiled):
    ``(2K + 3)·2⁻²⁴·max|g − ln t|`` over every table entry (a bound for any pixel)."""
    t = np.asarray(exposure_s, dtype=float)
    return (2 * t.size + 3) * 2.0**-24 * float(np.max(np.abs(g[..., None] - np.log(t))))


def _true_table(gamma=2.2):
    # ln f⁻¹ at every level; level 0 maps to -inf: any finite value does (weight 0 there)
    g = np.stack(
        [true_g(np.maximum(LEVELS, 0.5), ch, gamma=gamma, balance=BALANCE) for ch in range(3)]
    )
    return g


def test_merge_with_true_response_is_exact_to_quantisation(rng):
    l = log_uniform_scene(rng, (30, 40, 3), decades=3.0)
    frames = capture(l, EXPOSURES, balance=BALANCE)[0]
    sat = np.round(np.array(BALANCE) * 255)
    res = merge_Debevec1997(frames, EXPOSURES, LEVELS, _true_table(), saturation_level=sat)
    assert not res.mask.any()
    # each exposure's value is within half a bin of the truth: |Δ ln c| <= (g(c+.5)-g(c-.5))/2
    # for its own c, so the weighted mean is within the largest such bound of the used values
    half_bins = np.zeros(l.shape)
    for k in range(EXPOSURES.size):
        c = frames[k].astype(float)
        used = (c > 0) & (c < sat)
        q = 0.5 * 2.2 * (np.log(c + 0.5) - np.log(np.maximum(c - 0.5, 1e-9)))
        half_bins = np.maximum(half_bins, np.where(used, q, 0))
    err = np.abs(res.log_photoquantity - np.log(l))
    assert np.all(err <= half_bins + f32_atol(_true_table(), EXPOSURES))
    # and on average far better than the worst case
    assert err.mean() < 0.01


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), data=st.data())
def test_merge_is_invariant_to_the_order_of_frames(seed, data):
    rng = np.random.default_rng(seed)
    l = log_uniform_scene(rng, (6, 7, 3))
    frames = capture(l, EXPOSURES, balance=BALANCE)[0]
    perm = np.array(data.draw(st.permutations(range(EXPOSURES.size))))
    a = merge_Debevec1997(frames, EXPOSURES, LEVELS, _true_table())
    b = merge_Debevec1997(frames[perm], EXPOSURES[perm], LEVELS, _true_table())
    np.testing.assert_array_equal(a.mask, b.mask)
    # another order sums the float32 terms in another order: each is within the bound
    atol = 2 * f32_atol(_true_table(), EXPOSURES)
    np.testing.assert_allclose(a.log_photoquantity, b.log_photoquantity, rtol=0, atol=atol)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), log_s=st.floats(-5, 5))
def test_scaling_exposure_times_shifts_log_photoquantity(seed, log_s):
    """Times × s ⇒ ln c − ln s (eq. 6: ln c = g(c) − ln t)."""
    rng = np.random.default_rng(seed)
    frames = capture(log_uniform_scene(rng, (6, 7, 3)), EXPOSURES, balance=BALANCE)[0]
    s = np.exp(log_s)
    a = merge_Debevec1997(frames, EXPOSURES, LEVELS, _true_table())
    b = merge_Debevec1997(frames, EXPOSURES * s, LEVELS, _true_table())
    # both within the float32 bound of their exact values (the bound of the scaled times)
    atol = f32_atol(_true_table(), EXPOSURES) + f32_atol(_true_table(), EXPOSURES * s)
    np.testing.assert_allclose(b.log_photoquantity, a.log_photoquantity - log_s, atol=atol)


def test_pixels_without_valid_exposure_are_flagged_not_wrong():
    values = np.full((3, 2, 2, 3), 120.0)
    values[:, 0, 0, :] = 255.0  # saturated everywhere
    values[:, 1, 1, :] = 0.0  # dark everywhere
    res = merge_Debevec1997(values, [1.0, 2.0, 4.0], LEVELS, np.tile(np.log(LEVELS + 1), (3, 1)))
    assert res.mask[0, 0].all() and res.all_saturated[0, 0].all() and not res.all_dark[0, 0].any()
    assert res.mask[1, 1].all() and res.all_dark[1, 1].all() and not res.all_saturated[1, 1].any()
    assert np.isnan(res.log_photoquantity[res.mask]).all()
    assert np.isfinite(res.log_photoquantity[~res.mask]).all()
    assert res.mask.sum() == 6


def test_saturated_repeats_are_excluded_even_below_the_level():
    # mean of repeats 255 and 240 = 247.5 < 255, but a repeat clipped: weight 0
    values = np.full((2, 1, 1, 1), 100.0)
    values[1] = 247.5
    saturated = np.zeros(values.shape, dtype=bool)
    saturated[1] = True
    g = np.log(LEVELS + 1)[None]
    res = merge_Debevec1997(values, [1.0, 2.0], LEVELS, g, saturated=saturated)
    assert res.log_photoquantity[0, 0, 0] == pytest.approx(np.log(101.0))


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ({"exposure_s": [1.0, 2.0]}, "has 2 times but `values` has K=3"),
        ({"levels": np.arange(256.0)[::-1]}, "increasing"),
        ({"log_inverse_response": np.zeros((2, 256))}, r"shape \(3, 256\)"),
        ({"values": np.zeros((3, 2, 2))}, "4 dimensions"),
        ({"saturation_level": [255, 255]}, "saturation_level"),
        ({"log_inverse_response": np.full((3, 256), np.nan)}, "NaN"),
    ],
)
def test_bad_input_is_named(args, match):
    base = {
        "values": np.full((3, 2, 2, 3), 100.0),
        "exposure_s": [1.0, 2.0, 4.0],
        "levels": LEVELS,
        "log_inverse_response": np.zeros((3, 256)),
    }
    base |= args
    kw = {k: base.pop(k) for k in list(base) if k == "saturation_level"}
    with pytest.raises(InputError, match=match):
        merge_Debevec1997(*base.values(), **kw)


@pytest.mark.parametrize("weighting", ["hat", "hat-quantisation", "uniform"])
def test_integer_fast_path_equals_the_float_path(rng, weighting):
    frames = capture(log_uniform_scene(rng, (12, 14, 3)), EXPOSURES, balance=BALANCE)[0]
    sat = np.round(np.array(BALANCE) * 255)
    g = _true_table()
    kw = {
        "saturation_level": sat,
        "min_level": np.array([3.0, 2.0, 4.0]),
        "weighting": weighting,
        "dark_clipped": frames == 0,
    }
    a = merge_Debevec1997(frames, EXPOSURES, LEVELS, g, **kw)
    b = merge_Debevec1997(frames.astype(np.float64), EXPOSURES, LEVELS, g, **kw)
    assert a.log_photoquantity.dtype == np.float32 and b.log_photoquantity.dtype == np.float64
    for field in ("mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    atol = f32_atol(g, EXPOSURES)
    np.testing.assert_allclose(a.log_photoquantity, b.log_photoquantity, rtol=0, atol=atol)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 12),
    weighting=st.sampled_from(["hat", "hat-quantisation", "uniform"]),
    sat_offset=st.floats(-30.0, 0.0),
)
def test_merge_of_repeat_sums_is_the_merge_of_their_means(seed, n, weighting, sat_offset):
    """Sums of N integer frames with ``repeats=N`` (table path) = their means (float path).

    The same values are excluded and flagged; ``ln c`` agrees within the float32
    bound and ``Σw`` within its ``(K + 1)·2⁻²⁴`` relative rounding.
    """
    rng = np.random.default_rng(seed)
    frames = rng.integers(0, 256, size=(n, 4, 5, 6, 3))
    sums = frames.sum(axis=0).astype(np.uint16)
    sat = 255.0 + sat_offset
    kw = {
        "saturation_level": np.full(3, sat),
        "saturated": np.any(frames >= sat, axis=0),
        "dark_clipped": np.any(frames == 0, axis=0),
        "min_level": np.array([3.0, 0.0, 7.5]),
        "weighting": weighting,
    }
    g = _true_table()
    t = EXPOSURES[:4]
    a = merge_Debevec1997(sums, t, LEVELS, g, repeats=n, **kw)
    b = merge_Debevec1997(frames.mean(axis=0), t, LEVELS, g, **kw)
    for field in ("mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    np.testing.assert_allclose(
        a.log_photoquantity, b.log_photoquantity, rtol=0, atol=f32_atol(g, t)
    )
    np.testing.assert_allclose(a.weight_sum, b.weight_sum, rtol=(t.size + 1) * 2.0**-24, atol=0)


def test_repeats_needs_integer_sums():
    g = np.zeros((1, 256))
    with pytest.raises(InputError, match="integer sums"):
        merge_Debevec1997(np.full((2, 1, 1, 1), 10.5), [1.0, 2.0], LEVELS, g, repeats=3)
    with pytest.raises(InputError, match="`repeats`"):
        merge_Debevec1997(np.full((2, 1, 1, 1), 10), [1.0, 2.0], LEVELS, g, repeats=0)


def test_merge_methods_registry_dispatches_through_calibrate_and_correct(rng, tmp_path):
    """A merge method registered by name is used by merge_stack, stored by calibrate, used by correct.

    The method receives the stack (denoised means and N through the stack) and
    the response model, never integer sums with a repeat count to honour.
    """
    from photoquant.calibration import calibrate
    from photoquant.correction import correct
    from photoquant.merge import MERGE_METHODS, merge_stack, merge_stack_Debevec1997
    from photoquant.methods import register_method
    from photoquant.model import load_camera
    from photoquant.stack import ExposureStack

    assert MERGE_METHODS["Debevec 1997"].function is merge_stack_Debevec1997
    frames = capture(log_uniform_scene(rng, (10, 12, 3)), EXPOSURES, balance=BALANCE)
    stack = ExposureStack(frames.astype(np.uint8), EXPOSURES)
    g = _true_table()
    sat = stack.saturation_level
    ref = merge_stack(stack, LEVELS, g, sat)
    same = merge_stack(stack, LEVELS, g, sat, method="debevec 1997")  # case-insensitive
    np.testing.assert_array_equal(ref.log_photoquantity, same.log_photoquantity)
    with pytest.raises(InputError, match="unknown merge method 'nope'.*Debevec 1997"):
        merge_stack(stack, LEVELS, g, sat, method="nope")

    calls = []

    def traced(stack, response, options):
        calls.append((stack.n_repeats, response.method))
        return merge_stack_Debevec1997(stack, response, None)

    register_method("merge", "Traced", traced)
    try:
        model = calibrate([stack], merge="traced")
        assert model.parameters["steps"]["merge"]["method"] == "Traced" and calls
        n_calls = len(calls)
        correct(stack, model)
        assert len(calls) == n_calls + 1
        model.save(tmp_path / "cam")
        assert load_camera(tmp_path / "cam").merge.method == "Traced"
        with pytest.raises(InputError, match="unknown merge method"):
            calibrate([stack], merge="nope")
    finally:
        MERGE_METHODS.remove("Traced")


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(5, 7, 3), (700, 600, 3), (1, 2_000_000)])
def test_photoquantity_is_exp_of_the_log_to_the_bit(dtype, shape):
    # large results are exponentiated in row blocks on threads: numpy's exp, NaN kept
    from photoquant.merge import MergeResult

    rng = np.random.default_rng(3)
    log_c = rng.normal(0.0, 3.0, shape).astype(dtype)
    log_c.reshape(-1)[::97] = np.nan
    flags = np.isnan(log_c)
    res = MergeResult(log_c, flags, flags, np.zeros_like(flags), np.ones(shape, dtype))
    lin = res.photoquantity()
    expected = np.exp(log_c)
    assert lin.dtype == expected.dtype and lin.shape == expected.shape
    np.testing.assert_array_equal(lin, expected)


def test_correct_says_how_many_values_have_no_photoquantity(rng):
    """A scene black in every exposure corrects without an error, every value NaN, and
    the notes say so; a usual scene's notes give the shares of each cause."""
    from photoquant.calibration import calibrate
    from photoquant.correction import correct
    from photoquant.stack import ExposureStack

    frames = capture(log_uniform_scene(rng, (10, 12, 3)), EXPOSURES, balance=BALANCE)
    model = calibrate([ExposureStack(frames.astype(np.uint8), EXPOSURES)])
    black = ExposureStack(np.zeros_like(frames, dtype=np.uint8), EXPOSURES)
    result = correct(black, model)
    assert np.all(np.isnan(result.photoquantity)) and result.all_dark.all()
    assert "100 % of the values have no photoquantity (NaN): 100 % dark in every exposure" in (
        result.notes
    )
    frames = frames.astype(np.uint8)
    frames[:, :, 0, 0, :] = 255  # one pixel saturated in every exposure: 1 of 120 values
    result = correct(ExposureStack(frames, EXPOSURES), model)
    share = 100 * np.count_nonzero(result.mask) / result.mask.size
    note = [n for n in result.notes if "no photoquantity" in n]
    assert note and note[0].startswith(f"{share:.3g} % of the values")
    assert "saturated in every exposure" in note[0]
