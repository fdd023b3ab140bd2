"""pqsim writes the reach of its camera pipeline after the clip as the manifest's saturation_spread."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.disturbances import SensorDisturbances
from pqsim.synth_camera.presets import camera_from_preset


@pytest.mark.parametrize(
    ("fields", "reach"),
    [
        ({}, 0),
        ({"cfa": "RGGB"}, 1),  # bilinear: a 3×3 window
        ({"cfa": "RGGB", "demosaic": "vng"}, 2),  # 5×5 windows
        ({"cfa": "GRBG", "demosaic": "ea"}, 2),
        ({"jpeg_quality": 90}, 8),  # an 8×8 block
        ({"cfa": "RGGB", "jpeg_quality": 75}, 8),
        ({"black_level_dn": 3.0, "row_noise_dn": 0.5}, 0),  # before the clip: no spread
    ],
)
def test_clip_spread_px(fields, reach):
    assert SensorDisturbances(**fields).clip_spread_px == reach


def test_capture_set_writes_saturation_spread(tmp_path):
    kw = {"shape": (24, 32), "exposure_s": np.array([1e-3, 4e-3]), "n_repeats": 1, "n_views": 2}
    write_capture_set(tmp_path / "b", camera_from_preset("ccd", disturbances={"cfa": "RGGB"}), **kw)
    assert json.loads((tmp_path / "b" / "capture.json").read_text())["saturation_spread"] == 1
    write_capture_set(tmp_path / "c", camera_from_preset("ccd"), **kw)
    assert "saturation_spread" not in json.loads((tmp_path / "c" / "capture.json").read_text())
