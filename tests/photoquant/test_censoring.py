"""Symmetric trimming of censored exposure pairs (Powell 1986), on analytic truth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from photoquant.response import camera_response_Debevec1997
from photoquant.response.censoring import trim_censored_partners
from photoquant.response.debevec1997 import DebevecResponseOptions

P = 20_000


def _pair(rng, k_value, mu, sigma, lo, hi, t=(1.0, 8.0)):
    """Pixels at one level ``k_value`` of exposure 0 with partners ~ N(mu, sigma) in exposure 1,
    censored (not valid) outside ``(lo, hi)``."""
    values = np.empty((2, P))
    values[0] = k_value
    values[1] = rng.normal(mu, sigma, P)
    valid = np.ones((2, P), dtype=bool)
    valid[1] = (values[1] > lo) & (values[1] < hi)
    return values, valid, np.asarray(t)


def test_trimming_removes_the_truncation_bias_of_a_clipped_longer_partner(rng):
    mu, sigma, clip = 240.0, 10.0, 250.0  # one σ below the clip: 15.9 % censored
    values, valid, t = _pair(rng, 100.0, mu, sigma, 0.0, clip)
    out = trim_censored_partners(values, valid, t)
    kept_before = values[1, valid[1]]
    kept_after = values[1, out[1]]
    # the untrimmed pairs are the truncated normal: mean μ − σ φ(1)/Φ(1) = μ − 2.88
    # (Tobin 1958); the trimmed ones the central ±1σ, symmetric about μ
    se = sigma / np.sqrt(kept_after.size)  # an upper bound of the trimmed mean's error
    assert kept_before.mean() < mu - 2.5  # the bias is there: the test can fail
    assert abs(kept_after.mean() - mu) < 5 * se
    assert abs(np.median(kept_after) - mu) < 5 * 1.25 * se
    # as many dropped from the bottom as were censored at the top
    assert kept_before.size - kept_after.size == P - kept_before.size
    # partners are ranked by level (one DN here): the kept ones start within one
    # level of the 15.9 % quantile, μ − σ
    assert kept_after.min() >= np.floor(mu - sigma) - 1
    # exposure 0 (the level's own values) is untouched
    np.testing.assert_array_equal(out[0], valid[0])


def test_a_dark_clipped_shorter_partner_is_trimmed_at_its_top(rng):
    mu, sigma = 8.0, 4.0
    values, valid, _ = _pair(rng, 150.0, mu, sigma, 4.0, 255.0)  # 15.9 % below 4 censored
    t = np.array([8.0, 1.0])  # the partner (exposure 1) is the shorter one
    out = trim_censored_partners(values, valid, t)
    kept = values[1, out[1]]
    assert values[1, valid[1]].mean() > mu + 1.0  # truncated from below: biased up
    assert abs(kept.mean() - mu) < 5 * sigma / np.sqrt(kept.size)
    assert kept.max() < np.ceil(mu + sigma) + 1  # within a level of the 84.1 % quantile


def test_a_level_with_half_its_partners_censored_keeps_none(rng):
    values, valid, t = _pair(rng, 100.0, 252.0, 10.0, 0.0, 250.0)  # 58 % censored
    out = trim_censored_partners(values, valid, t)
    assert not out[1].any()
    np.testing.assert_array_equal(out[0], valid[0])


def test_levels_without_censoring_are_unchanged(rng):
    # two levels: one whose partners clip, one whose partners never do
    a, va, t = _pair(rng, 100.0, 240.0, 10.0, 0.0, 250.0)
    b, vb, _ = _pair(rng, 50.0, 120.0, 10.0, 0.0, 250.0)
    values, valid = np.concatenate([a, b], axis=1), np.concatenate([va, vb], axis=1)
    assert vb.all()
    out = trim_censored_partners(values, valid, t)
    np.testing.assert_array_equal(out[:, P:], valid[:, P:])
    assert out[1, :P].sum() < va[1].sum()


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k_count=st.integers(2, 5),
    n_pix=st.integers(1, 300),
)
def test_trimming_only_removes_values_and_is_deterministic(seed, k_count, n_pix):
    rng = np.random.default_rng(seed)
    values = rng.uniform(0, 255, (k_count, n_pix))
    valid = rng.random((k_count, n_pix)) < 0.8
    t = np.geomspace(1.0, 2.0**k_count, k_count)
    out = trim_censored_partners(values, valid, t)
    assert out.shape == valid.shape and out.dtype == bool
    assert not np.any(out & ~valid)
    np.testing.assert_array_equal(out, trim_censored_partners(values, valid, t))
    # nothing censored: nothing changes
    np.testing.assert_array_equal(trim_censored_partners(values, np.ones_like(valid), t), True)


def test_bad_input_is_one_clear_error():
    with pytest.raises(InputError, match="shape"):
        trim_censored_partners(np.zeros((2, 5)), np.ones((2, 4), bool), np.array([1.0, 2.0]))
    with pytest.raises(InputError, match="spacing"):
        trim_censored_partners(np.zeros((2, 5)), np.ones((2, 5), bool), np.ones(2), spacing=0)
    with pytest.raises(InputError, match="censoring"):
        DebevecResponseOptions(censoring="tobit")
    with pytest.raises(InputError, match="censoring"):
        camera_response_Debevec1997(np.ones((2, 4, 4, 1)), [1.0, 2.0], censoring="x")


def test_pixels_with_three_usable_values_are_not_trimmed(rng):
    # the same clipped pair, with a third, shorter exposure usable everywhere: ln E_p
    # rests on two more values, so the pair no longer decides the pixel's entry
    values, valid, _ = _pair(rng, 100.0, 240.0, 10.0, 0.0, 250.0)
    values = np.concatenate([np.full((1, P), 12.5), values])
    valid = np.concatenate([np.ones((1, P), dtype=bool), valid])
    out = trim_censored_partners(values, valid, np.array([0.125, 1.0, 8.0]))
    np.testing.assert_array_equal(out, valid)
