"""The ablation's calibrations: the paper's profile with its biases unstated keeps its estimates."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import photoquant as pq
from photoquant.calibration import resolve_steps
from photoquant.profiles import DEVIATIONS, profile_steps
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from validation.experiments.ablation import unstated, variants


def test_every_paper_variant_leaves_the_biases_unstated_and_keeps_its_deviation():
    stating = {s for s, (_, o) in profile_steps("paper").items() if "uncorrected_bias" in o}
    assert stating == {"response", "merge", "balance", "vignetting"}
    found = variants()
    assert len(found) == len(DEVIATIONS) + 2
    for (key, _, kwargs), dev in zip(found[1:-1], DEVIATIONS, strict=True):
        assert key.startswith("paper+")
        steps = {name: options for name, (_, options) in resolve_steps(**kwargs).items()}
        for step in stating:
            assert steps[step].uncorrected_bias == "ignored", (key, step)
        for name, value in dev.options.items():
            assert getattr(steps[dev.step], name) == value, (key, name)
    paper = {name: options for name, (_, options) in resolve_steps(**found[0][2]).items()}
    default = {name: options for name, (_, options) in resolve_steps("paper").items()}
    for step, options in paper.items():  # only the statement differs from the paper's profile
        if step in stating:
            options = dataclasses.replace(options, uncorrected_bias="stated")
        assert options == default[step], step
    assert found[-1][2] == {"profile": "photoquant"}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ablation") / "set"
    return write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=0)


def test_unstated_biases_leave_every_estimate_of_the_paper_profile(capture):
    stated = pq.calibrate_manifest(capture, profile="paper")
    unstated_ = pq.calibrate_manifest(capture, profile="paper", **unstated())
    pairs = [
        (stated.response.log_inverse_response, unstated_.response.log_inverse_response),
        (stated.balance.factors, unstated_.balance.factors),
        (stated.sensor_lut.lut, unstated_.sensor_lut.lut),
        (stated.vignetting.params, unstated_.vignetting.params),
    ]
    for a, b in pairs:
        assert np.array_equal(np.asarray(a), np.asarray(b))
    # the statement itself is what differs: the stated response gains its bias row
    rows = [m.response.covariance_factor.shape[1] for m in (stated, unstated_)]
    assert rows[0] == rows[1] + 1, rows
