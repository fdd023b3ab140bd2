"""Exposure refinement against jittered synthetic truth (pqsim's camera, true response)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from photoquant import exposure
from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import (
    ExposureRefinement,
    combine_stacks,
    fit_affine_shutter,
    refine_exposure_times,
    rounding_variance,
)
from photoquant.stack import ExposureStack
from pqsim.capture_set import DEFAULT_EXPOSURES_S
from pqsim.synth_camera.presets import camera_from_preset

JITTER, LAG_S = 0.03, 1e-4  # the shutter: 3 % jitter, 0.1 ms lag


def _actual_times(t_nominal: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return t_nominal * (1 + JITTER * rng.standard_normal(t_nominal.size)) + LAG_S


def _true_g(camera, levels: np.ndarray) -> np.ndarray:
    """The camera's true ln f⁻¹ at integer levels, made finite (-inf at 0, NaN above saturation)."""
    truth = camera.truth((2, 2))
    out = np.empty((camera.n_channels, levels.size))
    for ch in range(camera.n_channels):
        with np.errstate(all="ignore"):
            g = truth.inverse_response_ln(levels, ch)
        ok = np.isfinite(g)
        out[ch] = np.interp(levels, levels[ok], g[ok])
    return out


def _jittered_capture(preset="ccd", n_repeats=1, seed=3, shape=(48, 64), **camera_changes):
    cam = camera_from_preset(preset)
    if camera_changes:
        cam = cam.replace(**camera_changes)
    rng = np.random.default_rng(seed)
    # photoquantities log-uniform over the range the 1–200 ms bracket covers
    l = np.exp(rng.uniform(np.log(4e-3), np.log(5.0), (*shape, 3)))
    t_nom = DEFAULT_EXPOSURES_S
    t_act = _actual_times(t_nom, seed)
    cap = cam.capture(l, t_act, n_repeats=n_repeats, rng=seed + 1)
    stack = ExposureStack(cap.frames, t_nom, bit_depth=cam.bit_depth, channels=cam.channels)
    levels = np.arange(2**cam.bit_depth, dtype=np.float64)
    return cam, stack, t_act, levels, _true_g(cam, levels)


def _gauge_free(x: np.ndarray) -> np.ndarray:
    return x - x.mean()


@pytest.mark.parametrize(
    ("n_repeats", "bit_depth"),
    [(1, 8), (4, 12)],
    ids=["N1-8bit", "N4-12bit"],
)
def test_refined_times_match_the_actual_ones_within_their_noise(n_repeats, bit_depth):
    """With the true response, the data give the actual exposure ratios to their noise.

    The bound is 4 standard deviations of each refined ``ln t`` as the method
    reports them (from its weighted least squares, scaled by the residuals);
    the reported deviations must themselves be small (< 0.1 %) so that the
    test is strict, and the nominal times must fail it by far.
    """
    cam, stack, t_act, levels, g = _jittered_capture(n_repeats=n_repeats, bit_depth=bit_depth)
    ref = refine_exposure_times(stack, levels, g, cam.saturation_dn, valid_min=np.ones(3))
    assert ref.refined.all()
    err = _gauge_free(np.log(ref.exposure_s)) - _gauge_free(np.log(t_act))
    assert np.all(ref.log_std < 1e-3), ref.log_std
    assert np.all(np.abs(err) < 4 * ref.log_std), (err, ref.log_std)
    nominal_err = _gauge_free(np.log(stack.exposure_s)) - _gauge_free(np.log(t_act))
    assert np.abs(nominal_err).max() > 50 * np.abs(err).max()
    # the noise model holds: residuals in units of their predicted noise are ~1
    assert 0.6 < ref.residual_rms < 1.4


def test_gauges_keep_what_they_say(rng):
    cam, stack, _, levels, g = _jittered_capture(seed=5)
    geo = refine_exposure_times(stack, levels, g, cam.saturation_dn)
    assert np.log(geo.exposure_s).mean() == pytest.approx(
        np.log(stack.exposure_s).mean(), abs=1e-12
    )
    longest = refine_exposure_times(stack, levels, g, cam.saturation_dn, gauge="longest")
    assert longest.exposure_s[-1] == pytest.approx(stack.exposure_s[-1], rel=1e-12)
    assert longest.log_std[-1] == pytest.approx(0.0, abs=1e-9)
    # the two gauges give the same ratios
    np.testing.assert_allclose(
        _gauge_free(np.log(geo.exposure_s)), _gauge_free(np.log(longest.exposure_s)), atol=1e-9
    )
    np.testing.assert_array_equal(geo.nominal_s, stack.exposure_s)
    other = geo.apply(stack)
    np.testing.assert_array_equal(other.exposure_s, geo.exposure_s)
    assert set(geo.as_dict()) >= {"exposure_s", "nominal_s", "log_std", "refined"}


def test_refinement_is_deterministic():
    cam, stack, _, levels, g = _jittered_capture(seed=7)
    a = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_values=5000, seed=1)
    b = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_values=5000, seed=1)
    np.testing.assert_array_equal(a.exposure_s, b.exposure_s)


def test_exposures_that_share_no_pixels_are_not_refined():
    """A flat scene: each exposure's values sit at one level; without overlap nothing is known."""
    frames = np.zeros((1, 3, 20, 20, 1), dtype=np.uint8)
    frames[0, 0], frames[0, 1], frames[0, 2] = 10, 100, 255  # dark, mid, saturated
    stack = ExposureStack(frames, [0.001, 0.01, 0.1], channels=("Y",), saturation_level=[255])
    levels = np.arange(256.0)
    g = np.log(np.maximum(levels, 0.5))[None]
    with pytest.raises(CalibrationError, match="do not determine the exposure times"):
        refine_exposure_times(stack, levels, g)


def test_exposures_in_sets_no_pixel_links_keep_the_labels_of_the_smaller_set():
    """Two sets of exposures 16× apart that no pixel sees both of (the bright pixels
    clip in the long ones, the dark ones are below the floor in the short ones, as a
    glare capture's source and tail): the values relate the times within each set and
    nothing between them. The set with more values is refined, to its jitter; the other
    keeps its labels. (One gauge over both sets left their relative scale to rounding:
    a glare capture's times came out 44× off.)"""
    rng = np.random.default_rng(11)
    t_nom = np.array([1.0, 2.0, 4.0, 64.0, 128.0, 256.0]) * 1e-3
    t_act = t_nom * np.exp(0.02 * rng.standard_normal(t_nom.size))
    e = np.concatenate([rng.uniform(6e3, 5e4, 700), rng.uniform(60.0, 800.0, 300)])  # DN / s
    rng.shuffle(e)
    values = e[None, :] * t_act[:, None] + rng.normal(0.0, 0.7, (t_nom.size, e.size))
    frames = np.clip(np.rint(values), 0, 255).astype(np.uint8).reshape(1, t_nom.size, 25, 40, 1)
    stack = ExposureStack(frames, t_nom, channels=("Y",), saturation_level=[255])
    levels = np.arange(256.0)
    g = np.log(np.maximum(levels, 0.5))[None]
    ref = refine_exposure_times(stack, levels, g, valid_min=np.array([12.0]))
    short, long_ = slice(0, 3), slice(3, 6)
    assert ref.refined[short].all() and not ref.refined[long_].any(), ref.n_values
    np.testing.assert_array_equal(ref.exposure_s[long_], t_nom[long_])
    err = _gauge_free(np.log(ref.exposure_s[short])) - _gauge_free(np.log(t_act[short]))
    assert np.all(np.abs(err) < 4 * ref.log_std[short] + 1e-3), (err, ref.log_std)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"log_inverse_response": np.zeros((2, 256))}, r"must be \(C, L\) = \(3, 256\)"),
        ({"levels": np.arange(256.0)[::-1].copy()}, "increasing"),
        ({"gauge": "median"}, "gauge"),
        ({"huber_k": 0.0}, "huber_k"),
        ({"max_pixels": 0}, "max_pixels"),
        ({"max_pixels": 2.5}, "max_pixels"),
    ],
)
def test_bad_arguments_are_refused(kwargs, match):
    cam, stack, _, levels, g = _jittered_capture(shape=(8, 8))
    args = {"levels": levels, "log_inverse_response": g} | kwargs
    with pytest.raises(InputError, match=match):
        refine_exposure_times(stack, args.pop("levels"), args.pop("log_inverse_response"), **args)


def test_combined_stacks_mark_other_exposures_saturated(rng):
    a = ExposureStack(rng.integers(0, 200, (2, 2, 3, 4, 3)).astype(np.uint8), [0.01, 0.02])
    b = ExposureStack(rng.integers(0, 200, (2, 2, 3, 4, 3)).astype(np.uint8), [0.02, 0.04])
    both = combine_stacks([a, b])
    np.testing.assert_array_equal(both.exposure_s, [0.01, 0.02, 0.04])
    assert both.shape == (2, 3, 1, 24, 3)
    sat = both.saturated()
    # a's pixels (first 12) were not taken at 0.04 s, b's not at 0.01 s
    assert sat[2, 0, :12].all() and sat[0, 0, 12:].all()
    np.testing.assert_array_equal(both.frames[:, :2, 0, :12], a.frames.reshape(2, 2, 12, 3))
    with pytest.raises(InputError, match="differs from stacks"):
        combine_stacks([a, ExposureStack(a.frames[:1], [0.01, 0.02])])


def test_affine_shutter_fit_recovers_exponent_and_lag():
    """Times known up to the exponent ambiguity: the shutter model finds γ and λ within their errors."""
    rng = np.random.default_rng(11)
    t_nom = DEFAULT_EXPOSURES_S
    refs, actual = [], []
    gamma, offset = 1.02, 0.3
    for _ in range(3):
        t_act = t_nom * (1 + JITTER * rng.standard_normal(t_nom.size)) + LAG_S
        actual.append(t_act)
        refs.append(
            ExposureRefinement(
                exposure_s=np.exp(gamma * np.log(t_act) + offset),
                nominal_s=t_nom,
                log_std=np.full(t_nom.size, 1e-4),
                refined=np.ones(t_nom.size, bool),
                n_values=np.full(t_nom.size, 1000),
                residual_rms=1.0,
                gauge="geometric mean",
                iterations=1,
            )
        )
    fixed, fit = fit_affine_shutter(refs)
    assert abs(fit.exponent - gamma) < 3 * fit.exponent_std
    assert abs(fit.lag_s - LAG_S) < 3 * fit.lag_std_s
    assert fit.jitter_rms == pytest.approx(gamma * JITTER, rel=0.5)
    for r, t in zip(fixed, actual, strict=True):
        err = _gauge_free(np.log(r.exposure_s)) - _gauge_free(np.log(t))
        assert np.all(np.abs(err) < 4 * r.log_std)


def test_rounding_variance_limits():
    assert rounding_variance(0.0) == pytest.approx(1 / 12, rel=0.02)  # 64 terms of Σ 1/k²
    assert rounding_variance(0.5) < 1e-5
    assert np.all(np.diff(rounding_variance(np.linspace(0, 1, 11))) <= 0)


@pytest.mark.skipif(exposure._rounding_lookup_nb is None, reason="needs numba")
@given(
    hnp.arrays(
        np.float64,
        st.integers(65, 400),
        elements=st.one_of(
            st.floats(0, 1.5), st.floats(allow_nan=True, allow_infinity=True), st.just(1.0)
        ),
    )
)
def test_rounding_variance_compiled_lookup_is_the_numpy_one(sigma):
    # the compiled table look-up gives the numpy formula's bits: on the grid, between,
    # above 1 DN, at 1, NaN, infinite, negative (|σ|)
    got = rounding_variance(sigma)
    with np.errstate(over="ignore"):  # σ·16384 overflows to inf (then 0) for σ > 1e304
        want = exposure._rounding_lookup(np.abs(sigma), exposure._rounding_table()[1])
    np.testing.assert_array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))


def test_refined_scene_times_restore_the_test_scene_error():
    """The issue's target at correction: a scene bracket shot with 3 % jitter and 0.1 ms lag,
    labelled with its nominal times and refined against the camera's response, is measured
    within 10 % of the error it has with its exact times (the perfectly calibrated camera,
    so that only the exposure times differ)."""
    from photoquant.correction import correct
    from pqsim.analytic import scene_test_hdr
    from pqsim.capture_set import DEFAULT_SCENE_EXPOSURES_S
    from validation.metrics import relative_error_eq8
    from validation.truth_model import camera_model_from_truth

    shape = (60, 80)
    cam = camera_from_preset("ccd")
    model = camera_model_from_truth(cam.truth(shape))
    l = scene_test_hdr(shape)
    t_nom = DEFAULT_SCENE_EXPOSURES_S
    t_act = _actual_times(t_nom, seed=21)
    cap = cam.capture(l, t_act, n_repeats=4, rng=22)
    nominal = ExposureStack(cap.frames, t_nom, bit_depth=cam.bit_depth, channels=cam.channels)
    ref = refine_exposure_times(
        nominal,
        model.response.levels,
        model.response.log_inverse_response,
        model.response.saturation_level,
        valid_min=model.response.valid_min,
    )

    def error(stack):
        res = correct(stack, model)
        return relative_error_eq8(l, res.photoquantity, res.mask)[1].e_mean

    exact = error(nominal.with_exposure_times(t_act))
    assert error(ref.apply(nominal)) <= 1.10 * exact
    assert error(nominal) > 1.3 * exact  # the lag and jitter do matter


def test_joint_refinement_removes_the_jitter_the_data_determine():
    """Three views with independent shutter errors and one recovered response.

    The data determine each view's exposure errors up to a constant and a
    part linear in ``ln t`` (the exponent ambiguity); what is left after
    removing that part must be within the response method's 0.5 % budget
    (an error δ in ``g`` moves an exposure by at most δ), where the nominal
    times are off by their 3 % jitter.
    """
    from photoquant.exposure import refine_jointly
    from photoquant.response import recover_response

    cam = camera_from_preset("ccd")
    rng = np.random.default_rng(31)
    t_nom = DEFAULT_EXPOSURES_S
    views, actual = [], []
    for v in range(3):
        l = np.exp(rng.uniform(np.log(4e-3), np.log(5.0), (40, 60, 3)))
        t_act = _actual_times(t_nom, seed=40 + v)
        cap = cam.capture(l, t_act, n_repeats=4, rng=50 + v)
        views.append(ExposureStack(cap.frames, t_nom, bit_depth=8, channels=cam.channels))
        actual.append(t_act)

    def recover(stack):
        r = recover_response(stack, n_samples=2000, rng=np.random.default_rng(0))
        return r.levels, r.log_inverse_response, r.saturation_level, r.valid_min

    refs, _ = refine_jointly(views, recover, rounds=3)
    design = np.c_[np.ones(t_nom.size), np.log(t_nom)]

    def nonlinear_part(t, t_act):
        d = np.log(t) - np.log(t_act)
        return d - design @ np.linalg.lstsq(design, d, rcond=None)[0]

    for ref, t_act in zip(refs, actual, strict=True):
        assert np.abs(nonlinear_part(ref.exposure_s, t_act)).max() < 0.005  # 0.03 % seen
    assert max(np.abs(nonlinear_part(t_nom, t)).max() for t in actual) > 0.02


def test_a_pixel_sample_refines_to_the_statistics_of_its_size():
    """``max_pixels``: 4 000 of 19 200 pixels give the actual ratios within their (larger) noise.

    The log times' statistical errors scale as 1/√pixels: the sample's reported
    deviations must be about √(19200/4000) ≈ 2.2 times those of every pixel
    (1.5–3.5 allows for the random draw), and both results must match the
    actual times within 4 of their own deviations.
    """
    cam, stack, t_act, levels, g = _jittered_capture(shape=(120, 160), seed=11)
    every = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_pixels=None)
    sample = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_pixels=4000)
    assert every.refined.all() and sample.refined.all()
    truth = _gauge_free(np.log(t_act))
    for ref in (every, sample):
        err = _gauge_free(np.log(ref.exposure_s)) - truth
        assert np.all(np.abs(err) < 4 * ref.log_std), (err, ref.log_std)
    ratio = np.median(sample.log_std / every.log_std)
    assert 1.5 < ratio < 3.5, ratio


def test_a_sample_that_cannot_decide_falls_back_to_every_pixel():
    """A sample too small for ``min_overlap`` refines from every pixel, exactly as ``max_pixels=None``."""
    cam, stack, _, levels, g = _jittered_capture(shape=(48, 64), seed=13)
    every = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_pixels=None)
    tiny = refine_exposure_times(stack, levels, g, cam.saturation_dn, max_pixels=40)
    np.testing.assert_array_equal(tiny.exposure_s, every.exposure_s)
    np.testing.assert_array_equal(tiny.n_values, every.n_values)


def test_a_refinements_derived_quantities_follow_from_its_fields():
    """``std_s`` is each refined time times its ``ln`` standard deviation and
    ``relative_change`` the refined time over the label, less one."""
    from photoquant.exposure import ExposureRefinement

    ref = ExposureRefinement(
        exposure_s=np.array([0.011, 0.0195]),
        nominal_s=np.array([0.01, 0.02]),
        log_std=np.array([0.02, 0.01]),
        refined=np.array([True, True]),
        n_values=np.array([100, 100]),
        residual_rms=0.01,
        gauge="geometric mean",
        iterations=3,
    )
    np.testing.assert_allclose(ref.std_s, [0.00022, 0.000195])
    np.testing.assert_allclose(ref.relative_change, [0.1, -0.025])
