"""Exposure stacks: validation, ordering, denoising (eq. 2), saturation detection."""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.stack import ExposureStack, denoise_mean, detect_saturation_levels


def test_stack_is_sorted_by_exposure_and_denoised_by_the_mean(rng):
    frames = rng.integers(0, 200, (3, 2, 4, 5, 3)).astype(np.uint8)
    stack = ExposureStack(frames, [0.2, 0.1])
    np.testing.assert_array_equal(stack.exposure_s, [0.1, 0.2])
    np.testing.assert_array_equal(stack.frames[:, 0], frames[:, 1])
    np.testing.assert_allclose(stack.mean()[1], frames[:, 0].mean(axis=0))
    assert stack.shape == (3, 2, 4, 5, 3) and stack.image_shape == (4, 5)


def test_denoising_noise_falls_as_one_over_sqrt_n(rng):
    """Appendix A: std of the mean of N repeats is σ/√N."""
    sigma, n = 4.0, 16
    frames = 100 + sigma * rng.standard_normal((n, 1, 64, 64, 1))
    std = denoise_mean(frames).std()
    # the std of 4096 samples is estimated to within ~1/sqrt(2*4096) = 1.1 % (1σ); allow 5σ
    assert std == pytest.approx(sigma / np.sqrt(n), rel=5 / np.sqrt(2 * 4096))


def test_saturation_pile_up_below_the_nominal_maximum_is_detected(rng):
    v = rng.integers(0, 217, (2, 3, 30, 30, 3))
    v[..., 0] = np.minimum(v[..., 0] + 60, 216)  # red clips at 216 (balance < 1)
    v[..., 2] = rng.integers(0, 180, v[..., 2].shape)  # blue never clips
    v[..., 1] = np.minimum(v[..., 1] + 100, 255)  # green clips at 255
    levels = detect_saturation_levels(v.astype(np.uint8), 8)
    np.testing.assert_array_equal(levels, [216, 255, 255])


def test_saturated_means_any_repeat_clipped():
    frames = np.full((2, 1, 1, 1, 1), 100, dtype=np.uint8)
    frames[1] = 255
    stack = ExposureStack(frames, [1.0], channels=("Y",))
    assert stack.saturated()[0, 0, 0, 0]


@pytest.mark.parametrize("bit_depth", [8, 12, 16])
def test_sums_means_and_clip_flags_follow_their_definitions(rng, bit_depth):
    """The memoised sums, means and clip flags equal their plain-numpy definitions."""
    c_max = 2**bit_depth - 1
    frames = rng.integers(0, c_max + 1, (7, 2, 5, 6, 3)).astype(
        np.uint8 if bit_depth == 8 else np.uint16
    )
    frames[3, 0, 0, 0] = c_max  # one repeat clipped, the others not
    frames[5, 1, 1, 1] = 0
    stack = ExposureStack(frames, [0.1, 0.2], bit_depth=bit_depth)
    sums = stack.repeat_sum()
    assert sums.dtype.kind == "u" and np.array_equal(sums, frames.sum(axis=0, dtype=np.int64))
    np.testing.assert_array_equal(stack.mean(), denoise_mean(frames))  # to the last bit
    for level in ([c_max] * 3, [c_max - 10.5, c_max - 3, c_max]):
        expected = np.any(frames >= np.asarray(level, dtype=float), axis=0)
        np.testing.assert_array_equal(stack.saturated(np.asarray(level)), expected)
    np.testing.assert_array_equal(stack.dark_clipped(), np.any(frames <= 0, axis=0))
    with pytest.raises(InputError, match="saturation_level"):
        stack.saturated(np.array([1, 2]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frames": np.zeros((2, 2, 2, 3), dtype=np.uint8)}, "5 dimensions"),
        ({"frames": np.zeros((1, 2, 2, 2, 3), dtype=np.float32)}, "integer dtype"),
        ({"exposure_s": [0.1]}, "K=2"),
        ({"exposure_s": [0.1, 0.1]}, "unique"),
        ({"exposure_s": [0.1, 0.0]}, "positive"),
        ({"exposure_s": [0.1, np.inf]}, "NaN or infinite"),
        ({"bit_depth": 20}, "between 8 and 16"),
        ({"frames": np.full((1, 2, 2, 2, 3), 300, dtype=np.uint16)}, r"\[0, 255\]"),
        ({"channels": ("R", "G")}, "C=3"),
        ({"saturation_level": [300, 255, 255]}, "saturation_level"),
    ],
)
def test_bad_stacks_are_refused_with_a_named_reason(kwargs, match):
    args = {"frames": np.zeros((1, 2, 2, 2, 3), dtype=np.uint8), "exposure_s": [0.1, 0.2]} | kwargs
    with pytest.raises(InputError, match=match):
        ExposureStack(**args)
