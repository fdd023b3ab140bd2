"""A bracket too dark (or too bright) to measure a response is refused by every method.

:func:`photoquant.response.check_reaches_range` runs before any response
method (photoquant's and the peers'): a bracket whose values below the
saturation level stay under an eighth of the range in a channel measures no
response above that level, and some methods would otherwise return one
without a word.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from photoquant.calibration import calibrate
from photoquant.errors import CalibrationError
from photoquant.response import MIN_REACH, check_reaches_range, fit_response
from photoquant.stack import ExposureStack

from .analytic import log_uniform_scene

EXPOSURES = np.array([0.01, 0.04, 0.16, 0.64])


def _bracket(gain: float, *, black: float = 0.0, bit_depth: int = 8) -> ExposureStack:
    """Frames ``round(black + (c_max − black)·min(gain·t·l, 1)^(1/2.2))`` of a scene
    log-uniform over four decades below 1, 48 × 64, one repeat, the saturation level given."""
    c_max = 2**bit_depth - 1
    scene = log_uniform_scene(np.random.default_rng(0), (48, 64, 3), 4.0)
    x = np.minimum(gain * EXPOSURES[:, None, None, None] * scene[None], 1.0)
    frames = np.rint(black + (c_max - black) * x ** (1 / 2.2)).astype(np.uint16)[None]
    return ExposureStack(
        frames,
        EXPOSURES,
        bit_depth=bit_depth,
        saturation_level=np.full(3, float(c_max)),
        black_level=None if black == 0 else np.full(3, black),
    )


@pytest.mark.parametrize("method", ["Debevec 1997", "Robertson 2003", "Gamma", "EMoR 2004"])
def test_a_dark_bracket_is_refused_by_every_method(method):
    """The brightest value 11 of 255: the check names the channel and the level."""
    stack = _bracket(1.5e-3)
    top = int(stack.frames.max())
    assert 0 < top < MIN_REACH * 255
    with pytest.raises(CalibrationError, match=rf"channel R: .* reach level {top} at most"):
        fit_response(stack, method)
    with pytest.raises(CalibrationError, match="lens cap"):
        calibrate([stack])


def test_an_overexposed_bracket_is_named_so():
    stack = _bracket(1e9)
    assert np.all(stack.frames == 255)
    with pytest.raises(CalibrationError, match="every value is at the saturation level 255"):
        check_reaches_range(stack)


def test_saturated_values_do_not_count_as_reaching_the_range():
    """A dark bracket with a few pixels at the saturation level (a lamp, or defects hidden
    there by the calibration) still measures no level between."""
    stack = _bracket(1.5e-3)
    frames = stack.frames.copy()
    frames[..., :3, :3, :] = 255
    with pytest.raises(CalibrationError, match=r"reach level \d+ at most"):
        check_reaches_range(stack.with_frames(frames))


@pytest.mark.parametrize(("black", "bit_depth"), [(0.0, 8), (64.0, 8), (256.0, 12)])
def test_the_bar_is_an_eighth_of_the_range_above_the_black_level(black, bit_depth):
    """One value at the bar passes, every value one below it does not."""
    stack = _bracket(1.5e-3, black=black, bit_depth=bit_depth)
    bar = black + MIN_REACH * (2**bit_depth - 1 - black)
    frames = np.minimum(stack.frames, math.ceil(bar) - 1)
    with pytest.raises(CalibrationError):
        check_reaches_range(stack.with_frames(frames))
    frames[0, -1, 0, 0, :] = math.ceil(bar)
    check_reaches_range(stack.with_frames(frames))


def test_a_usual_bracket_passes():
    stack = _bracket(1.0)
    check_reaches_range(stack)
    assert fit_response(stack, "Gamma").model.n_channels == 3


def test_a_bracket_mostly_saturated_and_dark_between_says_so():
    """Half the values clipped, the rest near black (a night scene's lamps): the share at
    saturation is named, and the hint is the exposures' spacing, not a lens cap."""
    stack = _bracket(1.5e-3)
    frames = stack.frames.copy()
    frames[..., : frames.shape[2] // 2 + 1, :, :] = 255
    with pytest.raises(CalibrationError, match=r"\(5\d % of the values at it\).*too far apart"):
        check_reaches_range(stack.with_frames(frames))
    with pytest.raises(CalibrationError) as small:
        check_reaches_range(stack)
    assert "of the values at it" not in str(small.value)


@pytest.mark.parametrize("method", ["Debevec 1997", "Mitsunaga-Nayar 1999", "Robertson 2003"])
def test_a_methods_error_names_the_channel_as_the_stack_does(method, rng):
    """Two exposures 20 stops apart share no well-exposed pixel: the methods, which work on
    channel indices, fail in the first channel; the error names it as the user does."""
    from .analytic import capture

    t = np.array([1e-3, 1048.576])
    frames = capture(1e3 * log_uniform_scene(rng, (30, 40, 3), 6.0), t).astype(np.uint8)
    stack = ExposureStack(frames, t, channels=("L", "M", "S"))
    with pytest.raises(CalibrationError, match=r"^channel L: only 0 pixels") as info:
        fit_response(stack, method)
    assert "channel 0" not in str(info.value)
