"""The default (quick) validation job against its stored baseline; a broken calibrator fails it.

The stored baseline of the default configuration is checked with the real
default (quick) configuration — one run, shared by the tests of this module
(its own file, started first, so that the other test worker runs the rest of
the suite meanwhile). It is the suite's longest: 820 s on one core
(2026-12-02), 630 s of it the job's leaderboard, which ranks every
registered method including the real peers.
"""

from __future__ import annotations

import json

import pytest

from validation.baseline import DEFAULT_BASELINE, check_results, load_baseline
from validation.config import QUICK
from validation.experiments import EXPERIMENTS, run_validation
from validation.report import results_json, write_report

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _quiet(_message: str) -> None:
    pass


def _results(run) -> dict:
    return json.loads(results_json(run))


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The default job, checked against the stored baseline, with its report written."""
    run = run_validation(QUICK, 0, progress=_quiet)
    check = check_results(_results(run), load_baseline(DEFAULT_BASELINE), name="default.json")
    folder = write_report(run, tmp_path_factory.mktemp("quick") / "report", check=check)
    return run, check, folder


# --------------------------------------------------------------------------- the default job


@pytest.mark.slow
def test_default_quick_job_passes_the_stored_baseline(quick):
    _, check, _ = quick
    assert check.ok, check.summary()
    assert check.compared > 150
    assert check.not_run == 0


@pytest.mark.slow
def test_report_files(quick):
    run, _, folder = quick
    report = (folder / "report.md").read_text(encoding="utf-8")
    from validation.experiments import OPT_IN

    # every experiment but the opt-in ones (robustness: --full or on request)
    assert set(run.experiments) == set(EXPERIMENTS) - set(OPT_IN)
    for name in run.experiments:
        assert run.experiments[name].title in report, name
        if name != "rendered":  # the quick job leaves the rendered capture set out
            assert not run.experiments[name].skipped, (name, run.experiments[name].skipped)
    assert "not in this configuration" in run.experiments["rendered"].skipped
    for phrase in ("eq. 8", "global scale fit", "Hugin", "not a render", "Regression check"):
        assert phrase in report, phrase
    results = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    assert results["format"] == "photoquant.validation/1"
    assert results["config"]["shape"] == [240, 320]
    assert results["seed"] == 0 and results["seeds"]
    assert results["versions"]["numpy"]
    assert results["check"]["ok"] is True
    assert set(results["metrics"]) == set(results["metric_info"])
    figures = [p for e in results["experiments"].values() for p in e["figures"]]
    assert len(figures) >= 7
    from PIL import Image

    for rel in figures:
        path = folder / rel
        assert path.read_bytes()[:8] == PNG_SIGNATURE, rel
        with Image.open(path) as img:
            img.verify()
        assert f"]({rel})" in report
    assert not list(folder.parent.glob(".report.*")), "temporary folders left behind"


@pytest.mark.slow
def test_quick_board_ranks_photoquants_methods_and_names_where_the_peers_are(quick):
    """The peers' own solvers and programs are the full job's and ``photoquant leaderboard``'s."""
    from photoquant.methods import registry
    from validation.leaderboard import is_peer_method

    run, _, _ = quick
    rows = " ".join(row.quantity for row in run.experiments["leaderboard"].rows)
    for step in ("response", "vignetting"):
        for name in registry(step):
            method = registry(step)[name]
            if name.casefold() == "none":
                continue
            assert (f" {method.name}" in rows) != is_peer_method(method), (step, name)
    assert any("photoquant leaderboard" in note for note in run.experiments["leaderboard"].notes)
    # the noise experiment's merge table likewise
    rows = " ".join(row.quantity for row in run.experiments["noise"].rows)
    for name in registry("merge"):
        method = registry("merge")[name]
        if name.casefold() != "none":
            assert (f"merge {method.name}" in rows) != is_peer_method(method), name
    assert any("--peers" in note for note in run.experiments["noise"].notes)


@pytest.mark.slow
def test_quick_numbers_are_physical(quick):
    """Sanity of the headline numbers, with bounds from the physics, not from a run."""
    run, _, _ = quick
    m = run.metrics
    # the vignetting map within the method's 1 % budget (README, tests/test_roundtrip.py)
    assert m["vignetting.ccd.e_mean"] < 0.01
    # the LUT's error is its irradiance frames' noise (25 % slack of the first-order model)
    assert m["sensor_lut.ccd.e_mean"] < 1.25 * m["sensor_lut.ccd.noise_floor"]
    # appendix A: the fitted exponent of std ∝ N^α is −½ (4 points, ~10⁵ pixels each)
    assert m["noise.ccd.sqrt_n.raw_exponent"] == pytest.approx(-0.5, abs=0.02)
    # the corrected chart correlates better with the truth than the LDR frame (Table 1)
    for col in ("ccd.outdoor", "ccd.indoor", "cmos.outdoor", "cmos.indoor"):
        assert m[f"table1.{col}.corrected.r_camera"] > m[f"table1.{col}.uncorrected.r_camera"]


# --------------------------------------------------------------------------- a broken calibrator


@pytest.mark.slow
@pytest.mark.parametrize(
    ("knobs", "experiments", "moved"),
    [
        (
            {"calibrate_kwargs": {"response": {"smoothness": 1e9}}},
            ["response"],
            "response.ccd.g_rms.",
        ),
        ({"skip_vignetting": True}, ["vignetting"], "vignetting.ccd.e_mean"),
    ],
    ids=["absurd-smoothness", "vignetting-skipped"],
)
def test_broken_calibrator_fails_the_check_naming_the_metric(knobs, experiments, moved):
    config = QUICK.replace(presets=("ccd",), **knobs)
    run = run_validation(config, 0, experiments=experiments, progress=_quiet)
    check = check_results(_results(run), load_baseline(DEFAULT_BASELINE), name="default.json")
    assert not check.ok
    names = [f.key for f in check.regressions]
    assert any(k.startswith(moved) for k in names), names
    assert moved in check.summary()
    assert check.not_run > 0  # the cmos preset and the other experiments were not run
