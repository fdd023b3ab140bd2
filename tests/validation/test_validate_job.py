"""The validation job (``photoquant validate``): regression check, report, determinism.

The stored baseline of the default configuration is checked with the real
default (quick) job in ``test_validate_quick.py``. The tests here use the
``tiny`` configuration (96×72), every experiment of the job but the
leaderboard (:data:`JOB`).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from photoquant.cli import main
from tests._cpus import every_cpu
from validation.baseline import (
    DEFAULT_BASELINE,
    check_results,
    load_baseline,
    make_baseline,
)
from validation.config import (
    NOT_CONDITIONS,
    QUICK,
    TINY,
    ValidationConfig,
    ValidationError,
    stream_seed,
)
from validation.experiments import EXPERIMENTS, OPT_IN, run_validation
from validation.headlines import MAX_LINES
from validation.report import results_json, write_report


def _quiet(_message: str) -> None:
    pass


def _results(run) -> dict:
    return json.loads(results_json(run))


JOB = [name for name in EXPERIMENTS if name not in OPT_IN and name != "leaderboard"]
"""The default job's experiments but the leaderboard, which ranks every registered
method (about 3 of the tiny job's 4 minutes). Its metrics are reported, not
checked (``check=False``): a baseline made from these results is the same as one
made from the whole job's. Its determinism is the board's own
(``test_leaderboard.py::test_deterministic_for_a_seed``) and each method's
(``test_response_methods.py::test_deterministic``, ``test_peers.py``)."""


@pytest.fixture(scope="module")
def tiny_results():
    """:data:`JOB` in one process (the command line's run below uses two where it can)."""
    return _results(run_validation(TINY, 0, experiments=JOB, progress=_quiet, workers=1))


@pytest.fixture(scope="module")
def cli_job(tmp_path_factory):
    """:data:`JOB` run once more, through ``photoquant validate``: (report folder, stdout).

    Shared by the summary test and the determinism test (the second run of the
    same seed), which used to run the job each on their own (a tiny job's time).
    """
    out = tmp_path_factory.mktemp("cli-job") / "report"
    printed = io.StringIO()
    # every CPU: Table 1 and its neighbours in a second process where there are two
    with every_cpu(), contextlib.redirect_stdout(printed):
        status = main(["validate", "--tiny", "-q", "-o", str(out), "--experiments", *JOB])
    assert status == 0
    return out, printed.getvalue()


# --------------------------------------------------------------------------- determinism, CLI


def test_same_seed_same_metrics(tiny_results, cli_job):
    # every experiment of JOB run twice, in two runs with their own capture sets
    # (the second through the command line: its results.json), in one process and,
    # where the machine has two CPUs, with Table 1 and its neighbours in a second one
    again = json.loads((cli_job[0] / "results.json").read_text(encoding="utf-8"))
    other = _results(run_validation(TINY, 1, experiments=["response"], progress=_quiet))

    def untimed(results):
        return {k: v for k, v in results["metrics"].items() if not k.startswith("timings.")}

    assert untimed(again) == untimed(tiny_results)
    assert again["seeds"] == tiny_results["seeds"]
    key = "response.ccd.g_rms.G"
    assert other["metrics"][key] != tiny_results["metrics"][key]


def test_the_summary_is_short_and_names_the_report(cli_job):
    """``photoquant validate`` prints a compact summary; the tables are in the report.

    (Here rather than in ``test_validate_summary.py``: it shares :data:`JOB`'s
    command-line run with :func:`test_same_seed_same_metrics`.)
    """
    out, printed = cli_job
    lines = printed.rstrip("\n").splitlines()
    assert len(lines) <= MAX_LINES, printed
    assert str(out / "report.md") in printed
    # each experiment's headline beside the paper's figure and the noise floor
    header = next(line for line in lines if line.startswith("experiment"))
    assert "paper" in header and "floor" in header
    for name in ("response", "vignetting", "noise", "Table 1", "Fig. 7", "ablation"):
        assert any(line.startswith(name) for line in lines), name
    # the detail stays in the report
    report = (out / "report.md").read_text(encoding="utf-8")
    assert len(report.splitlines()) > len(lines)
    assert "(issue" not in printed and "(issue" not in report


def test_cli_check_names_a_regression_and_exits_1(tiny_results, tmp_path, capsys):
    base = make_baseline([tiny_results, tiny_results])  # zero spread: only the floors
    key = "sensor_lut.ccd.e_mean"
    base["metrics"][key]["value"] *= 0.5  # the run is now twice as bad as the baseline
    path = tmp_path / "tampered.json"
    path.write_text(json.dumps(base), encoding="utf-8")
    args = ["validate", "--tiny", "-q", "--json", "-o", str(tmp_path / "r"), "--check", str(path)]
    status = main([*args, "--experiments", "sensor_lut", "vignetting"])  # two of the job's
    captured = capsys.readouterr()
    assert status == 1
    results = json.loads(captured.out)
    # the same seed reproduces every other metric exactly, an experiment run alone included
    assert [f["key"] for f in results["check"]["regressions"]] == [key]
    assert results["check"]["compared"] > 10 and results["check"]["not_run"] > 0
    assert f"REGRESSION {key}" in captured.err
    assert (tmp_path / "r" / "report.md").is_file()


def test_cli_errors_are_one_line_exit_2(tmp_path, capsys):
    (tmp_path / "exists").mkdir()
    assert main(["validate", "--tiny", "-q", "-o", str(tmp_path / "exists")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (
        main(
            [
                "validate",
                "--tiny",
                "-q",
                "-o",
                str(tmp_path / "a"),
                "--check",
                str(tmp_path / "none.json"),
            ]
        )
        == 2
    )
    assert "does not exist" in capsys.readouterr().err
    assert (
        main(["validate", "--tiny", "-q", "-o", str(tmp_path / "b"), "--experiments", "nonsense"])
        == 2
    )
    assert "unknown experiment" in capsys.readouterr().err


def test_baseline_of_another_configuration_is_refused(tiny_results):
    with pytest.raises(ValidationError, match="shape"):
        check_results(tiny_results, load_baseline(DEFAULT_BASELINE))


def test_stored_baseline_documents_its_tolerances():
    base = load_baseline(DEFAULT_BASELINE)
    assert base["conditions"] == QUICK.conditions()
    assert len(base["seeds"]) >= 5 and base["seed"] == 0
    for key, m in base["metrics"].items():
        assert not key.startswith("timings."), key
        assert m["tolerance"] >= base["tolerance_rule"]["k_sigma"] * m["spread"] * (1 - 1e-12)


# --------------------------------------------------------------------------- configuration


def test_conditions_leave_out_exactly_the_knobs():
    assert set(NOT_CONDITIONS) == set(QUICK.as_dict()) - set(QUICK.conditions())


def test_config_checks_and_seed_streams():
    with pytest.raises(ValidationError, match="noise_repeats"):
        ValidationConfig(noise_repeats=(1, 2))
    with pytest.raises(ValidationError, match="shape"):
        ValidationConfig(shape=(10, 10))
    assert stream_seed(3, "a", 1) == stream_seed(3, "a", 1) != stream_seed(3, "a", 2)
    with pytest.raises(ValidationError):
        stream_seed(-1, "a")


def test_write_report_refuses_an_existing_folder(tmp_path):
    from photoquant.errors import OutputExistsError
    from validation.experiments import ValidationRun

    run = ValidationRun(TINY, 0, {})
    (tmp_path / "r").mkdir()
    with pytest.raises(OutputExistsError):
        write_report(run, tmp_path / "r")
    out = write_report(run, tmp_path / "r", overwrite=True)
    assert (out / "report.md").is_file() and isinstance(out, Path)


def test_without_the_optional_packages(tiny_results, tmp_path, monkeypatch):
    """No colour-science: the chart experiments are skipped, not failed; no matplotlib: no PNGs."""
    import validation.report as report
    from validation.experiments import noise, table1

    # Fig. 7 goes through table1's chart setup
    for module in (noise, table1):
        monkeypatch.setattr(module, "have_colour_science", lambda: False)
    monkeypatch.setattr(report, "_have_matplotlib", lambda: False)
    run = run_validation(TINY, 0, experiments=["noise", "table1", "fig7"], progress=_quiet)
    for res in run.experiments.values():
        assert res.skipped and "colour-science" in res.skipped
    check = check_results(_results(run), make_baseline([tiny_results, tiny_results]))
    assert check.ok and check.compared == 0 and check.not_run > 0
    folder = write_report(run, tmp_path / "r")
    assert "Not run: needs colour-science" in (folder / "report.md").read_text(encoding="utf-8")
    assert not list((folder / "figures").iterdir())


# --------------------------------------------------------------------------- rendered chart


def test_chart_source_is_checked():
    with pytest.raises(ValidationError, match="`chart`"):
        ValidationConfig(chart="photographed")
    assert QUICK.chart == "analytic" and "chart" in QUICK.conditions()


@pytest.mark.render
def test_rendered_chart_agrees_with_the_exact_integrals(tmp_path):
    """The rendered chart's patch means converge to the analytic chart's exact integrals."""
    pytest.importorskip("mitsuba")
    import numpy as np

    from validation.experiments.chart import chart_scene

    shape = (120, 160)
    rendered = chart_scene("rendered", shape, "A", cache_dir=tmp_path, spp=16)
    exact = chart_scene("analytic", shape, "A")
    assert rendered.source == "rendered" and rendered.render["spp"] == 16
    assert rendered.names == exact.names
    np.testing.assert_allclose(rendered.cie_rgb, exact.cie_rgb)
    # Monte-Carlo standard error of each patch mean, from the pixels' own scatter
    se = np.empty_like(rendered.patch_l)
    for i, (x0, y0, x1, y1) in enumerate(rendered.boxes):
        px = rendered.l[y0:y1, x0:x1].reshape(-1, 3)
        se[i] = px.std(axis=0, ddof=1) / np.sqrt(px.shape[0])
    assert np.all(np.abs(rendered.patch_l - exact.patch_l) < 5 * se + 1e-4 * exact.patch_l)
    # a second request is a cache hit and the same image
    again = chart_scene("rendered", shape, "A", cache_dir=tmp_path, spp=16)
    assert again.render["cache_hit"] and np.array_equal(again.l, rendered.l)


@pytest.mark.render
def test_table1_on_the_rendered_chart(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba")
    from pqsim import render
    from validation.experiments.chart import RENDER_VARIANT

    def machine_choice(**_: object) -> str:  # an LLVM variant where a library works
        raise AssertionError("the job's chart must not take the machine's variant")

    monkeypatch.setattr(render, "choose_variant", machine_choice)
    config = TINY.replace(chart="rendered", chart_spp=16, render_cache=str(tmp_path))
    run = run_validation(config, 0, experiments=["table1"], progress=_quiet)
    res = run.experiments["table1"]
    assert any("rendered by Mitsuba 3" in note for note in res.notes)
    # the same render on every machine: the stored baselines check its metrics
    assert any(f"variant {RENDER_VARIANT}," in note for note in res.notes), res.notes
    cases = {k.rsplit(".", 2)[0] for k in res.metrics if k.endswith(".corrected.r_camera")}
    assert len(cases) == len(config.presets) * len(config.illuminants)
    for case in cases:
        # the corrected patches follow the rendered truth (~0.3 % errors give
        # r > 0.9999); the camera's raw values do not (r ~ 0.85)
        r_corr = res.metrics[f"{case}.corrected.r_camera"]
        assert 0.999 < r_corr <= 1.0 and r_corr > res.metrics[f"{case}.uncorrected.r_camera"]


def test_rendered_chart_without_mitsuba_names_the_way_out(monkeypatch):
    import importlib.util

    from validation.experiments.chart import chart_scene

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "mitsuba" else real(name, *a)
    )
    with pytest.raises(ValidationError, match="--chart analytic"):
        chart_scene("rendered", (72, 96), "D65")


# --------------------------------------------------------------------------- rendered capture


def test_rendered_capture_experiment_is_off_unless_asked():
    run = run_validation(TINY, 0, experiments=["rendered"], progress=_quiet)
    res = run.experiments["rendered"]
    assert res.skipped and "--rendered-capture" in res.skipped and not res.metrics


@pytest.mark.render
def test_rendered_capture_experiment(tmp_path):
    """Calibrating from rendered scenes recovers v, u and the chart: errors from the physics."""
    pytest.importorskip("mitsuba")
    config = TINY.replace(
        rendered_capture=True, render_cache=str(tmp_path / "cache"), presets=("ccd",)
    )
    run = run_validation(config, 0, experiments=["rendered"], progress=_quiet)
    res = run.experiments["rendered"]
    assert not res.skipped, res.skipped
    m = res.metrics
    # the corrected scene is within a small factor of its noise floor (render MC noise and
    # calibration on 96x72 images add to the camera noise the floor counts)
    assert m["rendered.ccd.scene_e_mean"] < 3 * m["rendered.ccd.scene_noise_floor"]
    # vignetting (~20 % at the corners) is recovered to ~0.4 % on 96x72 renders (seeds
    # 0-2); 1 % leaves room for the MC noise of another variant, a broken fit is ~10 %
    assert m["rendered.ccd.vignetting_e_mean"] < 0.01
    assert m["rendered.ccd.colorchecker_r_cie_rgb"] > 0.9
    assert [f.name for f in res.figures] == ["rendered_vignetting_ccd"]


def test_full_job_without_mitsuba_says_how_to_run(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "mitsuba" else real(name, *a)
    )
    assert main(["validate", "--full", "-q", "-o", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "Mitsuba 3" in err and "--chart analytic" in err and not (tmp_path / "r").exists()


def test_ablation_compares_every_deviation_and_reuses_the_pipeline(tmp_path):
    """Experiment 'ablation': paper, paper + each deviation, photoquant; one calibrate for all.

    The photoquant-profile row must be exactly the job's own calibration (same
    frames, seed and pipeline: validation has no copy of a step), and the
    paper's row must come from the paper's options.
    """
    from photoquant.profiles import DEVIATIONS
    from validation.compare import compare_with_truth
    from validation.experiments import ablation
    from validation.experiments.shared import Shared, pipeline_scores

    config = TINY.replace(presets=("ccd",))
    shared = Shared(config, 0, tmp_path, _quiet)
    res = ablation.run(config, 0, tmp_path, shared=shared)
    keys = [k for k, _, _ in ablation.variants()]
    assert len(keys) == len(DEVIATIONS) + 2
    for key in keys:
        for q, _, _ in ablation.QUANTITIES:
            assert res.metrics[f"ablation.ccd.{key}.{q}"] is not None, (key, q)
    cal = shared.calibration("ccd")
    own = pipeline_scores(compare_with_truth(cal.manifest, cal.model, cal.truth))
    for q, value in own.items():
        assert res.metrics[f"ablation.ccd.photoquant.{q}"] == value, q
    assert not all(
        res.metrics[f"ablation.ccd.paper.{q}"] == own[q] for q, _, _ in ablation.QUANTITIES
    ), "the paper's profile gave the photoquant profile's results: the profile was not applied"


def test_an_error_in_the_second_process_is_one_line(tmp_path, monkeypatch, all_cpus):
    """An experiment that crashes in the forked process (not a refusal of the calibrator,
    which is its result) stops the run with one line naming the error."""
    from validation.experiments import BESIDE, _default_workers, sensor_lut

    if _default_workers() < 2:
        pytest.skip("one CPU or no fork: no second process")

    def crash(*args, **kwargs):
        raise RuntimeError("deliberately broken")

    assert "sensor_lut" in BESIDE and "response" not in BESIDE
    monkeypatch.setattr(sensor_lut, "run", crash)
    config = TINY.replace(presets=("ccd",))
    with pytest.raises(ValidationError, match="second process failed: RuntimeError: deliber"):
        run_validation(config, 0, experiments=["response", "sensor_lut"],
                       workdir=tmp_path / "w", progress=_quiet)  # fmt: skip


@pytest.mark.parametrize(("sig", "status", "word", "when"), [
    ("SIGINT", 130, "interrupted", "leaderboard: response /"),
    ("SIGTERM", 143, "terminated", "leaderboard: response /"),
    # before the fork, while the first preset is calibrated
    ("SIGINT", 130, "interrupted", "validate: calibrating 'ccd'"),
])  # fmt: skip
def test_stopping_a_two_process_run_is_one_line_and_leaves_nothing(
    tmp_path, sig, status, word, when, all_cpus
):
    """Ctrl-C (SIGINT to the terminal's process group) or SIGTERM while the second process
    ranks the leaderboard, or before the fork: one line, the status of the signal, no
    traceback from either process, neither left running, no report and no scratch
    folder."""
    import os
    import signal
    import subprocess
    import sys

    from validation.experiments import _default_workers

    if _default_workers() < 2:
        pytest.skip("one CPU or no fork: no second process")
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = os.environ | {"PYTHONPATH": os.pathsep.join(sys.path), "TMPDIR": str(scratch)}
    out = tmp_path / "report"
    code = "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); " \
        "from photoquant.cli import main; sys.exit(main(sys.argv[1:]))"  # fmt: skip
    argv = ["validate", "--tiny", "--experiments", "balance", "leaderboard", "-o", str(out)]
    with subprocess.Popen(
        [sys.executable, "-c", code, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    ) as proc:
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:  # the progress line of the moment the signal is for
            seen.append(line)
            if when in line:
                break
        os.killpg(proc.pid, getattr(signal, sig))
        err = "".join(seen) + proc.stderr.read()
        proc.wait(timeout=60)
    assert proc.returncode == status, err
    assert err.rstrip().splitlines()[-1] == f"photoquant: {word}" and "Traceback" not in err
    left = subprocess.run(["pgrep", "-g", str(proc.pid)], capture_output=True, text=True)
    assert left.stdout.strip() == "", "a process of the run is left"
    assert not out.exists() and list(scratch.iterdir()) == []
