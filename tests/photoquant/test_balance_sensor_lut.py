"""Colour balance (§5.3) and the sensor LUT (§5.4)."""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.balance import colour_balance, colour_balance_WhiteChart, fold_balance
from photoquant.errors import CalibrationError, InputError
from photoquant.sensor_lut import sensor_lut_IrradianceScene


def test_white_chart_factors_are_green_referenced():
    img = np.ones((10, 12, 3)) * np.array([2.0, 4.0, 8.0])
    a = colour_balance_WhiteChart(img, [2, 3, 6, 8])
    np.testing.assert_allclose(a, [2.0, 1.0, 0.5])
    np.testing.assert_allclose((img * a)[5, 5], [4.0, 4.0, 4.0])


@pytest.mark.parametrize("reference_channel", [0, 1, 5])
def test_a_monochrome_white_chart_is_its_own_reference(reference_channel):
    img = np.full((10, 12, 1), 3.0)
    a = colour_balance_WhiteChart(img, [2, 3, 6, 8], reference_channel=reference_channel)
    np.testing.assert_array_equal(a, [1.0])


def test_a_reference_channel_the_camera_lacks_is_refused_in_the_users_terms():
    img = np.ones((10, 12, 2))
    with pytest.raises(InputError, match="not one of the camera's 2 channels") as info:
        colour_balance_WhiteChart(img, [2, 3, 6, 8], reference_channel=2)
    assert "--option balance.reference_channel=0..1" in str(info.value)


def test_white_chart_ignores_flagged_pixels_and_outliers():
    img = np.ones((10, 10, 3)) * np.array([2.0, 4.0, 8.0])
    img[3, 3] = [100.0, 1.0, 1.0]  # a specular glint
    mask = np.zeros(img.shape, dtype=bool)
    img[4, 4] = np.nan
    mask[4, 4] = True
    np.testing.assert_allclose(colour_balance_WhiteChart(img, [2, 2, 8, 8], mask=mask), [2, 1, 0.5])


@pytest.mark.parametrize("roi", [[0, 0, 20, 5], [5, 5, 5, 8], [-1, 0, 3, 3], [0, 0, 3]])
def test_roi_outside_or_empty_is_an_error(roi):
    with pytest.raises(InputError, match="white_roi"):
        colour_balance_WhiteChart(np.ones((10, 10, 3)), roi)


def test_fully_saturated_chart_is_an_error():
    img = np.ones((10, 10, 3))
    mask = np.zeros(img.shape, dtype=bool)
    mask[2:5, 2:5, 0] = True
    with pytest.raises(CalibrationError, match="no validly exposed pixel in channel 0"):
        colour_balance_WhiteChart(img, [2, 2, 5, 5], mask=mask)


def test_balance_dispatch_and_fold():
    img = np.ones((4, 4, 3)) * np.array([1.0, 2.0, 4.0])
    np.testing.assert_allclose(colour_balance(img, [0, 0, 4, 4], method="none"), 1.0)
    a = colour_balance(img, [0, 0, 4, 4], method="white chart")
    g = np.zeros((3, 5))
    np.testing.assert_allclose(np.exp(fold_balance(g, a))[:, 0], a)
    with pytest.raises(InputError, match="valid methods are: None, White Chart"):
        colour_balance(img, [0, 0, 4, 4], method="grey world")


def test_sensor_lut_is_the_normalised_irradiance_image(rng):
    u = 1 + 0.02 * rng.standard_normal((20, 30, 3))
    level = np.array([3.0, 5.0, 2.0])
    lut = sensor_lut_IrradianceScene(u * level)
    expected = u / u.mean(axis=(0, 1))
    np.testing.assert_allclose(lut.lut, expected, rtol=1e-6)
    np.testing.assert_allclose(lut.lut.mean(axis=(0, 1)), 1.0, rtol=1e-6)
    assert lut.lut.dtype == np.float32 and lut.n_flagged == 0
    np.testing.assert_allclose(lut.prnu_std, expected.std(axis=(0, 1)), rtol=1e-5)


def test_sensor_lut_flagged_pixels_get_one_and_too_many_is_an_error():
    img = np.full((10, 10, 3), 2.0)
    mask = np.zeros(img.shape, dtype=bool)
    mask[0, 0, 1] = True
    lut = sensor_lut_IrradianceScene(img, mask, max_flagged_fraction=0.01)
    assert lut.lut[0, 0, 1] == 1.0 and lut.n_flagged == 1
    mask[:5] = True
    with pytest.raises(CalibrationError, match="50.00 % of the irradiance scene"):
        sensor_lut_IrradianceScene(img, mask)
