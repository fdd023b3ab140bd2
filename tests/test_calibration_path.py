"""The path a capture manifest takes through the calibration, as a reader follows it.

The pipeline layer (:mod:`photoquant.calibration`, :mod:`photoquant.calibration_steps`)
calls the steps' modules; following ``calibrate_manifest`` from the manifest to the
camera, a reader enters each step module once, in the pipeline's order, except where the
data make a step come back (listed below with the reason). Counted: the module-level
functions the pipeline layer calls (not the methods of the models and results it holds),
consecutive calls into one module once.
"""

from __future__ import annotations

import sys

import pytest

import photoquant as pq
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset

PIPELINE = {"photoquant.calibration", "photoquant.calibration_steps"}
STEP_MODULES = {
    "photoquant.response",
    "photoquant.merge",
    "photoquant.sensor_lut",
    "photoquant.vignetting",
    "photoquant.balance",
    "photoquant.glare",
    "photoquant.correspondences",
    "photoquant.peers",
    "photoquant.exposure",
    "photoquant.defects",
    "photoquant.adequacy",
    "photoquant.holdout",
    "photoquant.response_selection",
}

COMES_BACK = {
    # the views' hot and stuck pixels are hidden from each frame set where it is used
    "photoquant.defects": "the defect map applied to each frame set it concerns",
    # the views' labels are tested inside the response step (the test needs g);
    # the irradiance scene's, flat field's and glare capture's times after it
    "photoquant.exposure": "the views' times with the response, the other frame sets' after",
    # the noise of the irradiance scene (the LUT's) and of view 0 (the camera's record)
    "photoquant.merge": "the irradiance scene's noise for the LUT, view 0's for the camera",
    # the tracks, given or found, are converted at the vignetting fit's public boundary
    "photoquant.correspondences": "the tracks checked again at the vignetting fit's boundary",
    # the white chart's box is checked before the balance method runs
    "photoquant.balance": "the white chart's box checked before the method",
}


def _path(manifest) -> list[str]:
    seq: list[str] = []

    def profile(frame, event, _arg):
        if event != "call" or frame.f_back is None:
            return
        caller = frame.f_back.f_globals.get("__name__", "")
        code = frame.f_code
        if caller not in PIPELINE or "." in code.co_qualname or code.co_name.startswith("<"):
            return
        top = ".".join(frame.f_globals.get("__name__", "").split(".")[:2])
        if top in STEP_MODULES and (not seq or seq[-1] != top):
            seq.append(top)

    sys.setprofile(profile)
    try:
        pq.calibrate_manifest(manifest)
    finally:
        sys.setprofile(None)
    return seq


@pytest.fixture(scope="module")
def path(tmp_path_factory):
    manifest = write_capture_set(
        tmp_path_factory.mktemp("path") / "set",
        camera_from_preset("ccd"),
        shape=(48, 64),
        n_repeats=2,
        n_views=3,
        seed=0,
    )
    return _path(manifest)


def test_each_step_module_is_entered_once_unless_the_data_bring_it_back(path):
    returns = {m for m in path if path.count(m) > 1}
    assert returns <= set(COMES_BACK), (returns - set(COMES_BACK), path)
    # the count sees a step coming back (the views' times, then the other frame sets')
    assert "photoquant.exposure" in returns, path


def test_the_steps_come_in_the_pipelines_order(path):
    first = list(dict.fromkeys(path))
    order = [
        "photoquant.defects",
        "photoquant.response",
        "photoquant.exposure",
        "photoquant.adequacy",
        "photoquant.sensor_lut",
        "photoquant.vignetting",
        "photoquant.balance",
    ]
    assert [m for m in first if m in order] == order, first
