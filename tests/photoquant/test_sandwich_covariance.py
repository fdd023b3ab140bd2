"""The pixel-clustered sandwich of the response fit against its dense definition."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from photoquant.response.covariance import cluster_sandwich_covariance


def _system(rng: np.random.Generator, n_levels: int, k: int, n_pix: int):
    """A reduced normal matrix ``S`` (SPD, of a spread of scales, as a smoothness prior and
    levels of little data make it) and the data rows of ``n_pix`` pixels at ``k`` exposures."""
    basis = rng.normal(size=(n_levels, 3 * n_levels)) * np.geomspace(1.0, 1e-3, 3 * n_levels)
    s = basis @ basis.T + 1e-6 * np.eye(n_levels)
    lo = rng.integers(0, n_levels - 1, size=(k, n_pix))
    idx = np.concatenate([lo, lo + 1])
    alpha = rng.uniform(size=(k, n_pix))
    used = rng.uniform(size=(k, n_pix)) < 0.7  # unused values: coefficients and residual 0
    w = np.where(used, rng.uniform(0.2, 1.0, size=(k, n_pix)), 0.0)
    coef = np.concatenate([w * (1 - alpha), w * alpha])
    residual = np.where(used, rng.normal(scale=0.02, size=(k, n_pix)), 0.0)
    return s, idx, coef, residual


def _dense_sandwich(s, idx, coef, residual):
    """``S⁻¹ M S⁻¹``, ``M = P/(P − 1) Σ_p s_p s_pᵀ`` with each pixel's score ``s_p`` summed
    into a dense vector: the definition, by explicit inverse-free solves."""
    n_levels, (k, n_pix) = s.shape[0], residual.shape
    scores = np.zeros((n_levels, n_pix))
    for r in range(2 * k):
        np.add.at(scores, (idx[r], np.arange(n_pix)), coef[r] * residual[r % k])
    meat = scores @ scores.T * (n_pix / (n_pix - 1))
    return np.linalg.solve(s, np.linalg.solve(s, meat).T)


@pytest.mark.parametrize(("seed", "lower"), [(0, True), (1, True), (2, False)])
def test_the_sandwich_is_its_dense_definition(seed, lower):
    rng = np.random.default_rng(seed)
    s, idx, coef, residual = _system(rng, n_levels=40, k=5, n_pix=300)
    cov = cluster_sandwich_covariance(
        scipy.linalg.cho_factor(s, lower=lower), idx, coef, residual, 40
    )
    dense = _dense_sandwich(s, idx, coef, residual)
    # both are backward stable to cond(S) ε; S's condition here is ~1e6
    np.testing.assert_allclose(cov, dense, rtol=0, atol=1e-8 * np.abs(dense).max())
    np.testing.assert_array_equal(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-12 * np.abs(dense).max())
