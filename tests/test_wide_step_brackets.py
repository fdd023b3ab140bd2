"""Wide-step brackets from the synthetic cameras: cross-validated, template prior against eq. 7's.

Three exposures 3 stops apart (an auto-bracket; cross-validation fits the two
outer ones, 6 stops apart) from pqsim cameras of three kinds of response —
linear (ccd), drawn from the space of real ones (emor-1) and a film's
characteristic curve with toe and shoulder (film, not from that space) — and
the default one-stop bracket, where nothing may change
(:mod:`photoquant.response.wide_steps`).
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.crossval import crossval_manifest
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset

SHAPE = (120, 160)


def _bracket(tmp_path, preset: str, exposure_s) -> object:
    return write_capture_set(
        tmp_path / preset, camera_from_preset(preset), shape=SHAPE, exposure_s=exposure_s,
        n_repeats=1, n_views=1, seed=0,
    )  # fmt: skip


@pytest.mark.parametrize("preset", ["ccd", "emor-1", "film"])
def test_three_stop_brackets_are_predicted_better(tmp_path, preset):
    """Measured (2026-12-01, 120×160, seed 0), template against eq. 7: ccd 11.9 / 18.6 DN,
    emor-1 10.6 / 21.6, film 8.8 / 30.2 (1.6× to 3.4× less)."""
    manifest = _bracket(tmp_path, preset, 1.5e-3 * 8.0 ** np.arange(3))
    ours = crossval_manifest(manifest).overall_mae_dn
    plain = crossval_manifest(manifest, options={"wide_steps": "none"}).overall_mae_dn
    assert ours < 0.75 * plain, f"{preset}: template {ours:.2f} DN, eq. 7 {plain:.2f} DN"


def test_one_stop_brackets_are_unchanged(tmp_path):
    manifest = _bracket(tmp_path, "film", np.geomspace(1e-3, 0.2, 8))
    ours = crossval_manifest(manifest)
    plain = crossval_manifest(manifest, options={"wide_steps": "none"})
    assert [r.mae_dn for r in ours.rows] == [r.mae_dn for r in plain.rows]
