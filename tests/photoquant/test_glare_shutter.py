"""Exposures a capture's data leave undetermined: the shutter lag of the views or of the source's own exposures."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photoquant as pq
from photoquant.calibration_steps import _fill_by_shutter, _lag_from_group
from photoquant.exposure import ExposureRefinement
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset
from pqsim.synth_camera.truth import load_truth


def _ref(nominal, refined_s, refined):
    k = len(nominal)
    return ExposureRefinement(
        exposure_s=np.asarray(refined_s, float),
        nominal_s=np.asarray(nominal, float),
        log_std=np.where(refined, 0.01, np.nan),
        refined=np.asarray(refined),
        n_values=np.full(k, 500),
        residual_rms=1.0,
        gauge="geometric mean",
        iterations=1,
    )


def test_undetermined_exposures_follow_the_affine_shutter():
    """Actual times ``c (t + λ)``: the refined ones fix ``c``, the others get it with ``λ``."""
    nominal = np.array([15e-6, 60e-6, 1e-3, 1e-2, 1e-1])
    lag, c = 1e-4, 0.97  # the refined exposures' gauge: off by 3 % from nominal + lag
    actual = c * (nominal + lag)
    refined = np.array([False, False, True, True, True])
    ref = _ref(nominal, np.where(refined, actual, nominal), refined)
    out = _fill_by_shutter(ref, lag)
    np.testing.assert_allclose(out.exposure_s, actual, rtol=1e-12)
    np.testing.assert_array_equal(out.refined, refined)  # still says what the data determined
    # nothing to fill, nothing to fill from, or no lag: unchanged
    assert _fill_by_shutter(ref, 0.0) is ref
    every = _ref(nominal, actual, np.ones(5, bool))
    assert _fill_by_shutter(every, lag) is every
    none = _ref(nominal, nominal, np.zeros(5, bool))
    assert _fill_by_shutter(none, lag) is none


@settings(max_examples=30, deadline=None)
@given(
    lag=st.floats(0.0, 3e-4),
    scale=st.floats(0.5, 2.0),
    seed=st.integers(0, 2**16),
)
def test_the_lag_a_group_bends_to(lag, scale, seed):
    """``ln t = s + ln(t_nominal + L)``: ``L`` recovered within its stated error.

    Four short exposures 2.35× apart (a glare capture's) with 0.1 % noise in
    ``ln t`` (the noise given as ``log_std``): the fit's ``L`` lies within
    4 σ of the truth (σ its own stated error), and σ is the right size: a
    few µs, not 0 and not the whole range.
    """
    nominal = 15e-6 * 2.35 ** np.arange(4)
    noise = 1e-3 * np.random.default_rng(seed).standard_normal(4)
    times = scale * (nominal + lag) * np.exp(noise)
    ref = _ref(nominal, times, np.ones(4, bool))
    ref = ExposureRefinement(**{**ref.__dict__, "log_std": np.full(4, 1e-3)})
    fitted = _lag_from_group(ref)
    assert fitted is not None
    got, sigma, s = fitted
    assert got >= 0.0
    assert 1e-8 < sigma < 1e-4
    assert abs(got - lag) <= 4 * sigma + 1e-9
    if lag > 10 * sigma:
        assert abs(np.exp(s) / scale - 1) < 0.05


def test_a_group_of_two_exposures_fixes_no_lag():
    nominal = np.array([15e-6, 35e-6, 1e-3])
    ref = _ref(nominal, nominal + 1e-4, np.array([True, True, False]))
    assert _lag_from_group(ref) is None


@pytest.mark.slow
def test_the_glare_captures_own_short_exposures_measure_the_lag(tmp_path):
    """A 0.1 ms lag, no jitter: the source's short exposures give the lag to a few µs.

    The views (1–200 ms) see the lag only as a few % on their shortest
    exposure; the glare capture's short exposures (15 µs nominal: 115 µs
    actual) are bent by it 7.7×. The calibration reports the group's lag,
    within 3 of its σ (under 5 µs) of the truth; the fitted glare fraction
    is within 3 % of the truth. With 3 % jitter as well (pqsim's ccd at
    320×240) the views' lag was 119 ± 15 µs, the group's 96 ± 3 µs, and
    the fraction went from 8 % high to 1–3 % low.
    """
    cam = camera_from_preset(
        "ccd",
        disturbances={"exposure_lag_s": 1e-4},
        glare={"fraction": 0.015, "width_px": 20.0},
    )
    man = write_capture_set(
        tmp_path / "set",
        cam,
        shape=(96, 128),
        seed=3,
        n_repeats=2,
        scene="lamp",
        glare={"level": 30.0},
    )
    model = pq.calibrate_manifest(man)
    rep = model.report["exposures"]
    glare = rep["glare"]
    assert "group_lag_s" in glare, glare
    assert abs(glare["group_lag_s"] - 1e-4) <= 3 * glare["group_lag_std_s"]
    assert glare["group_lag_std_s"] < 5e-6
    truth = load_truth(pq.load_manifest(man).root / "truth").camera.glare
    np.testing.assert_allclose(
        model.glare.fraction, np.broadcast_to(truth.fraction, (3,)), rtol=0.03
    )
