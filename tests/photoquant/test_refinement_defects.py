"""Exposure refinement of a mostly dark frame set leaves the sensor's defects out."""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.calibration_steps import _refine_against
from photoquant.defects import DefectMap
from photoquant.errors import CalibrationError
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

from .analytic import true_g


def _dark_capture_with_stuck_pixels():
    """A dark frame set (a glare capture's background, at 0 DN) whose 400 stuck
    pixels read 120 DN at every exposure, and a gamma camera's response."""
    rng = np.random.default_rng(0)
    times = np.array([1e-4, 1e-3, 1e-2, 1e-1])
    frames = np.zeros((2, 4, 40, 50, 3), dtype=np.uint8)
    stuck = np.zeros((40, 50, 3), bool)
    stuck.reshape(-1)[rng.choice(stuck.size, 400, replace=False)] = True
    frames[:, :, stuck] = 120
    levels = np.arange(256.0)
    g = np.stack([true_g(np.maximum(levels, 0.5), ch) for ch in range(3)])
    response = ResponseModel("gamma", levels, g, np.full(3, 255.0), valid_min=np.full(3, 1.0))
    defects = DefectMap(hot=np.zeros_like(stuck), stuck=stuck)
    return ExposureStack(frames, times), response, defects


def test_stuck_pixels_alone_would_pull_the_times_together():
    stack, response, _ = _dark_capture_with_stuck_pixels()
    ref = _refine_against(stack, response, 0)
    t = ref.exposure_s[ref.refined]
    # a stuck pixel's ratio is 1 between any two exposures: times three decades apart
    # come out equal, the failure the defect map prevents
    assert t.size >= 2 and t.max() / t.min() < 1.01


def test_the_defects_are_left_out_of_the_refinement():
    stack, response, defects = _dark_capture_with_stuck_pixels()
    with pytest.raises(CalibrationError, match="do not determine the exposure times"):
        _refine_against(stack, response, 0, defects)
