"""The coverage experiment: the calibrated parameters' stated uncertainty over seeds."""

from __future__ import annotations

import numpy as np
import pytest

from validation.config import QUICK, TINY, ValidationError
from validation.experiments import _select
from validation.experiments.coverage import run, summary


def test_summary_of_standard_normal_values_is_in_its_band():
    z = np.random.default_rng(0).standard_normal(40_000)
    stats = summary(z, z.size)
    assert stats["spread"] == pytest.approx(1.0, abs=0.02)
    assert stats["within_68"] == pytest.approx(0.683, abs=0.01)
    assert stats["in_band"] == 1.0
    # an uncertainty stated at 70 % of the actual scatter is outside it
    assert summary(z / 0.7, z.size)["in_band"] == 0.0
    assert summary(np.empty(0), 0) == {}


def test_it_runs_in_the_full_job_and_when_named_only():
    assert "coverage" not in _select(None, QUICK)
    assert "coverage" in _select(None, QUICK.replace(coverage_seeds=50))
    assert _select(["coverage"], QUICK) == ["coverage"]
    assert "coverage_seeds" not in QUICK.conditions()  # reported, never checked
    with pytest.raises(ValidationError, match="coverage_seeds"):
        QUICK.replace(coverage_seeds=-1)


def test_the_sensor_luts_stated_noise_covers_its_error_over_seeds(tmp_path):
    """Three capture sets per preset: the LUT's ~27 000 per-pixel z have a spread within
    5 % of 1 (its sampling error ~0.5 %; measured 0.99 / 1.02 over 20 seeds); every
    parameter gets its row and metrics, the balance a second one with the jackknife."""
    config = TINY.replace(coverage_seeds=3)
    res = run(config, 0, tmp_path)
    for preset in config.presets:
        assert abs(res.metrics[f"coverage.{preset}.lut.spread"] - 1.0) < 0.05
        assert res.metrics[f"coverage.{preset}.vignetting.spread"] > 0
        # g refined in the values, its noise bias gone: either statement of g's error holds
        # for the balance (these 3 seeds: the sandwich's spread 0.45 / 0.71 on ccd / cmos,
        # the jackknife's 0.41 / 0.86; with eq. 7's g the sandwich's cmos spread is 3.9).
        # Six values a preset know a spread to about ±30 %: neither may understate by half
        for key in ("balance", "balance_jackknife"):
            assert 0 < res.metrics[f"coverage.{preset}.{key}.spread"] < 1.5
    assert len(res.rows) == 4 * len(config.presets)
    assert "3 capture sets per preset" in res.notes[0]
