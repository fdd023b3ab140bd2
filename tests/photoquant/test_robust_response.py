"""Robust response fits: IRLS weights per band of levels (photoquant.response.robust)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from photoquant.errors import InputError
from photoquant.profiles import PROFILES
from photoquant.response.debevec1997 import (
    DebevecResponseOptions,
    camera_response_Debevec1997,
)
from photoquant.response.emor2004 import EMoRResponseOptions
from photoquant.response.robust import HUBER_K, TUKEY_C, robust_weights

from .analytic import capture, log_uniform_scene, true_g

# --------------------------------------------------------------------------- the weights


def test_huber_weights_follow_each_bands_own_noise():
    # band 0: scale 1; band 1: scale 10 (the MAD of ±1 and ±10 values, times 1.4826)
    r = np.array([1.0, -1.0, 1.0, -1.0, 8.0, 10.0, -10.0, 10.0, -10.0, 8.0])
    band = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 1])
    w = robust_weights(r, np.ones(10, bool), band)
    s0, s1 = 1.4826 * 1.0, 1.4826 * 10.0
    raw = np.array([1, 1, 1, 1, HUBER_K * s0 / 8.0, 1, 1, 1, 1, 1])
    np.testing.assert_allclose(w, raw / raw.mean(), rtol=1e-12)
    # the same residual of 8 is an outlier in the quiet band only
    assert w[4] < 0.3 * w[9]
    assert s1 > 8.0 / HUBER_K


def test_tukey_weights_reject_gross_outliers():
    r = np.array([0.5, -0.5, 0.5, -0.5, 100.0])
    w = robust_weights(r, np.ones(5, bool), np.zeros(5, int), loss="tukey")
    s = 1.4826 * 0.5
    u = 0.5 / (TUKEY_C * s)
    np.testing.assert_allclose(w[:4], w[0])
    assert w[4] / w[0] == pytest.approx(1e-6 / (1 - u**2) ** 2)


def test_unused_values_get_no_weight_and_an_exact_fit_keeps_full_weight():
    r = np.array([0.0, 0.0, 0.0, 5.0])
    used = np.array([True, True, True, False])
    w = robust_weights(r, used, np.zeros(4, int))
    assert w.tolist() == [1.0, 1.0, 1.0, 0.0]


def test_an_unknown_loss_is_named():
    with pytest.raises(InputError, match="unknown robust loss 'l1'"):
        robust_weights(np.ones(3), np.ones(3, bool), np.zeros(3, int), loss="l1")


@settings(max_examples=60, deadline=None)
@given(
    r=arrays(np.float64, 40, elements=st.floats(-1e3, 1e3, allow_subnormal=False)),
    band=arrays(np.int64, 40, elements=st.integers(0, 15)),
    factor=st.floats(1e-3, 1e3),
    loss=st.sampled_from(["huber", "tukey"]),
)
def test_weights_are_a_mean_one_and_scale_free(r, band, factor, loss):
    used = np.ones(40, bool)
    w = robust_weights(r, used, band, loss=loss)
    assert np.all(np.isfinite(w)) and np.all(w > 0)
    assert w.mean() == pytest.approx(1.0)
    # residuals in other units: the same weights (the scale is estimated)
    np.testing.assert_allclose(robust_weights(r * factor, used, band, loss=loss), w, rtol=1e-9)


# --------------------------------------------------------------------------- the fits

T = 2.0 ** np.arange(5) / 16


def _g_error(rec) -> float:
    """Worst channel's rms error of g over its measured levels below the shoulder (gauge removed)."""
    worst = 0.0
    for ch in range(3):
        levels = rec.levels[1:]
        keep = (levels >= rec.valid_min[ch]) & (levels < 0.95 * rec.saturation_level[ch])
        d = rec.log_inverse_response[ch, 1:][keep] - true_g(levels[keep], ch)
        worst = max(worst, float(np.sqrt(np.mean((d - d.mean()) ** 2))))
    return worst


def _brackets(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A gamma camera's bracket (1 DN of noise) and the same bracket with a quarter of
    its middle exposure taken of another scene (it moved)."""
    rng = np.random.default_rng(seed)
    clean = capture(log_uniform_scene(rng, (60, 80, 3)), T, noise_dn=1.0, rng=rng)
    other = capture(log_uniform_scene(rng, (60, 80, 3)), T, noise_dn=1.0, rng=rng)
    moved = clean.copy()
    moved[:, 2, :30, :40] = other[:, 2, :30, :40]
    return clean.mean(axis=0), moved.mean(axis=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_moved_scene_bends_least_squares_and_less_the_robust_fits(seed):
    clean, moved = _brackets(seed)
    fit = {
        loss: _g_error(camera_response_Debevec1997(moved, T, robust=loss, rng=0))
        for loss in ("none", "huber", "tukey")
    }
    floor = _g_error(camera_response_Debevec1997(clean, T, robust="none", rng=0))
    # least squares is pulled far beyond its clean-data error by 5 % of the values
    assert fit["none"] > 4 * floor
    # Huber's loss bounds the pull; the biweight removes it (within 1.5x the clean error,
    # the loss of efficiency of a 95 %-efficient estimator on 60x80 pixels plus the
    # pixels the moved patch takes away)
    assert fit["huber"] < 0.8 * fit["none"]
    assert fit["tukey"] < 1.5 * floor
    assert fit["tukey"] < 0.5 * fit["huber"]


def test_without_outliers_huber_keeps_least_squares_accuracy():
    # every candidate sampled: the loss is under test, not the sampling
    clean, _ = _brackets(2)
    ls = _g_error(camera_response_Debevec1997(clean, T, robust="none", rng=0, edges="kept"))
    hub = _g_error(camera_response_Debevec1997(clean, T, robust="huber", rng=0, edges="kept"))
    # 95 % efficiency: the standard error grows by 1/sqrt(0.95) = 1.03; a margin for the
    # estimate's own scatter between two fits of one sample
    assert hub < 1.15 * ls


def test_least_squares_is_one_solve_of_eq7():
    clean, _ = _brackets(3)
    once = camera_response_Debevec1997(clean, T, robust="none", rng=0)
    # rounds only matter with a robust loss
    again = camera_response_Debevec1997(clean, T, robust="none", robust_rounds=7, rng=0)
    np.testing.assert_array_equal(once.log_inverse_response, again.log_inverse_response)
    robust = camera_response_Debevec1997(clean, T, robust="huber", rng=0)
    assert not np.array_equal(once.log_inverse_response, robust.log_inverse_response)


def test_the_robust_fit_is_deterministic():
    _, moved = _brackets(4)
    a = camera_response_Debevec1997(moved, T, robust="tukey", rng=5)
    b = camera_response_Debevec1997(moved, T, robust="tukey", rng=5)
    np.testing.assert_array_equal(a.log_inverse_response, b.log_inverse_response)


def test_profiles_paper_keeps_least_squares_and_photoquant_is_robust():
    assert PROFILES["paper"]["response"][1]["robust"] == "none"
    assert DebevecResponseOptions().robust == "huber"
    assert EMoRResponseOptions().robust == "none"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"robust": "l1"}, "unknown `robust` loss 'l1'"),
        ({"robust_rounds": 0}, "`robust_rounds` must be an integer from 1 to 50"),
        ({"robust_rounds": 2.5}, "`robust_rounds` must be an integer from 1 to 50"),
    ],
)
def test_bad_robust_options_are_named(options, message):
    with pytest.raises(InputError, match=message):
        DebevecResponseOptions(**options)


def test_emor_robust_options_are_checked():
    with pytest.raises(InputError, match="unknown EMoR robust loss"):
        EMoRResponseOptions(robust="l2")
    with pytest.raises(InputError, match="unknown EMoR objective 'log-ratio'; valid: values"):
        EMoRResponseOptions(robust="huber", objective="log-ratio")


def test_a_robust_emor_fit_resists_a_moved_scene():
    """A camera whose response is the EMoR mean ``f0`` (in the model's space), one
    exposure a quarter taken of another scene: the values fit's ``g`` error in the
    mid-range, least squares against Huber's and the biweight."""
    from photoquant._emor_data import emor_basis
    from photoquant.response.emor2004 import characterise_response_EMoR2004
    from photoquant.stack import ExposureStack

    e, f0, _ = emor_basis()
    rng = np.random.default_rng(0)

    def shoot(scene: np.ndarray) -> np.ndarray:
        x = np.clip(scene[None] * T[:, None, None, None], 0.0, 1.0)
        return 255.0 * np.interp(x, e, f0) + rng.normal(0.0, 1.0, x.shape)

    frames = shoot(log_uniform_scene(rng, (60, 80, 3)))
    frames[2, :30, :40] = shoot(log_uniform_scene(rng, (60, 80, 3)))[2, :30, :40]
    stack = ExposureStack(np.clip(np.round(frames), 0, 255)[None].astype(np.uint8), T)
    mid = np.arange(40, 221)
    g_true = np.log(np.interp(mid / 255.0, f0, e))

    def error(loss: str) -> float:
        model = characterise_response_EMoR2004(stack, EMoRResponseOptions(robust=loss)).model
        worst = 0.0
        for ch in range(3):
            d = np.interp(mid, model.levels, model.log_inverse_response[ch]) - g_true
            worst = max(worst, float(np.sqrt(np.mean((d - d.mean()) ** 2))))
        return worst

    none, huber, tukey = error("none"), error("huber"), error("tukey")
    assert huber < 0.8 * none
    assert tukey < 0.5 * none


def test_bands_are_even_in_log_level_above_black():
    from photoquant.response.debevec1997 import _log_bands

    knots = np.arange(256.0)
    band = _log_bands(knots, 0.0, 255)
    assert band[0] == 0 and band[255] == 15 and np.all(np.diff(band) >= 0)
    # the darkest levels each in a band of their own; the top octave shares one or two
    assert len(set(band[1:4].tolist())) == 3
    assert band[128] >= 14
    # below the black level: the first band
    assert np.all(_log_bands(np.array([0.0, 5.0, 16.0]), 16.0, 255) == 0)
