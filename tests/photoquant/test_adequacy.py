"""Model adequacy: a bracket that one global response per channel cannot fit is told apart.

A camera that follows eq. 1 (a gamma response, noise, quantisation) against
the same camera behind a local tone curve (its response's exponent varying
smoothly over the image, as a phone's local tone mapping does) and behind a
scene that moved between exposures: only the latter two exceed the warning
level, and ``calibrate`` says so in its notes, ``crossval`` in its table.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photoquant as pq
from photoquant.adequacy import ADEQUACY_WARN, ModelAdequacy
from photoquant.crossval import crossval_stack
from photoquant.stack import ExposureStack

from .analytic import capture, log_uniform_scene

EXPOSURES = np.geomspace(1.0, 243.0, 6)
SHAPE = (64, 96, 3)


def _scene(rng):
    # smooth over 8-px cells: blocks of one scene value, as real surfaces are
    coarse = log_uniform_scene(rng, (SHAPE[0] // 8, SHAPE[1] // 8, 3), decades=3.0)
    return np.repeat(np.repeat(coarse, 8, axis=0), 8, axis=1)


def _stack(frames):
    return ExposureStack(frames, EXPOSURES)


def _adequacy(stack) -> ModelAdequacy:
    adequacy = ModelAdequacy.from_dict(pq.calibrate([stack]).report["model_adequacy"])
    assert adequacy is not None
    return adequacy


def test_a_camera_that_follows_eq1_is_adequate(rng):
    frames = capture(_scene(rng), EXPOSURES, noise_dn=1.0, n_repeats=2, rng=rng)
    adequacy = _adequacy(_stack(frames))
    assert adequacy.adequate and adequacy.n_blocks > 10
    # no structure beyond the noise: the excess is within a few times its sampling error
    assert adequacy.departure < 0.1 * ADEQUACY_WARN * 255


def test_a_local_tone_curve_is_not_one_global_response(rng):
    l = _scene(rng)
    # the exponent 1.5 on the left, 3.0 on the right: one tone curve per column (1.8 to 2.6
    # shows 0.9 DN: a global response absorbs most of a gentle one)
    gamma = np.linspace(1.5, 3.0, SHAPE[1])[None, :, None]
    frames = np.stack(
        [
            capture(
                l[:, i : i + 1],
                EXPOSURES,
                gamma=float(gamma[0, i, 0]),
                noise_dn=1.0,
                n_repeats=2,
                rng=rng,
            )
            for i in range(SHAPE[1])
        ],
        axis=3,
    )[:, :, :, :, 0]
    stack = _stack(frames)
    adequacy = _adequacy(stack)
    assert not adequacy.adequate, adequacy
    notes = pq.calibrate([stack]).report["notes"]
    assert any("eq. 1 does not hold here" in n for n in notes)
    table = crossval_stack(stack).format_table()
    assert "model adequacy:" in table and "eq. 1 does not hold" in table


def test_a_scene_that_moved_is_not_static(rng):
    l = _scene(rng)
    frames = capture(l, EXPOSURES, noise_dn=1.0, n_repeats=2, rng=rng)
    moved = capture(np.roll(l, 16, axis=1), EXPOSURES, noise_dn=1.0, n_repeats=2, rng=rng)
    frames[:, 3:] = moved[:, 3:]  # the longer half of the bracket after the scene moved
    assert not _adequacy(_stack(frames)).adequate


@pytest.mark.parametrize("departure", [float("nan"), 0.0])
def test_nothing_measured_or_nothing_left_is_adequate(departure):
    adequacy = ModelAdequacy(departure, 0.1, 16, 0)
    assert adequacy.adequate
    # a report holds strict JSON: nothing measured is null, and reads back as no adequacy
    record = json.loads(json.dumps(adequacy.as_dict(), allow_nan=False))
    assert (ModelAdequacy.from_dict(record) is None) == (not np.isfinite(departure))


@pytest.mark.parametrize("record", [None, {}, {"departure": "x"}, [1, 2]])
def test_a_report_without_a_valid_record_has_no_adequacy(record):
    assert ModelAdequacy.from_dict(record) is None
