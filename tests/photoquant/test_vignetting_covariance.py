"""The vignetting fit's stated covariance: checked against repeated noisy fits, propagated
to the map, stored in the camera.

Analytic tracks (three views, 400 points, 0.5 % independent noise per value, 40
seeds): the track-clustered sandwich states the maps' scatter to 1.03 (the
textbook ``σ² (JᵀJ)⁺``, which treats a track's pairs as independent, to 1.24),
and against the truth ``z`` has a spread of 1.02, 67 % within 1σ and 94 %
within 1.96σ.
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.vignetting.extended_goldman_chen import (
    ExtendedGoldmanChenVignetting,
    fit_vignetting_ExtendedGoldmanChen,
    vignetting_map,
)

from .test_vignetting import DARKENING, IMAGE_SHAPE, PAN_AND_TILT, observe

GRID = (slice(None, None, 20), slice(None, None, 20), 0)


@pytest.fixture(scope="module")
def repeated():
    maps, variances = [], []
    for seed in range(40):
        obs = observe(DARKENING, PAN_AND_TILT, 400, np.random.default_rng(seed), noise=0.005)
        fit = fit_vignetting_ExtendedGoldmanChen(
            obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE
        )
        assert fit.converged.all(), fit.message
        model = ExtendedGoldmanChenVignetting("fit", fit.params, fit.param_covariance)
        maps.append(np.log(model.map(IMAGE_SHAPE))[GRID])
        variances.append(model.log_map_variance(IMAGE_SHAPE)[GRID])
    return np.array(maps), np.array(variances)


def test_stated_map_uncertainty_matches_the_scatter_of_repeated_fits(repeated):
    maps, variances = repeated
    ratio = np.sqrt(np.sum(maps.var(axis=0, ddof=1)) / np.sum(variances.mean(axis=0)))
    # 40 fits: a variance is known to ±22 % (√(2/39)), its square root to ±11 %, pooled
    # over the grid a little better (the grid's points are correlated)
    assert abs(ratio - 1.0) < 0.2, ratio


def test_stated_map_uncertainty_covers_the_truth(repeated):
    maps, variances = repeated
    truth = np.log(vignetting_map(DARKENING, IMAGE_SHAPE))[GRID]
    ok = variances > 1e-14  # the centre: v = 1 by the model's form
    z = ((maps - truth) / np.sqrt(np.where(ok, variances, 1.0)))[ok]
    assert abs(z.std() - 1.0) < 0.15, z.std()
    assert 0.62 < np.mean(np.abs(z) < 1.0) < 0.74
    assert 0.91 < np.mean(np.abs(z) < 1.96) < 0.98


def test_map_variance_is_the_linearised_parameter_covariance():
    rng = np.random.default_rng(0)
    root = rng.normal(scale=1e-3, size=(6, 6))
    cov = (root @ root.T)[None]
    model = ExtendedGoldmanChenVignetting("given", DARKENING[None], cov)
    got = model.log_map_variance(IMAGE_SHAPE)[..., 0]
    # the same by finite differences of ln v along the parameters
    step = 1e-6
    grads = np.stack(
        [
            (
                np.log(vignetting_map(DARKENING + step * e, IMAGE_SHAPE))
                - np.log(vignetting_map(DARKENING - step * e, IMAGE_SHAPE))
            )[..., 0]
            / (2 * step)
            for e in np.eye(6)
        ],
        axis=-1,
    )
    expected = np.einsum("hwi,ij,hwj->hw", grads, cov[0], grads)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-14)


def test_covariance_persisted_and_checked():
    cov = np.tile(np.eye(6) * 1e-6, (2, 1, 1))
    model = ExtendedGoldmanChenVignetting("given", np.tile(DARKENING, (2, 1)), cov)
    params, images = model.to_params()
    back = ExtendedGoldmanChenVignetting.from_params("given", params, images)
    np.testing.assert_array_equal(back.param_covariance, cov)
    del params["param_covariance"]
    old = ExtendedGoldmanChenVignetting.from_params("given", params, images)
    assert old.param_covariance is None and old.log_map_variance(IMAGE_SHAPE) is None
    with pytest.raises(InputError, match="param_covariance"):
        ExtendedGoldmanChenVignetting("given", DARKENING[None], cov)  # 2 channels for 1
    with pytest.raises(InputError, match="non-negative"):
        ExtendedGoldmanChenVignetting("given", DARKENING[None], -cov[:1])
