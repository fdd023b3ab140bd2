"""photoquant.vignetting.trust: a vignetting fit whose residuals the model cannot explain is flagged."""

from __future__ import annotations

import dataclasses

import numpy as np

from photoquant.vignetting import VIGNETTING_METHODS
from photoquant.vignetting.trust import RESIDUAL_WARN_RMS, residual_warnings
from pqsim.synth_camera.optics import vignetting_extended_goldman_chen
from tests.photoquant.test_vignetting_models import EGC_PARAMS, IMAGE_SHAPE, make_data


def test_residual_warnings_name_each_channel_over_the_limit():
    assert residual_warnings([0.003, 0.019, 0.02]) == []
    notes = residual_warnings([0.003, 0.052, 0.1], [0.001, 0.0017, np.nan], ["R", "G", "B"])
    assert len(notes) == 2
    assert notes[0].startswith("vignetting channel G: pair residuals 5.2% rms (more than 2%)")
    assert "0.17% is a lower bound" in notes[0]
    assert notes[1].startswith("vignetting channel B") and "lower bound" not in notes[1]
    assert residual_warnings([np.nan]) != []  # a non-finite residual is no reassurance


def _fit(data):
    entry = VIGNETTING_METHODS["Extended Goldman-Chen"]
    return entry.function(data, entry.options(sample_radius=0))


def test_fit_with_values_off_eq1_is_flagged():
    """Block errors of each view, as compression leaves them, are flagged; eq. 1's data are not.

    Every 8×8 block of every view is off by a factor ``1 + 0.04 z`` (``z``
    standard normal, a block's own): a point's values in two views carry
    independent errors, pair residuals of about ``0.04 · √2 ≈ 5.7 %`` rms,
    which no vignetting explains. The same views with only their 0.5 %
    pixel noise give pair residuals of ~0.7 % (√2 × 0.5 %), within the limit.
    """
    rng = np.random.default_rng(3)
    truth = vignetting_extended_goldman_chen(np.tile(EGC_PARAMS, (3, 1)), IMAGE_SHAPE)
    data = make_data(truth, rng)
    clean = _fit(data)
    assert "warnings" not in clean.report
    assert np.all(np.asarray(clean.report["residual_rms"]) < RESIDUAL_WARN_RMS / 2)
    h, w = IMAGE_SHAPE
    blocks = [1 + 0.04 * rng.standard_normal((h // 8, w // 8, 1)) for _ in data.uniform_views]
    bent = [
        v * np.kron(b, np.ones((8, 8, 1))) for v, b in zip(data.uniform_views, blocks, strict=True)
    ]
    fit = _fit(dataclasses.replace(data, uniform_views=bent))
    assert len(fit.report["warnings"]) == 3
    assert np.all(np.asarray(fit.report["residual_rms"]) > RESIDUAL_WARN_RMS)
