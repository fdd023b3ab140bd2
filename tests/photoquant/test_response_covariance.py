"""The recovered response's covariance: estimated, stored, propagated, validated.

The sandwich covariance of eq. 7 (:mod:`photoquant.response.covariance`) is
checked against what it claims to be — the scatter of ``g`` from one capture
to another of the same camera — over 40 independent captures of analytic
scenes (a fresh scene, noise and sample each). Against the *truth* it
covers less than it states: eq. 7's estimate carries a bias from noise and
quantisation (a ripple with the bracket's step, the one shape of ``g`` that
the pixels' ratios cannot see, and a drift that grows with the noise). With
the defaults — ``g`` refined in the values, samples from flat regions — the
stated σ puts 85 % of the values inside the nominal 95 % interval at 2 DN of
noise and 93 % at 0.7 DN (eq. 7 as written, every candidate sampled: 35 %
and 81 %); the test of full coverage is an expected failure until the rest
is modelled. The method's other covariance, the exposure jackknife (the
spread of ``g`` over the fits that each leave one exposure out), states most
of eq. 7's error and is checked against the truth the same way.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.merge import DebevecMergeOptions, MergeModel
from photoquant.merge.uncertainty import log_variance_response_Debevec1997
from photoquant.response.covariance import (
    MIN_JACKKNIFE_EXPOSURES,
    exposure_jackknife_factor,
    low_rank_factor,
)
from photoquant.response.debevec1997 import (
    DebevecResponseOptions,
    camera_response_Debevec1997,
    characterise_response_Debevec1997,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

from .analytic import capture, log_uniform_scene, true_g

EXPOSURES = np.geomspace(0.5, 500.0, 8)
LEVELS = np.array([20, 40, 60, 90, 110, 160, 200, 230])
WHITE = (1.0, 1.0, 1.0)


def _captures(n_captures: int, noise_dn: float):
    """``(seed, frames (1, K, 60, 80, 3))``: independent captures of analytic scenes."""
    for seed in range(n_captures):
        rng = np.random.default_rng(seed)
        frames = capture(
            log_uniform_scene(rng, (60, 80, 3)),
            EXPOSURES,
            balance=WHITE,
            noise_dn=noise_dn,
            rng=rng,
        )
        yield seed, frames


def _repeated_fits(n_captures: int, noise_dn: float):
    """``g`` and its stated standard deviation at LEVELS over independent captures."""
    g, sd = [], []
    for seed, frames in _captures(n_captures, noise_dn):
        rec = camera_response_Debevec1997(
            frames[0], EXPOSURES, saturation_level=np.full(3, 255.0), uncertainty=True, rng=seed
        )
        g.append(rec.log_inverse_response[:, LEVELS])
        sd.append(np.sqrt(rec.log_inverse_response_variance[:, LEVELS]))
    return np.array(g), np.array(sd)


@pytest.fixture(scope="module")
def fits():
    return _repeated_fits(40, 2.0)


def test_stated_uncertainty_matches_the_scatter_between_captures(fits):
    g, sd = fits
    n = g.shape[0]
    z = (g - g.mean(axis=0)) / sd * np.sqrt(n / (n - 1))
    # 120 fits per level: the std of z is known to ±0.065 per level (1/√(2·119)), a
    # little better pooled over 8 levels; the sandwich's small-sample bias is a few %
    assert abs(z.std() - 1.0) < 0.15, z.std()
    assert np.all(np.abs(z.std(axis=(0, 1)) - 1.0) < 0.3), z.std(axis=(0, 1))


def test_stated_uncertainty_shrinks_with_the_noise():
    _, loud = _repeated_fits(3, 2.0)
    _, quiet = _repeated_fits(3, 0.7)
    # the statistical error follows the noise (≈ ∝ σ, less quantisation)
    assert np.median(quiet / loud) < 0.6


GAUGE_LEVEL = 127
"""Where the fit fixes ``g = 0``: the level nearest the middle of [0, 255] (the first of
127 and 128), and where its stated variance is 0: the truth is compared relative to it."""


def _true_g_at_levels() -> np.ndarray:
    """The analytic camera's ``g`` at LEVELS relative to the gauge level, ``(3, levels)``."""
    return np.stack(
        [true_g(LEVELS, c, balance=WHITE) - true_g(GAUGE_LEVEL, c, balance=WHITE) for c in range(3)]
    )


@pytest.mark.xfail(
    strict=True,
    reason="Debevec's g is biased by noise and quantisation (a ripple with the bracket's "
    "step, and a drift with the noise); the covariance is the statistical part only "
    "(measured 2026-12-06 with the defaults: 85 % inside the nominal 95 % interval at 2 DN, "
    "93 % at 0.7 DN)",
)
def test_stated_uncertainty_covers_the_truth(fits):
    g, sd = fits
    truth = _true_g_at_levels()
    inside = np.abs(g - truth[None]) / sd < 1.96
    assert inside.mean() > 0.93


def _method_fits(n_captures: int, noise_dn: float, covariance: str, edges: str = "excluded"):
    """As :func:`_repeated_fits`, through the ``"Debevec 1997"`` method with its defaults and
    the given ``covariance``; ``g`` relative to the gauge level (the truth's reference)."""
    g, sd = [], []
    options = DebevecResponseOptions(covariance=covariance, edges=edges)
    for seed, frames in _captures(n_captures, noise_dn):
        stack = ExposureStack(frames, EXPOSURES, bit_depth=8, saturation_level=[255] * 3)
        model = characterise_response_Debevec1997(stack, options, seed).model
        rel = (
            model.log_inverse_response
            - model.log_inverse_response[:, GAUGE_LEVEL : GAUGE_LEVEL + 1]
        )
        g.append(rel[:, LEVELS])
        sd.append(np.sqrt(model.covariance_diagonal[:, LEVELS]))
    return np.array(g), np.array(sd)


@pytest.mark.parametrize("noise_dn", [0.7, 2.0])
def test_the_exposure_jackknife_states_what_the_sandwich_misses(noise_dn):
    """Against the truth, over independent captures (K = 8), every candidate sampled: the
    jackknife's stated σ covers the recovered ``g``'s error, bias included, far better than
    the sandwich's.

    Measured (2026-12-06; 10 captures, 240 values each, strongly correlated within a
    capture: the bias is one pattern): at 0.7 DN the sandwich puts 81 % inside 1.96 σ, the
    jackknife 97 % (rms z 1.48 and 0.83); at 2 DN 35 % and 78 % (rms z 2.78 and 1.58).
    With the default samples, from flat regions, the bias is smaller and the sandwich
    nearly covers: 93 % and 89 % (rms z 1.07 and 1.24; the jackknife 99 % and 96 %).
    """
    truth = _true_g_at_levels()
    shares, rms = {}, {}
    for covariance in ("sandwich", "exposure jackknife"):
        g, sd = _method_fits(10, noise_dn, covariance, edges="kept")
        z = (g - truth[None]) / sd
        shares[covariance] = np.mean(np.abs(z) < 1.96)
        rms[covariance] = np.sqrt(np.mean(z**2))
    assert shares["exposure jackknife"] > shares["sandwich"] + 0.15, shares
    if noise_dn < 1:  # the bias small beside the noise: the jackknife covers (conservatively)
        assert shares["exposure jackknife"] > 0.9 and 0.6 < rms["exposure jackknife"] < 1.3, (
            shares,
            rms,
        )
    else:  # the bias dominates: most of it carried
        assert rms["exposure jackknife"] < 0.7 * rms["sandwich"], rms


def test_exposure_jackknife_factor_is_the_delete_one_jackknife():
    rng = np.random.default_rng(3)
    g = rng.normal(size=(5, 2, 7))
    factor = exposure_jackknife_factor(g)
    assert factor.shape == (2, 5, 7)
    for c in range(2):
        dev = g[:, c] - g[:, c].mean(axis=0)
        expected = 4 / 5 * dev.T @ dev
        np.testing.assert_allclose(factor[c].T @ factor[c], expected, rtol=1e-12, atol=1e-15)
    with pytest.raises(InputError, match="K ≥ 2"):
        exposure_jackknife_factor(g[:1])
    g[2, 1, 3] = np.nan
    with pytest.raises(InputError, match="finite"):
        exposure_jackknife_factor(g)


def test_the_method_keeps_its_g_and_says_which_covariance():
    rng = np.random.default_rng(4)
    frames = capture(log_uniform_scene(rng, (30, 40, 3)), EXPOSURES, noise_dn=1.0, rng=rng)
    stack = ExposureStack(frames, EXPOSURES, bit_depth=8, saturation_level=[255] * 3)
    jack = characterise_response_Debevec1997(
        stack, DebevecResponseOptions(covariance="exposure jackknife"), 0
    )
    plain = characterise_response_Debevec1997(stack, DebevecResponseOptions(), 0)
    # the covariance is a by-product: the same g either way
    np.testing.assert_array_equal(jack.model.log_inverse_response, plain.model.log_inverse_response)
    assert jack.report["covariance"] == "exposure jackknife"
    assert plain.report["covariance"] == "sandwich"
    assert jack.model.covariance_factor.shape[1] == EXPOSURES.size  # one row per fit
    np.testing.assert_allclose(jack.model.covariance_factor.sum(axis=1), 0.0, atol=1e-12)
    # too few exposures to leave one out: the sandwich, said so
    short = stack.with_frames(frames[:, :3], EXPOSURES[:3])
    fit = characterise_response_Debevec1997(
        short, DebevecResponseOptions(covariance="exposure jackknife"), 0
    )
    assert fit.report["covariance"].startswith("sandwich")
    assert str(MIN_JACKKNIFE_EXPOSURES) in fit.report["covariance"]
    assert fit.model.covariance_factor is not None
    with pytest.raises(InputError, match="covariance"):
        DebevecResponseOptions(covariance="bootstrap")


RESPONSE_ONLY = {"vignetting": "None", "sensor_lut": "None", "balance": "None"}
"""calibrate's later steps off: the calibrations below differ in the response step alone."""


def _two_views(seed: int) -> list[ExposureStack]:
    """Two views of analytic scenes (30×40, the 8 exposures, 1 DN of noise), exact labels."""
    rng = np.random.default_rng(seed)
    return [
        ExposureStack(
            capture(log_uniform_scene(rng, (30, 40, 3)), EXPOSURES, noise_dn=1.0, rng=rng),
            EXPOSURES,
            bit_depth=8,
            saturation_level=[255] * 3,
        )
        for _ in range(2)
    ]


def test_the_view_time_screen_judges_with_the_jackknife_fit_itself(monkeypatch):
    """Two views: the screen of the labels fits ``g`` on view 0 with the method, and with
    the profile's reference only where that is another ``g``; the exposure jackknife
    differs from the reference in the covariance alone, so its own fit judges — one fit
    fewer, the same decision and ``g`` as the default."""
    import photoquant as pq
    from photoquant import calibration_steps

    views = _two_views(5)
    calls: list[str] = []
    real_fit = calibration_steps.fit_response

    def counted(stack, spec, **kwargs):
        calls.append(spec[1].covariance if hasattr(spec[1], "covariance") else str(spec))
        return real_fit(stack, spec, **kwargs)

    monkeypatch.setattr(calibration_steps, "fit_response", counted)
    default = pq.calibrate(views, **RESPONSE_ONLY)
    n_default = len(calls)
    calls.clear()
    jack = pq.calibrate(
        views, response=("Debevec 1997", {"covariance": "exposure jackknife"}), **RESPONSE_ONLY
    )
    # the screen's fit is the method's own (first), and no reference fit is added to the
    # default's count (the old screen fitted the reference too: one more)
    assert calls[0] == "exposure jackknife" and len(calls) == n_default
    np.testing.assert_array_equal(
        jack.response.log_inverse_response, default.response.log_inverse_response
    )
    assert jack.report["exposures"] == default.report["exposures"]
    assert jack.report["response"]["covariance"] == "exposure jackknife"


def test_labels_the_reference_keeps_stay_where_the_methods_own_g_cannot_relate_pairs(
    monkeypatch,
):
    """The screen judges the labels with the profile's response; a method whose own ``g``
    cannot relate some view's neighbouring pairs (a peer's poor fit) keeps those labels,
    with no joint recovery of the times: the calibration at the labels, the reference's
    decision reported."""
    import photoquant as pq
    from photoquant import calibration_steps

    views = _two_views(6)
    spec = ("Debevec 1997", {"smoothness": 300.0})  # not the profile's: the reference judges
    real_pairs = calibration_steps._refine_views_by_pairs
    calls = []

    def method_cannot_tell(views_, fit, seed):
        calls.append(fit)
        return real_pairs(views_, fit, seed) if len(calls) == 1 else None

    def no_joint(*args, **kwargs):
        raise AssertionError("the joint recovery ran although the labels were kept")

    monkeypatch.setattr(calibration_steps, "_refine_views_by_pairs", method_cannot_tell)
    monkeypatch.setattr(calibration_steps, "_recover_with_view_times", no_joint)
    kept = pq.calibrate(views, response=spec, **RESPONSE_ONLY)
    monkeypatch.undo()
    assert len(calls) == 2  # the reference's pairs, then the method's own
    assert kept.report["exposures"]["refined"] is False
    assert kept.report["exposures"]["decision"]["refine"] is False
    at_labels = pq.calibrate(views, response=spec, refine_exposures=False, **RESPONSE_ONLY)
    np.testing.assert_array_equal(
        kept.response.log_inverse_response, at_labels.response.log_inverse_response
    )


def test_a_jackknife_that_cannot_fit_keeps_the_sandwich_and_says_why(monkeypatch):
    import photoquant.response.debevec1997 as debevec

    def no_overlap(*args, **kwargs):
        raise debevec.CalibrationError("the exposures do not overlap")

    rng = np.random.default_rng(4)
    frames = capture(log_uniform_scene(rng, (30, 40, 3)), EXPOSURES, noise_dn=1.0, rng=rng)
    stack = ExposureStack(frames, EXPOSURES, bit_depth=8, saturation_level=[255] * 3)
    plain = characterise_response_Debevec1997(stack, DebevecResponseOptions(), 0)
    monkeypatch.setattr(debevec, "exposure_jackknife_factor", no_overlap)
    fit = characterise_response_Debevec1997(
        stack, DebevecResponseOptions(covariance="exposure jackknife"), 0
    )
    assert fit.report["covariance"].startswith("sandwich (the exposure jackknife failed")
    assert "do not overlap" in fit.report["covariance"]
    np.testing.assert_array_equal(fit.model.covariance_factor, plain.model.covariance_factor)


def test_uncertainty_is_relative_to_the_gauge_level():
    rng = np.random.default_rng(0)
    frames = capture(log_uniform_scene(rng, (40, 50, 3)), EXPOSURES, noise_dn=1.0, rng=rng)
    rec = camera_response_Debevec1997(frames[0], EXPOSURES, uncertainty=True, n_samples=500)
    var = rec.log_inverse_response_variance
    gauge = np.argmin(np.abs(rec.levels - 0.5 * (0 + 255)))
    assert np.all(var[:, gauge] < 1e-6 * var.max(axis=1))
    assert np.all(var.max(axis=1) > 0)
    # without the option: nothing estimated, the same g (the covariance is a by-product)
    plain = camera_response_Debevec1997(frames[0], EXPOSURES, n_samples=500)
    assert plain.log_inverse_response_factor is None
    np.testing.assert_array_equal(plain.log_inverse_response, rec.log_inverse_response)


def test_low_rank_factor_keeps_the_leading_part():
    rng = np.random.default_rng(1)
    basis = rng.normal(size=(3, 50))
    cov = basis.T @ np.diag([4.0, 1.0, 1e-9]) @ basis
    f = low_rank_factor(cov, fraction=0.999)
    assert f.shape == (2, 50)
    np.testing.assert_allclose(f.T @ f, cov, atol=1e-6 * np.abs(cov).max())
    np.testing.assert_array_equal(low_rank_factor(np.zeros((5, 5))), np.zeros((1, 5)))


def _response_with_covariance(rng, rest=1e-4):
    levels = np.arange(256.0)
    g = np.log(np.maximum(levels, 0.5) / 255.0)[None]
    # smooth rows (g moved along them stays increasing)
    phase = rng.uniform(0, 2 * np.pi, (3, 1))
    factor = (0.01 * np.sin(2 * np.pi * np.arange(1, 4)[:, None] * levels / 256 + phase))[None]
    diagonal = np.sum(factor**2, axis=1) + rng.uniform(0, rest, (1, 256))
    return ResponseModel(
        "given",
        levels,
        g,
        np.array([255.0]),
        covariance_factor=factor,
        covariance_diagonal=diagonal,
    )


def _stack(rng, k):
    frames = rng.integers(1, 255, size=(1, k, 4, 5, 1)).astype(np.uint8)
    return ExposureStack(frames, 3.0 ** np.arange(k), bit_depth=8, channels=("Y",))


def test_propagation_of_the_factor_is_the_merge_moved_along_it():
    # ln Ê is linear in g for fixed weights: moving g along the factor's rows moves
    # ln Ê by Σ_k a_k F_r(c_k), whose squares sum to the stated variance
    rng = np.random.default_rng(2)
    response = _response_with_covariance(rng, rest=0.0)
    stack = _stack(rng, 3)
    merge = MergeModel("Debevec 1997", {"weighting": "hat"})
    got = log_variance_response_Debevec1997(stack, response, merge.options)
    base = merge.merge(stack, response).log_photoquantity[..., 0].astype(np.float64)
    expected = np.zeros_like(base)
    for row in response.covariance_factor[0]:
        moved = dataclasses.replace(
            response,
            log_inverse_response=response.log_inverse_response + row,
            covariance_factor=None,
            covariance_diagonal=None,
        )
        expected += (merge.merge(stack, moved).log_photoquantity[..., 0] - base) ** 2
    # the merge's float32 output: ~1e-7 of ln Ê ≈ −3 against moves of ~1e-2
    np.testing.assert_allclose(got[..., 0], expected, rtol=1e-3)


def test_the_rest_of_the_diagonal_adds_per_value():
    # one exposure: the merge is g(c) − ln t, its variance the diagonal at c
    rng = np.random.default_rng(4)
    response = _response_with_covariance(rng)
    stack = _stack(rng, 1)
    got = log_variance_response_Debevec1997(stack, response, DebevecMergeOptions(weighting="hat"))
    c = stack.frames[0, 0, ..., 0].astype(int)
    np.testing.assert_allclose(got[..., 0], response.covariance_diagonal[0][c], rtol=1e-12)


def test_a_read_back_at_the_merged_level_shares_the_responses_error():
    # one exposure read back at its own value: g's error enters both and the factor's
    # part cancels; the rest of the diagonal is independent per read, so it counts twice
    rng = np.random.default_rng(5)
    response = _response_with_covariance(rng)
    stack = _stack(rng, 1)
    options = DebevecMergeOptions(weighting="hat")
    c = stack.frames[0, 0].astype(np.float64)  # (H, W, 1)
    got = log_variance_response_Debevec1997(stack, response, options, held_out_level=c)
    rest = response.covariance_diagonal[0] - np.sum(response.covariance_factor[0] ** 2, axis=0)
    np.testing.assert_allclose(got[..., 0], 2 * rest[c[..., 0].astype(int)], rtol=1e-9, atol=1e-15)
    # read back elsewhere: the factor's rows moved g by F_r(c) − F_r(ẑ)
    other = np.full_like(c, 128.0)
    far = log_variance_response_Debevec1997(stack, response, options, held_out_level=other)
    factor = response.covariance_factor[0]
    idx = c[..., 0].astype(int)
    expected = sum((row[idx] - row[128]) ** 2 for row in factor) + rest[idx] + rest[128]
    np.testing.assert_allclose(far[..., 0], expected, rtol=1e-9)


def test_a_response_without_covariance_is_named():
    response = _response_with_covariance(np.random.default_rng(5))
    plain = dataclasses.replace(response, covariance_factor=None, covariance_diagonal=None)
    with pytest.raises(InputError, match="carries no covariance"):
        log_variance_response_Debevec1997(_stack(np.random.default_rng(6), 2), plain)


def test_response_covariance_validated_and_persisted():
    rng = np.random.default_rng(3)
    response = _response_with_covariance(rng)
    params, images = response.to_params()
    back = ResponseModel.from_params("given", params, images)
    np.testing.assert_array_equal(back.covariance_factor, response.covariance_factor)
    np.testing.assert_array_equal(back.covariance_diagonal, response.covariance_diagonal)
    # a response written without one still loads, and states none
    del params["covariance_factor"], params["covariance_diagonal"]
    assert ResponseModel.from_params("given", params, images).log_inverse_std() is None
    with pytest.raises(InputError, match="go together"):
        dataclasses.replace(response, covariance_diagonal=None)
    with pytest.raises(InputError, match="non-negative"):
        dataclasses.replace(response, covariance_diagonal=-response.covariance_diagonal)
    with pytest.raises(InputError, match=r"\(C, R, L\)"):
        dataclasses.replace(response, covariance_factor=response.covariance_factor[:, :, :10])
    # the balance folds a constant into g: the covariance stays
    balanced = response.balanced(np.array([2.0]))
    np.testing.assert_array_equal(balanced.covariance_factor, response.covariance_factor)
    np.testing.assert_array_equal(balanced.covariance_diagonal, response.covariance_diagonal)


def test_correct_states_the_response_component_beside_the_noise():
    import photoquant as pq

    rng = np.random.default_rng(7)
    frames = capture(
        log_uniform_scene(rng, (40, 50, 3)), EXPOSURES, noise_dn=1.0, n_repeats=2, rng=rng
    )
    stack = ExposureStack(frames, EXPOSURES, bit_depth=8)
    model = pq.calibrate([stack])
    result = pq.correct(stack, model, uncertainty=True)
    ok = ~result.mask
    response, noise = result.log_sigma_response[ok], result.log_sigma_noise[ok]
    assert np.all(response > 0) and np.all(np.isnan(result.log_sigma_response[~ok]))
    np.testing.assert_allclose(
        result.log_sigma[ok],
        np.sqrt(noise.astype(float) ** 2 + response.astype(float) ** 2),
        rtol=1e-6,
    )
    # a camera whose response states no covariance: the noise alone, and a note says so
    bare = dataclasses.replace(
        model,
        response=dataclasses.replace(
            model.response, covariance_factor=None, covariance_diagonal=None
        ),
    )
    plain = pq.correct(stack, bare, uncertainty=True)
    assert plain.log_sigma_response is None
    assert any("states no covariance" in note for note in plain.notes)
    np.testing.assert_array_equal(plain.log_sigma, plain.log_sigma_noise)


def test_exposure_component_is_the_merge_moved_along_the_times():
    from photoquant.merge.uncertainty import log_variance_exposure_Debevec1997

    rng = np.random.default_rng(8)
    response = _response_with_covariance(rng)
    stack = _stack(rng, 3)
    root = rng.normal(scale=0.01, size=(3, 3))
    cov = root @ root.T
    merge = MergeModel("Debevec 1997", {"weighting": "hat"})
    got = log_variance_exposure_Debevec1997(stack, response, cov, merge.options)
    base = merge.merge(stack, response).log_photoquantity[..., 0].astype(np.float64)
    vals, vecs = np.linalg.eigh(cov)
    expected = np.zeros_like(base)
    for val, vec in zip(vals, vecs.T, strict=True):
        moved = stack.with_frames(stack.frames, stack.exposure_s * np.exp(np.sqrt(val) * vec))
        expected += (merge.merge(moved, response).log_photoquantity[..., 0] - base) ** 2
    np.testing.assert_allclose(got[..., 0], expected, rtol=1e-3)
    # exposures kept at their labels (NaN rows) add nothing
    nan_cov = np.full((3, 3), np.nan)
    nan_cov[:2, :2] = cov[:2, :2]
    kept = log_variance_exposure_Debevec1997(stack, response, nan_cov, merge.options)
    assert np.all(kept <= got + 1e-15) and np.all(np.isfinite(kept))
    with pytest.raises(InputError, match=r"\(3, 3\)"):
        log_variance_exposure_Debevec1997(stack, response, cov[:2, :2])


def test_correct_states_the_refined_times_component():
    import photoquant as pq

    from .test_exposure import _jittered_capture

    _, stack, *_ = _jittered_capture(n_repeats=2, seed=5)
    model = pq.calibrate([stack])
    result = pq.correct(stack, model, uncertainty=True, refine_exposures=True)
    assert result.exposures is not None
    ok = ~result.mask
    exposure = result.log_sigma_exposure[ok].astype(np.float64)
    assert np.all(exposure > 0) and np.all(np.isnan(result.log_sigma_exposure[~ok]))
    parts = [result.log_sigma_noise, result.log_sigma_calibration]
    expected = np.sqrt(exposure**2 + sum(p[ok].astype(np.float64) ** 2 for p in parts))
    np.testing.assert_allclose(result.log_sigma[ok], expected, rtol=1e-5)
    # nominal times kept: nothing stated for them
    kept = pq.correct(stack, model, uncertainty=True, refine_exposures=False)
    assert kept.exposures is None and kept.log_sigma_exposure is None


@pytest.mark.parametrize("part", ["response", "response read back", "exposure"])
def test_the_compiled_calibration_parts_give_the_numpy_bits(monkeypatch, part):
    """The response's and the exposure times' parts, computed in compiled passes over the
    values, equal the numpy path over the merge's weights to the bit (clipped and dark
    values, a value clipped in every exposure, N = 3 repeats, three channels), the
    response's also with a held-out read-back level per value (cross-validation's)."""
    import photoquant.merge.uncertainty as uncertainty
    from photoquant.merge.uncertainty import (
        log_variance_exposure_Debevec1997,
        merge_weights_Debevec1997,
    )

    if uncertainty._weights_nb is None:
        pytest.skip("numba is not installed: the numpy path is the only one")
    rng = np.random.default_rng(11)
    frames = rng.integers(0, 256, size=(3, 4, 12, 10, 3)).astype(np.uint8)
    frames[:, 1, :2] = 255
    frames[:, 2, -2:] = 0
    frames[:, :, 5, 5] = 255
    stack = ExposureStack(frames, [0.01, 0.03, 0.1, 0.3], bit_depth=8)
    one = _response_with_covariance(rng)
    response = ResponseModel(
        "given",
        one.levels,
        np.repeat(one.log_inverse_response, 3, axis=0),
        np.full(3, 255.0),
        covariance_factor=np.repeat(one.covariance_factor, 3, axis=0) * [[[1.0]], [[0.5]], [[2]]],
        covariance_diagonal=np.repeat(one.covariance_diagonal, 3, axis=0),
    )
    a = rng.normal(size=(4, 4)) * 0.01
    log_cov = a @ a.T
    log_cov[2] = log_cov[:, 2] = np.nan  # an exposure kept at its label

    # read-back levels between and at the response's levels, and beyond its ends
    held = rng.uniform(-3.0, 258.0, size=(12, 10, 3))
    held[0, 0] = [0.0, 17.0, 255.0]
    held[0, 1] = [np.nan, np.inf, -np.inf]

    def variance(**kw):
        if part == "response":
            return log_variance_response_Debevec1997(stack, response, **kw)
        if part == "response read back":
            return log_variance_response_Debevec1997(stack, response, held_out_level=held, **kw)
        return log_variance_exposure_Debevec1997(stack, response, log_cov, **kw)

    fused = variance()
    plain = variance(weights=merge_weights_Debevec1997(stack, response))
    monkeypatch.setattr(uncertainty, f"_{part.split()[0]}_variance_nb", None)
    again = variance()
    np.testing.assert_array_equal(fused, plain)
    np.testing.assert_array_equal(fused, again)
    assert np.isnan(fused).any() and (np.nan_to_num(fused) > 0).any()
