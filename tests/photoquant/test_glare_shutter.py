"""Exposures a capture's data leave undetermined take the views' shutter lag (calibration)."""

from __future__ import annotations

import numpy as np

from photoquant.calibration import _fill_by_shutter
from photoquant.exposure import ExposureRefinement


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
