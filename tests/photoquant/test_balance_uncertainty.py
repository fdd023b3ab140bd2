"""The balance factors' stated uncertainty against their actual scatter over noise draws.

A white chart of known colour is drawn many times with fresh noise; the
factors ``a_λ`` measured from each draw scatter by some amount, and the
variance each draw states (:func:`photoquant.balance.balance_log_variance`)
must match it. With ``S`` draws the scatter's standard deviation is known to
``1/√(2(S − 1))`` relative (Gaussian); the bands are four of those plus the
few per cent the tiles' median approximations may leave.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import uniform_filter

from photoquant.balance import (
    BalanceData,
    BalanceModel,
    balance_log_variance,
    characterise_balance_WhiteChart,
    colour_balance_WhiteChart,
)
from photoquant.errors import InputError

DRAWS = 300
WHITE = np.log(np.array([0.6, 0.9, 0.75]))


def _chart(rng, shape=(64, 64), sigma=0.05, smooth=1, shading=None):
    noise = rng.normal(0.0, sigma, (*shape, 3))
    if smooth > 1:  # neighbouring pixels correlated (a demosaiced or filtered image)
        noise = uniform_filter(noise, size=(smooth, smooth, 1), mode="reflect") * smooth
    log = WHITE + noise
    if shading is not None:
        log = log + shading[..., None]
    return np.exp(log)


def _scatter_and_stated(roi_shape=(64, 64), **kwargs):
    rng = np.random.default_rng(7)
    roi = [0, 0, roi_shape[1], roi_shape[0]]
    logs, stated = [], []
    for _ in range(DRAWS):
        chart = _chart(rng, roi_shape, **kwargs)
        logs.append(np.log(colour_balance_WhiteChart(chart, roi)))
        stated.append(balance_log_variance(chart, roi))
    scatter = np.std(np.array(logs), axis=0, ddof=1)
    return scatter, np.sqrt(np.mean(np.array(stated), axis=0))


BAND = 4.0 / np.sqrt(2 * (DRAWS - 1)) + 0.05


@pytest.mark.parametrize(
    ("case", "kwargs"),
    [
        ("independent pixels", {}),
        ("correlated neighbours", {"smooth": 3}),
        ("a small chart: single pixels", {"roi_shape": (6, 6)}),
    ],
)
def test_the_stated_uncertainty_is_the_scatter_over_noise_draws(case, kwargs):
    scatter, stated = _scatter_and_stated(**kwargs)
    assert stated[1] == 0.0 and scatter[1] == 0.0  # green: the reference, 1 by definition
    ratio = stated[[0, 2]] / scatter[[0, 2]]
    assert np.all(np.abs(ratio - 1.0) < BAND), (case, ratio)


def test_correlated_noise_is_not_read_as_independent_pixels():
    """The per-pixel formula (π/2 · var/n) would state a third of the actual scatter
    of a chart whose noise is smoothed over 3 × 3 pixels; the tiles see it."""
    scatter, stated = _scatter_and_stated(smooth=3)
    rng = np.random.default_rng(7)
    chart = _chart(rng, smooth=3)
    d = np.log(chart[..., 1]) - np.log(chart[..., 0])
    per_pixel = np.sqrt(np.pi / 2 * d.var() / d.size)
    assert per_pixel < 0.5 * scatter[0] < stated[0]


def test_light_shading_common_to_the_channels_cancels():
    """A chart lit unevenly (the same in every channel) changes no ratio: the stated
    uncertainty is the noise's alone, as without the shading."""
    y, x = np.mgrid[0:64, 0:64]
    shading = 0.3 * (x / 63.0) + 0.2 * np.sin(y / 9.0)
    scatter, stated = _scatter_and_stated(shading=shading)
    _, plain = _scatter_and_stated()
    assert np.all(np.abs(stated[[0, 2]] / plain[[0, 2]] - 1.0) < 0.1)
    assert np.all(np.abs(stated[[0, 2]] / scatter[[0, 2]] - 1.0) < BAND)


def test_a_monochrome_chart_and_the_reference_channel_state_zero():
    rng = np.random.default_rng(1)
    mono = _chart(rng)[..., :1]
    assert balance_log_variance(mono, [0, 0, 64, 64]).tolist() == [0.0]
    v = balance_log_variance(_chart(rng), [0, 0, 64, 64], reference_channel=0)
    assert v[0] == 0.0 and np.all(v[1:] > 0)
    with pytest.raises(InputError, match="reference channel 5"):
        balance_log_variance(_chart(rng), [0, 0, 64, 64], reference_channel=5)


def test_a_masked_chart_states_nan_and_the_model_none():
    rng = np.random.default_rng(2)
    chart = _chart(rng, (16, 16))
    mask = np.zeros(chart.shape, bool)
    mask[..., 2] = True
    mask[0, 0, 2] = False  # one valid blue pixel: a factor, but no scatter to state
    v = balance_log_variance(chart, [0, 0, 16, 16], mask)
    assert np.isnan(v[2]) and np.isfinite(v[0])
    fit = characterise_balance_WhiteChart(BalanceData(chart, chart, (0, 0, 16, 16), mask))
    assert fit.model.log_variance is None and "log_std" not in fit.report


def test_the_model_keeps_its_variance_through_its_params():
    rng = np.random.default_rng(3)
    chart = _chart(rng)
    fit = characterise_balance_WhiteChart(
        BalanceData(chart, chart, (0, 0, 64, 64), np.zeros(chart.shape, bool))
    )
    params, images = fit.model.to_params()
    back = BalanceModel.from_params("White Chart", params, images)
    np.testing.assert_array_equal(back.log_variance, fit.model.log_variance)
    np.testing.assert_allclose(fit.report["log_std"], np.sqrt(fit.model.log_variance))
    old = {"factors": params["factors"], "method_params": {}}  # a camera written before
    assert BalanceModel.from_params("White Chart", old, {}).log_variance is None
    with pytest.raises(InputError, match="log_variance"):
        BalanceModel.from_params("White Chart", {**params, "log_variance": "big"}, {})
    with pytest.raises(InputError, match="non-negative"):
        BalanceModel("White Chart", np.ones(3), log_variance=np.array([0.0, -1.0, 0.0]))


def test_correct_states_the_balance_part_of_the_calibration_uncertainty(tmp_path):
    """Through a simulated camera: the balance's variance travels in the camera's files
    and enters the correction's calibration component, one value per channel."""
    import photoquant as pq
    from photoquant.io import load_manifest, load_stack
    from photoquant.model import load_camera
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    manifest = write_capture_set(
        tmp_path / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=5
    )
    model = pq.calibrate_manifest(manifest)
    variance = model.balance.log_variance
    assert variance is not None and variance[1] == 0.0 and np.all(variance[[0, 2]] > 0)
    model.save(tmp_path / "cam")
    model = load_camera(tmp_path / "cam")
    np.testing.assert_array_equal(model.balance.log_variance, variance)
    loaded = load_manifest(manifest)
    result = pq.correct(load_stack(loaded.scene, loaded), model, uncertainty=True)
    ok = ~result.mask
    for ch in range(3):
        part = result.log_sigma_balance[..., ch][ok[..., ch]]
        np.testing.assert_allclose(part, np.sqrt(variance[ch]), rtol=1e-6)
    others = np.sqrt(
        result.log_sigma_response**2
        + result.log_sigma_sensor_lut**2
        + result.log_sigma_vignetting**2
    )
    np.testing.assert_allclose(
        result.log_sigma_calibration[ok],
        np.sqrt(others**2 + result.log_sigma_balance**2)[ok],
        rtol=1e-5,
    )
