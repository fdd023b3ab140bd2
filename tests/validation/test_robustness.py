"""The robustness experiment : rows, metrics, selection."""

from __future__ import annotations

import pytest

from validation.config import FULL, QUICK, TINY
from validation.experiments import EXPERIMENTS, _select
from validation.experiments.robustness import DISTURBANCES, QUANTITIES, run


def test_every_row_switches_something_on_for_both_presets() -> None:
    from pqsim.synth_camera.presets import camera_from_preset

    keys = [d.key for d in DISTURBANCES]
    assert len(set(keys)) == len(keys) and keys[-1] == "all"
    assert {"typical", "typical_glare", "glare", "glare_capture", "cos4", "emor"} <= set(keys)
    for preset in ("ccd", "cmos"):
        clean = camera_from_preset(preset)
        assert clean.disturbances is None and clean.glare is None
        for dist in DISTURBANCES:
            assert dist.overrides or dist.capture  # a disturbance of the camera or the capture
            cam = camera_from_preset(preset, **dist.overrides)
            if "disturbances" in dist.overrides:
                assert cam.disturbances is not None and cam.disturbances.active
            if "glare" in dist.overrides:
                assert cam.glare is not None
            if dist.capture.get("glare"):
                assert dist.scene == "lamp"  # the glare target: the lamp scene
    # "all" holds every other row's sensor and output fields
    every = DISTURBANCES[-1].overrides["disturbances"]
    for dist in DISTURBANCES[:-1]:
        for key, value in dist.overrides.get("disturbances", {}).items():
            assert every[key] == value


def test_in_full_and_on_request_not_in_quick() -> None:
    assert "robustness" in EXPERIMENTS
    assert "robustness" not in _select(None, QUICK)
    assert "robustness" in _select(None, FULL)
    assert _select(["robustness"], QUICK) == ["robustness"]
    assert "robustness" not in QUICK.conditions() and "robustness" not in FULL.conditions()


@pytest.mark.slow
def test_run_reports_each_quantity_against_the_clean_camera(tmp_path) -> None:
    rows = [d for d in DISTURBANCES if d.key in ("defects", "typical")]
    cfg = TINY.replace(presets=("ccd",))
    res = run(cfg, 0, tmp_path, disturbances=rows)
    m = res.metrics
    for key in ("clean", "defects", "typical"):
        for q, _, _ in QUANTITIES:
            assert m[f"robustness.ccd.{key}.{q}"] is not None
    assert m["robustness.ccd.clean.scene_ratio"] == pytest.approx(1.0)
    floor = m["robustness.ccd.scene_noise_floor"]
    assert 0 < floor <= m["robustness.ccd.clean.scene"] * 1.5
    # the typical set costs accuracy: 3 % exposure jitter per frame is a gain error per
    # exposure, far above the scene's noise floor
    assert m["robustness.ccd.typical.scene"] > 1.2 * m["robustness.ccd.clean.scene"]
    assert len(res.rows) == 3
    assert not any((tmp_path / "robustness" / "ccd").iterdir())  # capture sets removed


def test_the_pairs_experiment_has_every_pair_once_and_runs_only_when_named(monkeypatch):
    import itertools

    import validation.experiments.robustness_pairs as pairs_exp
    from validation.experiments.robustness import PAIRS, SENSOR_GROUPS

    expected = {f"{a}+{b}" for a, b in itertools.combinations(SENSOR_GROUPS, 2)}
    assert {d.key for d in PAIRS} == expected and len(PAIRS) == len(expected)
    for dist in PAIRS:
        a, b = dist.key.split("+")
        assert dist.overrides["disturbances"] == {**SENSOR_GROUPS[a][1], **SENSOR_GROUPS[b][1]}
    # each group is one of the single rows' disturbances at the same level
    singles = {k: v for d in DISTURBANCES for k, v in d.overrides.get("disturbances", {}).items()}
    for _, fields in SENSOR_GROUPS.values():
        assert all(singles[k] == v for k, v in fields.items())
    assert "robustness_pairs" not in _select(None, QUICK) + _select(None, FULL)
    assert _select(["robustness_pairs"], QUICK) == ["robustness_pairs"]
    seen = {}

    def fake(config, seed, workdir, **kwargs):
        seen.update(kwargs)
        return "result"

    monkeypatch.setattr(pairs_exp, "run_rows", fake)
    assert pairs_exp.run(TINY, 0, "unused") == "result"
    assert seen["disturbances"] == PAIRS and seen["key"] == "robustness_pairs"
