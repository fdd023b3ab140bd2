"""Simulate → calibrate → correct → compare with the truth (numpy synthetic camera).

The capture follows the paper's calibration settings (§6.1: 1–200 ms, K = 8,
N = 10, V = 3) at a small image size; scenes are corrected with N = 4. Every
tolerance is derived from the camera's physics (``validation.noise_model``)
or from the method's stated budget, never from what happened to pass.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoquant.calibration import calibrate_manifest
from photoquant.correction import correct, correct_manifest
from photoquant.weighting import weighting_hat_Debevec1997
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.metrics import (
    channel_scale_ratios,
    map_relative_error,
    relative_error_eq8,
    response_error,
)
from validation.noise_model import (
    predicted_log_error,
    predicted_log_variance,
    predicted_relative_error,
)
from validation.truth_model import camera_model_from_truth

SHAPE = (72, 96)


@pytest.fixture(scope="module", params=["ccd", "cmos"])
def calibrated(request, tmp_path_factory):
    camera = camera_from_preset(request.param)
    folder = tmp_path_factory.mktemp(f"capture_{request.param}")
    manifest = write_capture_set(folder / "cap", camera, shape=SHAPE, n_repeats=10, seed=1)
    truth = load_truth(folder / "cap" / "truth")
    model = calibrate_manifest(manifest)
    return camera, manifest, truth, model


def test_response_matches_truth(calibrated):
    _, _, truth, model = calibrated
    for ch in range(3):
        levels = model.response.levels
        w = weighting_hat_Debevec1997(levels, 0, model.response.saturation_level[ch])
        g_true = truth.camera.inverse_response_ln(levels, ch)
        rms, _ = response_error(
            model.response.log_inverse_response[ch], g_true, np.where(w >= 0.05, w, 0)
        )
        # an error δ in g is a relative error δ in every photoquantity merged
        # from that level: the method's 0.5 % budget bounds it
        assert rms < 0.005, (ch, rms)
    np.testing.assert_array_equal(model.response.saturation_level, truth.camera.saturation_dn)


def test_balance_within_one_percent(calibrated):
    camera, _, truth, model = calibrated
    view = truth.captures["view0"]
    stack = camera.capture(view.l, view.exposure_s, 10, rng=11).to_stack()
    res = correct(stack, model)
    # the analytic world's white chart is neutral: a balanced camera measures l
    ratios = channel_scale_ratios(view.l, res.photoquantity, res.mask)
    assert np.all(np.abs(ratios - 1) < 0.01), ratios


def test_sensor_lut_below_the_prnu_floor_and_at_its_noise(calibrated):
    _, _, truth, model = calibrated
    u_true = truth.camera.sensor_lut
    err = np.abs(model.sensor_lut.lut - u_true) / u_true
    prnu_floor = np.mean(np.abs(u_true - 1))  # the error of assuming u = 1
    assert err.mean() < prnu_floor
    # the LUT is a merged irradiance image: its error is that image's noise,
    # E|ε| = sqrt(2/π)·σ for Gaussian ε; allow 25 % for the first-order model
    irr = truth.captures["irradiance"]
    var = predicted_log_variance(truth.camera, irr.l, irr.exposure_s, irr.n_repeats, gain=u_true)
    expected = np.sqrt(2 / np.pi) * np.sqrt(var).mean()
    assert err.mean() < 1.25 * expected, (err.mean(), expected)


def test_vignetting_map_within_one_percent(calibrated):
    _, _, truth, model = calibrated
    stats = map_relative_error(truth.camera.vignetting, model.vignetting_map())
    assert stats.e_mean < 0.01, stats
    assert model.report["vignetting"]["n_tracks"] >= 100


def _noise_floor(truth, capture, n, l=None, exposure_s=None):
    """Expected eq. 8 error of a perfectly calibrated camera: noise and dark current."""
    l = capture.l if l is None else l
    t = capture.exposure_s if exposure_s is None else exposure_s
    bias, var = predicted_log_error(truth.camera, l, t, n)
    return predicted_relative_error(l, var, np.random.default_rng(0), log_bias=bias)


# The prediction is first order and treats quantisation as dithered noise; on
# this 8-bit camera it may miss the true-model error by up to ~15 %.
MODEL_SLACK = 1.15
# What calibration may add to the mean error: the method's 0.5 % budget
# (paper §6.3), for its estimated g, balance, LUT and vignetting together.
CALIBRATION_BUDGET = 0.005


@pytest.mark.parametrize("n", [1, 4])
def test_merge_noise_follows_the_noise_model(calibrated, n):
    """Appendix A: with a perfect calibration, the error is the frames' noise."""
    camera, _, truth, _ = calibrated
    view = truth.captures["view0"]
    true_model = camera_model_from_truth(truth.camera)
    res = correct(camera.capture(view.l, view.exposure_s, n, rng=21).to_stack(), true_model)
    e, stats, _ = relative_error_eq8(view.l, res.photoquantity, res.mask, fit_scale=False)
    pred = _noise_floor(truth, view, n)
    ok = np.isfinite(pred) & np.isfinite(e)
    assert e[ok].mean() == pytest.approx(pred[ok].mean(), rel=MODEL_SLACK - 1)


def test_noise_falls_as_one_over_sqrt_n(calibrated):
    """Appendix A: σ(c̄) ∝ 1/√N, so the noise-limited error halves from N = 1 to 4."""
    camera, _, truth, _ = calibrated
    view = truth.captures["view0"]
    true_model = camera_model_from_truth(truth.camera)
    errs = {}
    for n in (1, 4):
        res = correct(camera.capture(view.l, view.exposure_s, n, rng=41).to_stack(), true_model)
        e, _, _ = relative_error_eq8(view.l, res.photoquantity, res.mask, fit_scale=False)
        errs[n] = np.nanmean(e)
    # quantisation (not reduced when the noise is below a DN) keeps it above 1/2
    assert 0.45 < errs[4] / errs[1] < 0.6


@pytest.mark.parametrize("scene", ["view0", "scene"])
def test_photoquantity_error_at_n4(calibrated, scene):
    """§6.3: correct an N = 4 capture; the error is the noise floor plus the calibration budget."""
    camera, _, truth, model = calibrated
    cap = truth.captures[scene]
    res = correct(camera.capture(cap.l, cap.exposure_s, 4, rng=31).to_stack(), model)
    e, stats, _ = relative_error_eq8(cap.l, res.photoquantity, res.mask)
    pred = _noise_floor(truth, cap, 4)
    ok = np.isfinite(e) & np.isfinite(pred)
    assert ok.mean() > 0.95, "few pixels may be flagged, not many"
    assert e[ok].mean() < MODEL_SLACK * pred[ok].mean() + CALIBRATION_BUDGET


def test_paper_noise_claim_on_a_ccd_and_a_moderate_scene(calibrated):
    """§6.3: "N = 4 was sufficient to obtain e_mean < 0.5 %", on the paper's kind of
    camera (a CCD) and scene ("not very contrasted", §6.4: here one decade)."""
    camera, _, truth, model = calibrated
    if truth.camera.responses[0].kind != "linear":
        pytest.skip("the claim is about the paper's CCD; the cmos preset's noise floor is higher")
    rng = np.random.default_rng(5)
    l = 10 ** np.kron(rng.uniform(-1, 0, (6, 8, 3)), np.ones((SHAPE[0] // 6, SHAPE[1] // 8, 1)))
    t = truth.captures["view0"].exposure_s
    res = correct(camera.capture(l, t, 4, rng=6).to_stack(), model)
    e, stats, _ = relative_error_eq8(l, res.photoquantity, res.mask)
    floor = _noise_floor(truth, None, 4, l=l, exposure_s=t)
    assert floor.mean() < 0.004  # the physics leaves room for the claim ...
    assert stats.e_mean < 0.005  # ... and the calibrated pipeline meets it


def test_correct_manifest_flags_instead_of_guessing(calibrated):
    _, manifest, truth, model = calibrated
    res = correct_manifest(manifest, model)
    assert res.photoquantity.dtype == np.float32
    assert np.isnan(res.photoquantity[res.mask]).all()
    assert np.isfinite(res.photoquantity[~res.mask]).all()
    assert (res.mask == (res.all_saturated | res.all_dark)).all()


@settings(
    max_examples=6,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(seed=st.integers(0, 2**31 - 1), decades=st.floats(0.5, 2.0))
def test_correct_of_capture_is_l_up_to_scale(calibrated, seed, decades):
    """``correct(capture(l)) ≈ l`` up to one scale, within the noise bound."""
    camera, _, truth, model = calibrated
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(-decades, 0, (6, 8, 3))
    l = 10 ** np.kron(coarse, np.ones((SHAPE[0] // 6, SHAPE[1] // 8, 1)))
    t = truth.captures["view0"].exposure_s
    res = correct(camera.capture(l, t, 4, rng=rng).to_stack(), model)
    e, stats, _ = relative_error_eq8(l, res.photoquantity, res.mask)
    pred = _noise_floor(truth, None, 4, l=l, exposure_s=t)
    ok = np.isfinite(e) & np.isfinite(pred)
    assert ok.mean() > 0.95
    assert e[ok].mean() < MODEL_SLACK * pred[ok].mean() + CALIBRATION_BUDGET


def test_correspondences_are_found_automatically_without_the_manifest_tracks(tmp_path):
    """§5.5: without given tracks, SIFT + RANSAC homographies find them; the count is reported."""
    import json

    manifest = write_capture_set(
        tmp_path / "cap", camera_from_preset("ccd"), shape=(192, 256), n_repeats=4, seed=2
    )
    data = json.loads(manifest.read_text())
    del data["correspondences"]
    (tmp_path / "cap" / "no_tracks.json").write_text(json.dumps(data))
    model = calibrate_manifest(tmp_path / "cap" / "no_tracks.json")
    vig = model.report["vignetting"]
    assert vig["correspondence_source"].startswith("automatic")
    assert vig["n_tracks"] >= 100
    truth = load_truth(tmp_path / "cap" / "truth")
    assert map_relative_error(truth.camera.vignetting, model.vignetting_map()).e_mean < 0.01
