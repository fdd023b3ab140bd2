"""The noise part of the photoquantity's uncertainty (photoquant.merge.uncertainty, correct)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photoquant as pq
from photoquant.errors import InputError
from photoquant.merge.noise_aware import (
    NoiseParameters,
    estimate_noise_from_exposures,
)
from photoquant.merge.uncertainty import (
    log_variance_Debevec1997,
    noise_parameters_from_record,
    noise_record,
)
from photoquant.response.model import ResponseModel
from photoquant.weighting import weighting_function
from pqsim.analytic import scene_test_hdr
from pqsim.synth_camera.presets import camera_from_preset

LEVELS = np.arange(256, dtype=np.float64)
GAIN, READ = 0.05, 0.8  # DN per e⁻, DN


def _linear_response() -> ResponseModel:
    """A linear camera, ``g(c) = ln c`` (black 0, clipping at 255): ``y = c`` on its linear scale."""
    g = np.log(np.maximum(LEVELS, 0.5))
    return ResponseModel(
        "linear",
        LEVELS,
        np.stack([g, g, g]),
        np.full(3, 255.0),
        valid_min=np.ones(3),
        black_level=np.zeros(3),
    )


def _stack(values_per_exposure, times) -> pq.ExposureStack:
    frames = np.array(values_per_exposure, dtype=np.uint8)[None, :, None, None, None]
    return pq.ExposureStack(np.repeat(frames, 3, axis=-1), np.asarray(times, dtype=float))


def _one_value_variance(c: float) -> float:
    """``Var(ln E)`` of one frame's value ``c`` of the linear camera: shot and read noise
    over ``y² = c²``, and quantisation ``g'²/12`` with ``g'`` the larger one-sided slope of
    the table at the level, ``ln(c/(c − 1))`` (module notes of ``noise_aware``)."""
    slope = np.log(c / (c - 1.0))
    return (GAIN * c + READ**2) / c**2 + slope**2 / 12.0


def test_one_usable_exposure_gives_its_own_variance():
    # the second exposure is clipped: the merge is the first value alone
    stack = _stack([200, 255], [1.0, 4.0])
    var = log_variance_Debevec1997(
        stack, _linear_response(), NoiseParameters(np.full(3, GAIN), np.full(3, READ), "given")
    )
    np.testing.assert_allclose(var[0, 0], _one_value_variance(200.0), rtol=1e-12)


def test_two_exposures_combine_with_the_merges_own_weights():
    stack = _stack([60, 180], [1.0, 3.0])
    noise = NoiseParameters(np.full(3, GAIN), np.full(3, READ), "given")
    var = log_variance_Debevec1997(stack, _linear_response(), noise)
    weight = weighting_function("hat-quantisation")
    w = np.array([weight(np.array([c]), 0.0, 255.0)[0] for c in (60.0, 180.0)])
    v = np.array([_one_value_variance(c) for c in (60.0, 180.0)])
    expected = np.sum(w**2 * v) / np.sum(w) ** 2
    np.testing.assert_allclose(var[0, 0], expected, rtol=1e-12)
    # the weighted mean of two estimates is more certain than either alone
    assert var[0, 0, 0] < v.min()


def test_no_usable_exposure_has_no_variance():
    stack = _stack([255, 255], [1.0, 4.0])
    noise = NoiseParameters(np.full(3, GAIN), np.full(3, READ), "given")
    assert np.all(np.isnan(log_variance_Debevec1997(stack, _linear_response(), noise)))


def test_the_compiled_pass_gives_the_numpy_bits(monkeypatch):
    import photoquant.merge.uncertainty as uncertainty
    from photoquant.merge.uncertainty import merge_weights_Debevec1997

    rng = np.random.default_rng(4)
    # clipped and dark values among them, N = 3 repeats: sums on the tables' grid
    frames = rng.integers(0, 256, size=(3, 4, 12, 10, 3)).astype(np.uint8)
    frames[:, 1, :2] = 255
    frames[:, 2, -2:] = 0
    frames[:, :, 5, 5] = 255  # clipped in every exposure: no variance
    stack = pq.ExposureStack(frames, [0.01, 0.03, 0.1, 0.3])
    noise = NoiseParameters(np.full(3, GAIN), np.full(3, READ), "given")
    fused = log_variance_Debevec1997(stack, _linear_response(), noise)
    weights = merge_weights_Debevec1997(stack, _linear_response())
    plain = log_variance_Debevec1997(stack, _linear_response(), noise, weights=weights)
    monkeypatch.setattr(uncertainty, "_weighted_variance_nb", None)
    again = log_variance_Debevec1997(stack, _linear_response(), noise)
    np.testing.assert_array_equal(fused, plain)
    np.testing.assert_array_equal(fused, again)
    assert np.isnan(fused).any() and np.isfinite(fused).any()


def test_the_camera_record_round_trips():
    params = NoiseParameters(np.array([0.1, 0.2, 0.3]), np.array([1.0, 0.0, 2.0]), "estimated")
    back = noise_parameters_from_record(noise_record(params), 3)
    np.testing.assert_array_equal(back.gain, params.gain)
    np.testing.assert_array_equal(back.read_noise, params.read_noise)
    assert back.source == "camera's calibration (estimated)"
    for bad in (
        None,
        {},
        {"gain_dn_per_e": [0.1], "read_noise_dn": [1.0]},
        {"gain_dn_per_e": [-1, 1, 1], "read_noise_dn": [0, 0, 0]},
    ):
        assert noise_parameters_from_record(bad, 3) is None


@pytest.fixture(scope="module")
def noisy_camera():
    """A cmos-preset camera calibrated from one view with 4 repeats, and its scene.

    The cmos preset's read noise (0.5 DN) dithers the quantiser: two captures of
    a scene then have independent quantisation errors. Below it (the ccd's
    0.2 DN) a value's quantisation error mostly repeats between captures (the
    same code twice): the stated uncertainty includes it, as an error against
    the truth, but a difference of two captures cannot see it.
    """
    cam = camera_from_preset("cmos")
    times = np.geomspace(2.5e-4, 0.64, 6)
    scene = scene_test_hdr((96, 128))
    view = cam.capture(scene, times, 4, rng=100)
    camera = pq.calibrate([pq.ExposureStack(view.frames, view.exposure_s)])
    return cam, camera, scene, times


@pytest.mark.parametrize("repeats", [1, 4])
def test_the_stated_uncertainty_matches_the_scatter_of_independent_captures(noisy_camera, repeats):
    """Two captures of one scene corrected with one camera differ by their noise alone
    (the calibration's errors are common to both): ``z = Δ ln l / √(σ₁² + σ₂²)`` must be
    a standard normal variate: its spread is held to 1 ± 0.05 and its 68 % and 95 %
    intervals to 68 ± 2 % and 95 ± 1 % (12 288 × 3 independent values: binomial
    standard errors of 0.2 % and 0.1 %)."""
    cam, camera, scene, times = noisy_camera
    results = []
    for seed in (1, 2):
        capture = cam.capture(scene, times, repeats, rng=seed)
        stack = pq.ExposureStack(capture.frames, capture.exposure_s)
        results.append(pq.correct(stack, camera, uncertainty=True, refine_exposures=False))
    a, b = results
    expected = "estimated" if repeats > 1 else "camera's calibration (estimated)"
    assert a.noise.source == expected
    d = np.log(a.photoquantity.astype(float)) - np.log(b.photoquantity.astype(float))
    s = np.hypot(a.log_sigma_noise.astype(float), b.log_sigma_noise.astype(float))
    ok = np.isfinite(d) & np.isfinite(s)
    assert np.count_nonzero(ok) > 0.95 * ok.size
    z = d[ok] / s[ok]
    assert abs(z.std() - 1.0) < 0.05
    assert abs(np.mean(np.abs(z) < 1.959964) - 0.95) < 0.01
    assert abs(np.mean(np.abs(z) < 1.0) - 0.6827) < 0.02
    assert np.all(np.isnan(a.log_sigma_noise[a.mask]))


def test_bad_requests_are_named(noisy_camera):
    cam, camera, scene, times = noisy_camera
    capture = cam.capture(scene, times, 1, rng=5)
    stack = pq.ExposureStack(capture.frames, capture.exposure_s)
    with pytest.raises(InputError, match="'Debevec 1997' merge"):
        pq.correct(stack, camera, uncertainty=True, merge="Robertson 2003")
    with pytest.raises(InputError, match="`uncertainty` must be true, false or 'auto'"):
        pq.correct(stack, camera, uncertainty="yes")
    bare = dataclasses.replace(camera, parameters={**camera.parameters, "noise": None})
    with pytest.raises(InputError, match="no noise information"):
        pq.correct(stack, bare, uncertainty=True)
    assert pq.correct(stack, camera).log_sigma_noise is None


def test_auto_states_what_it_can_and_says_why_not(noisy_camera):
    """``uncertainty="auto"`` (the command's default): the same result as ``True`` where the
    uncertainty can be stated; where it cannot, the photoquantity without it and a note."""
    cam, camera, scene, times = noisy_camera
    capture = cam.capture(scene, times, 1, rng=5)
    stack = pq.ExposureStack(capture.frames, capture.exposure_s)
    auto = pq.correct(stack, camera, uncertainty="auto")
    full = pq.correct(stack, camera, uncertainty=True)
    np.testing.assert_array_equal(auto.log_sigma, full.log_sigma)
    np.testing.assert_array_equal(auto.photoquantity, full.photoquantity)
    other = pq.correct(stack, camera, uncertainty="auto", merge="Robertson 2003")
    assert other.log_sigma_noise is None
    assert any("no uncertainty" in n and "'Debevec 1997' merge" in n for n in other.notes)
    bare = dataclasses.replace(camera, parameters={**camera.parameters, "noise": None})
    quiet = pq.correct(stack, bare, uncertainty="auto")
    assert quiet.log_sigma is None
    assert any(n.startswith("no uncertainty: no noise information") for n in quiet.notes)
    np.testing.assert_array_equal(quiet.photoquantity, auto.photoquantity)


# ---------------------------------------------------------------------------
# one frame per exposure: the noise from neighbouring exposures
# ---------------------------------------------------------------------------

LINEAR_GAIN, LINEAR_READ = 0.05, 0.8  # DN per e⁻, DN


def _linear_capture(rate, times, seed):
    """One frame per exposure of a linear 8-bit camera: ``round(K·Poisson + N(0, σ_r))``."""
    rng = np.random.default_rng(seed)
    electrons = rng.poisson(rate[None] * np.asarray(times)[:, None, None, None])
    values = np.round(LINEAR_GAIN * electrons + rng.normal(0.0, LINEAR_READ, electrons.shape))
    frames = np.clip(values, 0, 255).astype(np.uint8)[None]
    return pq.ExposureStack(frames, np.asarray(times, dtype=float))


@pytest.fixture(scope="module")
def linear_bracket_camera():
    """A linear camera calibrated from one view of one frame per exposure, 4 stops."""
    rate = np.exp(np.random.default_rng(7).uniform(np.log(100.0), np.log(40_000.0), (128, 160, 3)))
    times = np.array([0.0625, 0.125, 0.25, 0.5, 1.0])
    camera = pq.calibrate([_linear_capture(rate, times, 1)])
    return camera, rate, times


def test_a_calibration_without_repeats_stores_the_noise_of_neighbouring_exposures(
    linear_bracket_camera,
):
    """The camera's gain and read noise from its view's neighbouring exposures (``N = 1``).

    Through the *recovered* response the pairs' differences also carry the response's own
    errors; read from the first percent of the range above black, where the response is
    least certain, they read as extra shot noise (the gain came out 20-40 % above the
    camera's 0.05 DN/e⁻ here). Above it (``photon_transfer_floor``) the gain lies
    within 3 standard errors of the camera's (seeds 1, 4, 5: within 1.5)."""
    camera, rate, times = linear_bracket_camera
    record = camera.parameters["noise"]
    assert record["source"] == "neighbouring exposures"
    gain = np.asarray(record["gain_dn_per_e"])
    fit = estimate_noise_from_exposures(_linear_capture(rate, times, 1), camera.response)
    np.testing.assert_allclose(gain, fit.gain, rtol=1e-12)
    se = np.sqrt(fit.covariance[:, 0, 0])
    assert np.all(np.abs(gain - LINEAR_GAIN) <= 3.0 * se), (gain, se)
    assert np.all(se < 0.1 * LINEAR_GAIN)  # informative


def test_a_scene_without_repeats_states_its_noise_through_the_cameras_record(
    linear_bracket_camera,
):
    """Two captures of one scene, one frame per exposure, corrected with that camera: the
    noise parts of their stated uncertainties explain their difference, to the precision of
    the gain (σ ∝ √K: 20 % on K is 10 % on σ, so the spread of z within 1 ± 0.15)."""
    camera, rate, times = linear_bracket_camera
    a, b = (pq.correct(_linear_capture(rate, times, s), camera, uncertainty=True) for s in (2, 3))
    assert a.noise.source == "camera's calibration (neighbouring exposures)"
    d = np.log(a.photoquantity.astype(float)) - np.log(b.photoquantity.astype(float))
    s = np.hypot(a.log_sigma_noise.astype(float), b.log_sigma_noise.astype(float))
    ok = np.isfinite(d) & np.isfinite(s) & (s > 0)
    assert np.count_nonzero(ok) > 0.9 * ok.size
    assert abs((d[ok] / s[ok]).std() - 1.0) < 0.15


def test_a_loosely_fixed_noise_is_not_stated():
    from photoquant.merge.noise_aware import MAX_GAIN_ERROR, PhotonTransferFit

    tight = np.array([[[1e-6, 0.0], [0.0, 1e-3]]] * 3)
    loose = tight.copy()
    loose[1, 0, 0] = (0.5 * 0.01) ** 2  # channel 1's gain known to 50 %
    gain, read = np.full(3, 0.01), np.array([0.25, -0.1, 0.0])
    params = PhotonTransferFit(gain, read, tight, []).noise_parameters(MAX_GAIN_ERROR)
    assert params is not None and params.source == "neighbouring exposures"
    np.testing.assert_array_equal(params.read_noise, [0.5, 0.0, 0.0])
    assert PhotonTransferFit(gain, read, loose, []).noise_parameters(MAX_GAIN_ERROR) is None
    assert PhotonTransferFit(gain, read, loose, []).noise_parameters() is not None


@given(
    st.sampled_from([np.uint8, np.uint16]),
    st.lists(st.floats(-3.0, 70000.0), min_size=3, max_size=3),
    st.lists(st.floats(-3.0, 70000.0), min_size=3, max_size=3),
    st.integers(0, 2**16 - 1),
)
@settings(max_examples=60, deadline=None)
def test_within_levels_is_the_float_comparison(dtype, low, high, seed):
    """The neighbouring-exposure fit's integer thresholds select the values the float
    comparison does, for fractional, integral and out-of-range levels."""
    from photoquant.merge.noise_aware import _within_levels

    top = np.iinfo(dtype).max
    frames = np.random.default_rng(seed).integers(0, top, (3, 5, 7, 3), endpoint=True)
    frames = frames.astype(dtype)[:, ::2, ::3]  # a grid view, as the fit reads it
    low = np.array(low) if seed % 2 else np.round(low)
    high = np.array(high) if seed % 3 else np.round(high)
    expected = (frames >= low) & (frames < high)
    np.testing.assert_array_equal(_within_levels(frames, low, high), expected)
