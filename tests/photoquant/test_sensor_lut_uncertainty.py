"""The sensor LUT's stated noise, checked against a second calibration of the same sensor.

Two capture sets of one pqsim camera (independent noise, N = 2 repeats of the
irradiance scene) give two LUTs; their difference, divided by the stated
uncertainties combined, is a standard normal where the statement is right
(measured: spread 1.01 and 0.99, 68 / 95 % coverage 67.8 / 94.7 % and
68.2 / 95.1 % on the cmos and ccd presets, 48×64).
"""

from __future__ import annotations

import numpy as np
import pytest

import photoquant as pq
from photoquant.errors import InputError
from photoquant.sensor_lut import SensorLUTModel
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset


def _calibrated(tmp_path, preset, seed):
    manifest = write_capture_set(
        tmp_path / f"{preset}-{seed}", camera_from_preset(preset), shape=(48, 64), n_repeats=2,
        seed=seed,
    )  # fmt: skip
    return pq.calibrate_manifest(manifest)


@pytest.mark.parametrize("preset", ["cmos", "ccd"])
def test_stated_lut_noise_matches_a_second_calibration(tmp_path, preset):
    first, second = (_calibrated(tmp_path, preset, seed) for seed in (11, 12))
    var = [m.sensor_lut.log_variance.astype(np.float64) for m in (first, second)]
    diff = np.log(first.sensor_lut.lut.astype(np.float64)) - np.log(second.sensor_lut.lut)
    z = (diff / np.sqrt(var[0] + var[1]))[np.isfinite(diff) & (var[0] + var[1] > 0)]
    # 9 216 values: the spread is known to ±0.7 % and a coverage to ±0.5 % (1σ);
    # the bounds are the (1 ± 0.05, 68 ± 2 %, 95 ± 1 %)
    assert abs(z.std() - 1.0) < 0.05, z.std()
    assert abs(np.mean(np.abs(z) < 1.0) - 0.683) < 0.02
    assert abs(np.mean(np.abs(z) < 1.96) - 0.95) < 0.01


def test_lut_noise_saved_with_the_camera_and_used_by_correct(tmp_path):
    model = _calibrated(tmp_path, "cmos", 11)
    model.save(tmp_path / "cam")
    back = pq.load_camera(tmp_path / "cam")
    np.testing.assert_array_equal(back.sensor_lut.log_variance, model.sensor_lut.log_variance)
    from photoquant.io import load_manifest, load_stack

    manifest = load_manifest(tmp_path / "cmos-11" / "capture.json")
    result = pq.correct(load_stack(manifest.views[0], manifest), back, uncertainty=True)
    ok = ~result.mask
    np.testing.assert_allclose(
        result.log_sigma_sensor_lut[ok] ** 2,
        back.sensor_lut.log_variance[ok],
        rtol=1e-5,
    )
    parts = [
        result.log_sigma_response,
        result.log_sigma_sensor_lut,
        result.log_sigma_vignetting,
        result.log_sigma_balance,
    ]
    expected = np.sqrt(sum(p[ok].astype(np.float64) ** 2 for p in parts))
    np.testing.assert_allclose(result.log_sigma_calibration[ok], expected, rtol=1e-5)


def test_lut_noise_checked():
    lut = np.ones((2, 3, 1), dtype=np.float32)
    with pytest.raises(InputError, match="non-negative"):
        SensorLUTModel("given", lut, log_variance=-lut)
    with pytest.raises(InputError, match="log_variance"):
        SensorLUTModel("given", lut, log_variance=np.ones((3, 2, 1), dtype=np.float32))
