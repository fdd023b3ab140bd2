"""Vignetting fits with a free gain per view: exposure errors of the views beside the vignetting.

A view whose exposure scale is off by ``e_j`` has values ``e_j v l``. With
``view_gains`` the pair fit estimates ``a_j = e_0 / e_j`` with the vignetting
(Goldman & Chen 2005's joint exposure and vignetting estimation). Tolerances:
gains within 4 of their reported standard deviations, maps within 3 of their
reported first-order uncertainty (as the existing vignetting tests).
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.methods import options_from_mapping
from photoquant.vignetting import VIGNETTING_METHODS
from photoquant.vignetting._pairs import _Problem
from photoquant.vignetting.extended_goldman_chen import (
    _PairProblem,
    fit_vignetting_ExtendedGoldmanChen,
    normalised_coordinates,
)
from photoquant.vignetting.goldman_chen2005 import _pair_model
from tests.photoquant.test_vignetting import (
    DARKENING,
    IMAGE_SHAPE,
    PAN_AND_TILT,
    PAPER,
    map_relative_error,
    observe,
)
from tests.photoquant.test_vignetting_models import make_data, truth_maps

NOISE = 0.005  # relative noise per value
EXPOSURE_ERROR = np.array([1.0, 1.03, 0.975])  # e_j: view j's values are e_j times too bright


def _with_exposure_errors(obs):
    return obs.values * EXPOSURE_ERROR[obs.view][:, None]


def _fit(values, obs, **kwargs):
    if kwargs.get("view_gains"):
        kwargs.setdefault("view_gain_centre", "free")
    return fit_vignetting_ExtendedGoldmanChen(
        values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, **kwargs
    )


@pytest.fixture
def strong():
    """The paper's fitted vignetting (§6.3): curved enough for the gains to be determined."""
    return observe(PAPER, PAN_AND_TILT, 2000, np.random.default_rng(5), noise=NOISE)


def test_gains_and_vignetting_are_both_recovered(strong):
    fit = _fit(_with_exposure_errors(strong), strong, view_gains=True)
    assert fit.converged.all(), fit.message
    assert "view gains" in fit.message
    expected = EXPOSURE_ERROR[0] / EXPOSURE_ERROR
    err = fit.view_gains[0] - expected
    assert fit.view_gain_std[0, 0] == 0.0 and fit.view_gains[0, 0] == 1.0
    assert np.all(fit.view_gain_std[0, 1:] < 2e-3), fit.view_gain_std
    assert np.all(np.abs(err[1:]) < 4 * fit.view_gain_std[0, 1:]), (err, fit.view_gain_std)
    map_err = map_relative_error(fit.params, PAPER).mean()
    assert map_err < 3 * fit.map_uncertainty[0], (map_err, fit.map_uncertainty)
    # the same data without gains read the exposure errors as vignetting
    plain = _fit(_with_exposure_errors(strong), strong)
    assert map_relative_error(plain.params, PAPER).mean() > 10 * map_err


def test_exact_exposures_give_unit_gains_and_as_good_a_map(strong):
    with_gains = _fit(strong.values, strong, view_gains=True)
    without = _fit(strong.values, strong)
    assert with_gains.converged.all(), with_gains.message
    gains, std = with_gains.view_gains[0, 1:], with_gains.view_gain_std[0, 1:]
    assert np.all(np.abs(gains - 1) < 4 * std), (gains, std)
    e_with = map_relative_error(with_gains.params, PAPER).mean()
    e_without = map_relative_error(without.params, PAPER).mean()
    # two more parameters: the map is as good within its own uncertainty
    assert e_with < e_without + 3 * with_gains.map_uncertainty[0], (e_with, e_without)
    assert without.view_gains is None


def test_mild_vignette_free_gains_are_degenerate_and_flagged():
    """Views related by shifts cannot tell a view gain from a ramp of ``v``.

    ``v → v·exp(a·x)``, ``l → l·exp(−a·X)``, ``e_j → e_j·exp(a·d_j)`` leaves
    every value unchanged; a model with a free centre reproduces the ramp to
    second order by moving its centre, so for a mild, nearly quadratic
    vignette (pqsim's CCD preset) only the small higher-order terms hold the
    gains. The fit must say so, not return a wrong map as trusted.
    """
    obs = observe(DARKENING, PAN_AND_TILT, 2000, np.random.default_rng(5), noise=NOISE)
    fit = _fit(obs.values, obs, view_gains=True)
    if fit.converged[0]:
        assert map_relative_error(fit.params, DARKENING).mean() < 0.02, fit.message
    else:
        assert "NOT TRUSTWORTHY" in fit.message


def test_gains_held_at_the_image_centre_resolve_a_mild_vignette():
    """``view_gain_centre="image"``: gains from a vignetting centred on the image, then the
    full model with them held. The lens centre (0.52, 0.47) is off by δ ≈ 2–3 %, which
    biases the gains by about ``2 |m1| m4 δ·d`` ≈ 0.3 % for these 10 % shifts (module
    notes): gains within 0.6 %, map within 1 %, where without gains the 3 % exposure
    errors give a map error of several %."""
    obs = observe(DARKENING, PAN_AND_TILT, 2000, np.random.default_rng(5), noise=NOISE)
    values = _with_exposure_errors(obs)
    fit = fit_vignetting_ExtendedGoldmanChen(
        values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, view_gains=True
    )
    assert fit.converged.all(), fit.message
    expected = EXPOSURE_ERROR[0] / EXPOSURE_ERROR
    np.testing.assert_allclose(fit.view_gains[0], expected, atol=6e-3)
    map_err = map_relative_error(fit.params, DARKENING).mean()
    plain = fit_vignetting_ExtendedGoldmanChen(values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    assert map_err < 0.01
    assert map_relative_error(plain.params, DARKENING).mean() > 3 * map_err


def test_auto_view_gains_follow_the_exposure_scale_uncertainty(rng):
    """``view_gains="auto"``: gains only when the views' exposure scales are uncertain."""
    from photoquant.vignetting.base import AUTO_VIEW_GAIN_STD

    truth = truth_maps()["Extended Goldman-Chen"]
    data = make_data(truth, rng, n_tracks=600)
    entry = VIGNETTING_METHODS["Extended Goldman-Chen"]
    opts = options_from_mapping(entry, {"sample_radius": 0})
    assert opts.view_gains == "auto"
    for std, expect in ((None, False), (AUTO_VIEW_GAIN_STD / 10, False), (0.01, True)):
        d = type(data)(data.uniform_views, data.tracks, data.image_shape, exposure_scale_std=std)
        rep = entry.function(d, opts).report
        assert ("view_gains" in rep) is expect, (std, rep["message"])


def test_centred_model_determines_gains_of_a_mild_vignette(rng):
    """The Goldman–Chen 2005 model is centred: no ramp to trade for gains."""
    truth = truth_maps()["Goldman-Chen 2005"]
    data = make_data(truth, rng, n_tracks=1500)
    errors = np.array([1.0, 1.02, 0.985])
    data = type(data)(
        [v * e for v, e in zip(data.uniform_views, errors, strict=True)],
        data.tracks,
        data.image_shape,
    )
    entry = VIGNETTING_METHODS["Goldman-Chen 2005"]
    result = entry.function(
        data, options_from_mapping(entry, {"sample_radius": 0, "view_gains": True})
    )
    rep = result.report
    gains, std = np.asarray(rep["view_gains"]), np.asarray(rep["view_gain_std"])
    expected = errors[0] / errors
    assert np.all(np.abs(gains[:, 1:] - expected[1:]) < 4 * std[:, 1:] + 1e-12), (gains, std)
    np.testing.assert_allclose(rep["exposure_correction"], expected, atol=3e-3)
    v = result.model.map(IMAGE_SHAPE)
    mean_err = np.abs(v / truth - 1).mean(axis=(0, 1))
    assert np.all(mean_err < 3 * np.asarray(rep["map_uncertainty"])), (mean_err, rep)


@pytest.mark.parametrize("scale_invariant", [False, True])
def test_gain_jacobians_match_finite_differences(rng, scale_invariant):
    obs = observe(DARKENING, PAN_AND_TILT, 80, rng)
    _, track_index = np.unique(obs.track, return_inverse=True)
    sel = np.flatnonzero(np.bincount(track_index)[track_index] >= 2)[:60]
    a, b = sel[:-1], sel[1:]
    keep = obs.view[a] != obs.view[b]
    a, b = a[keep], b[keep]
    c = obs.values[:, 0]
    x_n, y_n = normalised_coordinates(obs.xy[:, 0], obs.xy[:, 1], IMAGE_SHAPE)
    ga, gb = obs.view[a], obs.view[b]
    egc = _PairProblem(x_n, y_n, a, b, c[a], c[b], 1.0 / c[a], scale_invariant, ga, gb, 2)
    gc = _Problem(
        _pair_model(IMAGE_SHAPE), x_n, y_n, a, b, c[a], c[b], 1.0 / c[a], scale_invariant, ga, gb, 2
    )
    for prob, p in (
        (egc, np.array([-0.3, 0.1, -0.2, 1.3, 0.45, 0.55, 1.04, 0.97])),
        (gc, np.array([-0.3, 0.05, -0.02, 1.04, 0.97])),
    ):
        step = 1e-6
        numeric = np.stack(
            [
                (prob.residuals(p + step * e) - prob.residuals(p - step * e)) / (2 * step)
                for e in np.eye(p.size)
            ],
            axis=1,
        )
        np.testing.assert_allclose(prob.jacobian(p), numeric, rtol=1e-6, atol=1e-8)


def test_residual_is_invariant_to_a_common_scale_of_the_gains(rng):
    """``(a_i c_a v_b − a_j c_b v_a) / √(a_i a_j)``: scaling every gain by κ changes nothing."""
    obs = observe(PAPER, PAN_AND_TILT, 80, rng, noise=NOISE)
    _, track_index = np.unique(obs.track, return_inverse=True)
    sel = np.flatnonzero(np.bincount(track_index)[track_index] >= 2)[:60]
    a, b = sel[:-1], sel[1:]
    keep = obs.view[a] != obs.view[b]
    a, b = a[keep], b[keep]
    c = obs.values[:, 0]
    x_n, y_n = normalised_coordinates(obs.xy[:, 0], obs.xy[:, 1], IMAGE_SHAPE)
    # views 1 and 2 only (gain indices 1, 2 of three: view 0 absent from these pairs)
    pairs = (obs.view[a] > 0) & (obs.view[b] > 0)
    a, b = a[pairs], b[pairs]
    prob = _PairProblem(x_n, y_n, a, b, c[a], c[b], 1.0 / c[a], True, obs.view[a], obs.view[b], 2)
    p = np.r_[PAPER, 1.03, 0.98]
    q = np.r_[PAPER, 1.03 * 1.7, 0.98 * 1.7]
    np.testing.assert_allclose(prob.residuals(q), prob.residuals(p), rtol=1e-12, atol=1e-15)


def test_a_tight_gain_prior_is_the_fit_without_gains(strong):
    values = _with_exposure_errors(strong)
    tight = _fit(values, strong, view_gains=True, view_gain_sigma=1e-6)
    plain = _fit(values, strong)
    np.testing.assert_allclose(tight.view_gains[0], 1.0, atol=1e-4)
    assert (
        np.abs(
            map_relative_error(tight.params, PAPER) - map_relative_error(plain.params, PAPER)
        ).max()
        < 2e-3
    )


def test_bad_view_gain_arguments(strong):
    with pytest.raises(InputError, match="view_gains"):
        _fit(strong.values, strong, view_gains="yes")
    with pytest.raises(InputError, match="view_gain_sigma"):
        _fit(strong.values, strong, view_gains=True, view_gain_sigma=-1.0)
    entry = VIGNETTING_METHODS["Extended Goldman-Chen"]
    with pytest.raises(InputError, match="view_gains"):
        options_from_mapping(entry, {"view_gains": 1})
