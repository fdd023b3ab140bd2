"""Regression testing of the user's own pipeline (issue 15): record, check, JUnit, Python helper.

The end-to-end test registers a plug-in response method, records a
baseline of it over three seeds on a test-size configuration (96×72, the
response experiment, the ccd preset: about a second per seed), shows the
check passing, then replaces the method's code by a version that smooths
``g`` a million times more and shows the check failing, naming the metric,
through the CLI (exit 1, one line per regression), the JUnit report and
:func:`photoquant.testing.check_against_baseline`. The bad-input tests use
baselines sealed from synthetic results: nothing is simulated.
"""

from __future__ import annotations

import copy
import functools
import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

import photoquant as pq
from photoquant.cli import main
from validation.baseline import (
    BASELINE_FORMAT_2,
    DEFAULT_BASELINE,
    FULL_BASELINE,
    K_SIGMA,
    CheckResult,
    Finding,
    baseline_checksum,
    k_sigma_for,
    load_baseline,
    make_baseline,
    seal_baseline,
    validate_baseline,
)
from validation.config import ValidationError
from validation.regression import (
    RunConfiguration,
    check_against_baseline,
    check_configuration,
    describe_configuration,
    junit_xml,
    prepare_check,
)

REPO = Path(__file__).resolve().parents[2]
PLUGIN = "Smoothed (regression test)"
TEST_RUN = ["--tiny", "--experiments", "response", "--preset", "ccd", "-q"]
TEST_CONFIG = {"mode": "tiny", "experiments": ["response"], "presets": ["ccd"]}


@dataclass(frozen=True)
class SmoothedOptions:
    """The plug-in's one option."""

    smoothness: float = 1000.0


def _smoothed(factor: float):
    """A response method: Debevec 1997 with ``factor`` times the given smoothness."""

    def characterise_response_smoothed(stack, options, rng):
        debevec = pq.registry("response")["Debevec 1997"]
        return debevec.function(stack, debevec.options(smoothness=options.smoothness * factor), rng)

    return characterise_response_smoothed


@pytest.fixture
def plugin():
    pq.register_method("response", PLUGIN, _smoothed(1.0), options=SmoothedOptions)

    def degrade() -> None:  # the plug-in's next version: g smoothed a million times too much
        pq.register_method(
            "response", PLUGIN, _smoothed(1e6), options=SmoothedOptions, replace=True
        )

    yield degrade
    pq.registry("response").remove(PLUGIN)


def _junit_cases(path: Path) -> dict[str, ET.Element]:
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    return {c.get("name"): c for c in root.iter("testcase")}


def _has_testing_entry_point() -> bool:
    return any(
        ep.name == "check_against_baseline"
        for ep in metadata.entry_points(group="photoquant.testing")
    )


@pytest.fixture
def testing_entry_point(tmp_path_factory, monkeypatch):
    """The ``photoquant.testing`` entry points of ``pyproject.toml``, installed or shimmed.

    An editable install made before the group existed lacks it (as
    ``tests/_commands.py`` explains for commands): a hand-written
    ``.dist-info`` declares it, so the helper is reached as users reach it.
    """
    import tomllib

    if _has_testing_entry_point():
        return
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    declared = project["entry-points"]["photoquant.testing"]
    site = tmp_path_factory.mktemp("testing-shim")
    info = site / "photoquant_testing_shim-0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: photoquant-testing-shim\nVersion: 0\n"
    )
    lines = "".join(f"{k} = {v}\n" for k, v in sorted(declared.items()))
    (info / "entry_points.txt").write_text(f"[photoquant.testing]\n{lines}")
    monkeypatch.syspath_prepend(str(site))
    assert _has_testing_entry_point()


# --------------------------------------------------------------------------- end to end


@pytest.mark.slow
def test_a_plugin_baseline_passes_then_its_degraded_version_fails(
    plugin, testing_entry_point, tmp_path, capsys
):
    base = tmp_path / "plugin.baseline.json"
    method = ["--method", f"response={PLUGIN}"]
    status = main(
        ["validate", *TEST_RUN, *method, "-o", str(tmp_path / "r0")]
        + ["--write-baseline", str(base), "--seeds", "0", "1", "2"]
    )
    assert status == 0
    capsys.readouterr()
    doc = load_baseline(base)
    assert doc["format"] == BASELINE_FORMAT_2
    assert doc["seeds"] == [0, 1, 2]
    assert doc["configuration"]["steps"]["response"]["method"] == PLUGIN
    assert doc["configuration"]["steps"]["response"]["resolved_options"] == {"smoothness": 1000.0}
    assert doc["tolerance_rule"]["k_sigma"] == pytest.approx(k_sigma_for(3))
    key = "response.ccd.g_rms.G"
    assert doc["metrics"][key]["tolerance"] >= k_sigma_for(3) * doc["metrics"][key]["spread"]

    # the same method: the baseline's own seed reproduces every value
    junit = tmp_path / "pass.xml"
    argv = ["validate", *TEST_RUN, *method, "--check", str(base), "--junit"]
    assert main([*argv, str(junit), "-o", str(tmp_path / "r1")]) == 0
    assert "PASS" in capsys.readouterr().out
    cases = _junit_cases(junit)
    assert set(cases) == set(doc["metrics"])
    assert not [c for c in cases.values() if c.find("failure") is not None]
    helper = check_against_baseline(base, methods={"response": PLUGIN}, **TEST_CONFIG)
    assert helper.ok and helper.compared == len(doc["metrics"])

    plugin()  # the method's code changes; its name and options do not
    junit = tmp_path / "fail.xml"
    assert main([*argv, str(junit), "-o", str(tmp_path / "r2")]) == 1
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.strip().startswith("REGRESSION")]
    named = [line.split()[1].rstrip(":") for line in lines]
    assert key in named, out
    line = lines[named.index(key)]
    assert "vs baseline" in line and "tolerance" in line
    failures = {n: c.find("failure") for n, c in _junit_cases(junit).items()}
    assert failures[key] is not None and key in failures[key].get("message")
    assert {n for n, f in failures.items() if f is not None} == set(named)

    with pytest.raises(AssertionError, match=key.replace(".", r"\.")) as info:
        check_against_baseline(base, methods={"response": PLUGIN}, **TEST_CONFIG)
    assert all(f"REGRESSION {n}:" in str(info.value) for n in named)
    from photoquant.testing import check_against_baseline as public  # through its entry point

    with pytest.raises(AssertionError, match=key.replace(".", r"\.")) as info:
        public(base, methods={"response": PLUGIN}, **TEST_CONFIG)
    assert all(f"REGRESSION {n}:" in str(info.value) for n in named)


def test_the_public_helper_is_found_through_its_entry_point(testing_entry_point):
    from photoquant import testing

    with pytest.raises(ValidationError, match="does not exist"):
        testing.check_against_baseline("no-such-baseline.json")


def test_the_public_helper_without_the_validation_package(monkeypatch):
    from photoquant import testing

    monkeypatch.setattr(testing.metadata, "entry_points", lambda group: [])
    with pytest.raises(testing.TestingUnavailableError, match="validation package"):
        testing.check_against_baseline("any.json")


def test_a_user_preset_file_is_run_and_described(tmp_path):
    from pqsim.synth_camera.presets import preset_json
    from validation.experiments import run_validation

    preset = tmp_path / "my-camera.json"
    preset.write_text(preset_json("cmos"), encoding="utf-8")
    rc = RunConfiguration(mode="tiny", presets=(str(preset),), experiments=("response",))
    config = rc.validation_config()
    assert config.presets == ("my-camera",) and config.sweep_preset == "my-camera"
    described = describe_configuration(config, rc.experiments)["presets"][0]
    assert described["source"] == "file" and len(described["sha256"]) == 64
    assert described["content"]["responses"][0]["kind"] != "linear"  # the cmos preset's
    run = run_validation(config, 0, experiments=rc.experiments, progress=lambda _m: None)
    assert any(k.startswith("response.my-camera.g_rms.") for k in run.metrics)


# --------------------------------------------------------------------------- bad input


def _fake_results(config, seed: int, scale: float) -> dict:
    """A results.json dict of the test configuration with made-up metric values."""
    metrics = {"response.ccd.g_rms.G": 0.01 * scale, "response.ccd.g_max.G": 0.05 * scale}
    return {
        "config": config.as_dict(),
        "seed": seed,
        "metrics": metrics,
        "metric_info": {k: {"better": "lower", "check": True} for k in metrics},
        "experiments_run": ["response"],
        "experiments": {},
        "presets": list(config.presets),
    }


def _sealed(rc: RunConfiguration) -> dict:
    config = rc.validation_config()
    runs = [_fake_results(config, 0, 1.0), _fake_results(config, 1, 1.1)]
    base = make_baseline(runs, k_sigma=k_sigma_for(2))
    base["versions"] = {"numpy": np.__version__}
    return seal_baseline(base, describe_configuration(config, rc.experiments))


@pytest.fixture
def sealed(plugin, tmp_path):
    rc = RunConfiguration(methods={"response": PLUGIN}, **TEST_CONFIG)
    doc = _sealed(rc)
    path = tmp_path / "sealed.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path, doc


def _reseal(doc: dict) -> dict:
    doc = copy.deepcopy(doc)
    doc["checksum"] = {"sha256": baseline_checksum(doc)}
    return doc


def _bad(doc_change):
    def make(doc):
        doc = copy.deepcopy(doc)
        doc_change(doc)
        return doc

    return make


def _set_metric_value(doc):
    doc["metrics"]["response.ccd.g_rms.G"]["value"] = 1.0


BAD_FILES = {
    "not a baseline": (lambda doc: {"format": "photoquant.validation/1"}, "not a validation"),
    "a list": (lambda doc: [doc], "not a validation baseline"),
    "newer format": (
        lambda doc: _reseal(dict(doc, format="photoquant.validation-baseline/3")),
        "newer format",
    ),
    "tampered value": (_bad(_set_metric_value), "edited after it was written"),
    "checksum removed": (_bad(lambda d: d.pop("checksum")), "lacks its `checksum`"),
    "steps a list, resealed": (
        lambda doc: _reseal(dict(doc, configuration=dict(doc["configuration"], steps=[1]))),
        "`configuration.steps`",
    ),
    "a preset without a name, resealed": (
        lambda doc: _reseal(
            dict(doc, configuration=dict(doc["configuration"], presets=[{"source": "file"}]))
        ),
        "`configuration.presets`",
    ),
    "configuration removed": (
        lambda doc: _reseal({k: v for k, v in doc.items() if k != "configuration"}),
        "lacks `configuration`",
    ),
}

_PLUGGED = ["--tiny", "-q", "--method", f"response={PLUGIN}"]
MISMATCHES = {
    "another method": (
        ["--tiny", "-q", "--experiments", "response", "--preset", "ccd"],
        "response method: baseline",
    ),
    "an option given": (
        [*_PLUGGED, "--experiments", "response", "--preset", "ccd"]
        + ["--option", "response.smoothness=10"],
        "response options given",
    ),
    "another profile": (
        [*_PLUGGED, "--experiments", "response", "--preset", "ccd", "--profile", "paper"],
        "profile: baseline",
    ),
    "another experiment": (
        [*_PLUGGED, "--experiments", "response", "balance", "--preset", "ccd"],
        "experiment(s) balance are not in the baseline",
    ),
    "another preset": (
        [*_PLUGGED, "--experiments", "response", "--preset", "cmos"],
        "preset 'cmos' is not in the baseline",
    ),
    "another mode": (
        ["--quick", *_PLUGGED[2:], "--experiments", "response", "--preset", "ccd"],
        "conditions.shape",
    ),
}


def _refused_before_the_run(monkeypatch, capsys, argv, expected) -> None:
    import validation.experiments as experiments

    def boom(*args, **kwargs):
        raise AssertionError("the validation ran before the baseline was checked")

    monkeypatch.setattr(experiments, "run_validation", boom)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("photoquant: error: ") and err.count("\n") == 1, err
    assert expected in err, err


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_a_bad_baseline_file_exits_2_before_the_run(sealed, tmp_path, monkeypatch, capsys, case):
    _, doc = sealed
    make, expected = BAD_FILES[case]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(make(doc)), encoding="utf-8")
    argv = ["validate", *TEST_RUN, "--method", f"response={PLUGIN}", "-o", str(tmp_path / "r")]
    _refused_before_the_run(monkeypatch, capsys, [*argv, "--check", str(path)], expected)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("case", sorted(MISMATCHES))
def test_a_configuration_the_baseline_does_not_describe_is_named(
    sealed, tmp_path, monkeypatch, capsys, case
):
    path, _ = sealed
    options, expected = MISMATCHES[case]
    argv = ["validate", *options, "-o", str(tmp_path / "r"), "--check", str(path)]
    _refused_before_the_run(monkeypatch, capsys, argv, expected)


def test_a_changed_preset_file_is_refused(tmp_path, monkeypatch, capsys):
    from pqsim.synth_camera.presets import preset_json

    preset = tmp_path / "cam.json"
    preset.write_text(preset_json("ccd"), encoding="utf-8")
    rc = RunConfiguration(mode="tiny", presets=(str(preset),), experiments=("response",))
    base = tmp_path / "cam.baseline.json"
    base.write_text(json.dumps(_sealed(rc)), encoding="utf-8")
    doc = json.loads(preset.read_text(encoding="utf-8"))
    doc["bit_depth"] = 10
    preset.write_text(json.dumps(doc), encoding="utf-8")
    argv = ["validate", "--tiny", "--experiments", "response", "--preset", str(preset), "-q"]
    argv += ["-o", str(tmp_path / "r"), "--check", str(base)]
    _refused_before_the_run(monkeypatch, capsys, argv, "preset 'cam' differs (bit_depth")


def test_the_format_1_baseline_describes_the_default_pipeline_only(
    plugin, tmp_path, monkeypatch, capsys
):
    argv = ["validate", "-q", "--method", f"response={PLUGIN}", "-o", str(tmp_path / "r")]
    _refused_before_the_run(monkeypatch, capsys, [*argv, "--check"], "format 1")
    prepare_check(RunConfiguration(), None)  # the default run still applies to it


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (["--method", "response=No Such Method"], "unknown response method"),
        (["--option", "response.no_such_option=1"], "no option(s) no_such_option"),
        (["--preset", "no-such.json"], "no-such.json"),
        (["--preset", "nikon"], "unknown camera preset"),
        (["--junit", "j.xml"], "add --check"),
        (["--seeds", "0", "1"], "--write-baseline"),
        (["--write-baseline", "b.json", "--seeds", "3"], "two distinct"),
        (["--write-baseline", "b.json", "--check"], "exclude each other"),
        (["--write-baseline", "r/b.json"], "lies inside the output"),
        (["--write-baseline", "b.json", "--seed", "3"], "not --seed"),
    ],
)
def test_bad_options_exit_2_before_the_run(tmp_path, monkeypatch, capsys, options, expected):
    monkeypatch.chdir(tmp_path)
    argv = ["validate", *TEST_RUN, *options, "-o", str(tmp_path / "r")]
    _refused_before_the_run(monkeypatch, capsys, argv, expected)


def test_nothing_written_is_overwritten(sealed, tmp_path, monkeypatch, capsys):
    path, _ = sealed
    before = path.read_bytes()
    argv = ["validate", *TEST_RUN, "--method", f"response={PLUGIN}", "-o", str(tmp_path / "r")]
    _refused_before_the_run(
        monkeypatch, capsys, [*argv, "--write-baseline", str(path)], "already exists"
    )
    junit = tmp_path / "kept.xml"
    junit.write_text("mine", encoding="utf-8")
    _refused_before_the_run(
        monkeypatch, capsys, [*argv, "--check", str(path), "--junit", str(junit)], "already exists"
    )
    assert path.read_bytes() == before and junit.read_text(encoding="utf-8") == "mine"


def test_version_differences_are_notes_not_failures(sealed):
    _, doc = sealed
    other = copy.deepcopy(doc)
    other["versions"]["numpy"] = "0.0.1"
    prep = prepare_check(
        RunConfiguration(methods={"response": PLUGIN}, **TEST_CONFIG), _reseal(other)
    )
    assert any("numpy" in n and "0.0.1" in n for n in prep.notes), prep.notes


def test_the_helper_names_a_wrong_keyword():
    with pytest.raises(ValidationError, match="the fields are mode"):
        check_against_baseline(None, method={"response": "Gamma"})


# --------------------------------------------------------------------------- pieces


def test_k_sigma_keeps_the_false_alarm_rate_of_eight_seeds():
    p8 = chi2.sf(7 * (2.5 / K_SIGMA) ** 2, 7)
    assert k_sigma_for(8) == pytest.approx(K_SIGMA)
    ks = [k_sigma_for(n) for n in range(2, 12)]
    assert all(a > b for a, b in zip(ks, ks[1:], strict=False))
    # Monte Carlo: P(K(n)·s > 2.5 σ) over 40 000 draws of n normal values; the
    # binomial standard error of a rate near 0.97 is ~0.001, 5 of them allowed
    rng = np.random.default_rng(15)
    for n in (3, 4):
        s = rng.standard_normal((40_000, n)).std(axis=1, ddof=1)
        assert np.mean(k_sigma_for(n) * s > 2.5) == pytest.approx(p8, abs=0.005)


def test_junit_has_one_case_per_metric():
    baseline = {
        "metrics": {
            "response.ccd.g_rms.G": {"value": 0.01, "tolerance": 0.002, "better": "lower"},
            "vignetting.cmos.e_mean": {"value": 0.02, "tolerance": 0.002, "better": "lower"},
            "response.ccd.g_max.G": {"value": 0.05, "tolerance": 0.01, "better": "lower"},
        }
    }
    results = {
        "config": {"name": "tiny"},
        "seed": 0,
        "metrics": {"response.ccd.g_rms.G": 0.5, "response.ccd.g_max.G": 0.05, "timings.x": 1.0},
        "metric_info": {"timings.x": {"check": False}},
    }
    check = CheckResult(baseline="b.json", compared=2, not_run=1, notes=["note: numpy 9"])
    check.regressions.append(
        Finding("response.ccd.g_rms.G", "regression", 0.5, 0.01, 0.002, "lower")
    )
    root = ET.fromstring(junit_xml(results, check, baseline))
    cases = {c.get("name"): c for c in root.iter("testcase")}
    assert set(cases) == set(baseline["metrics"]) | {"timings.x"}
    assert "0.5 vs baseline 0.01" in cases["response.ccd.g_rms.G"].find("failure").get("message")
    assert cases["vignetting.cmos.e_mean"].find("skipped").get("message") == "not run"
    assert "never compared" in cases["timings.x"].find("skipped").get("message")
    assert cases["response.ccd.g_max.G"].find("failure") is None
    suite = root.find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("skipped")) == ("4", "1", "2")
    assert "note: numpy 9" in [p.get("value") for p in suite.iter("property")]


def test_the_stored_baselines_apply_to_their_modes():
    assert load_baseline(DEFAULT_BASELINE)["format"] == "photoquant.validation-baseline/1"
    prepare_check(RunConfiguration(mode="quick"), None)
    if not FULL_BASELINE.is_file():
        with pytest.raises(ValidationError, match="no baseline of the full configuration"):
            prepare_check(RunConfiguration(mode="full"), None)
        pytest.skip(f"{FULL_BASELINE.name} is not recorded yet (see the README)")
    full = load_baseline(FULL_BASELINE)
    assert full["format"] == BASELINE_FORMAT_2 and len(full["seeds"]) >= 3
    prep = prepare_check(RunConfiguration(mode="full"), None)
    assert Path(prep.name) == FULL_BASELINE
    for m in full["metrics"].values():
        assert m["tolerance"] >= full["tolerance_rule"]["k_sigma"] * m["spread"] * (1 - 1e-12)


EXAMPLE = REPO / "examples" / "test_my_method_baseline.py"
EXAMPLE_CONFIG = {"methods": {"response": "Robertson 2003"}, "experiments": ["response"]}


def test_the_example_baseline_applies_to_the_example_test():
    base = EXAMPLE.with_name("my_method.baseline.json")
    doc = load_baseline(base)
    assert doc["seeds"] == list(range(8)) and doc["tolerance_rule"]["k_sigma"] == pytest.approx(5)
    prepare_check(RunConfiguration(presets=("ccd",), **EXAMPLE_CONFIG), base)
    with pytest.raises(ValidationError, match="response method"):
        prepare_check(RunConfiguration(presets=("ccd",), experiments=["response"]), base)


@pytest.mark.slow
def test_the_example_test_passes(testing_entry_point):
    import importlib.util

    spec = importlib.util.spec_from_file_location("example_baseline_test", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.test_my_method_holds_its_baseline()


# --------------------------------------------------------------------------- property

_leaf = st.none() | st.booleans() | st.integers(-3, 3) | st.floats(allow_nan=False)
_any = st.recursive(
    _leaf | st.text(max_size=5),
    lambda kids: (
        st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=5), kids, max_size=3)
    ),
    max_leaves=6,
)
_PLAIN = RunConfiguration(**TEST_CONFIG)


@functools.cache
def _plain() -> tuple[str, str]:
    """The sealed baseline and the description of the plain test configuration (JSON, once)."""
    config = _PLAIN.validation_config()
    return json.dumps(_sealed(_PLAIN)), json.dumps(
        describe_configuration(config, _PLAIN.experiments)
    )


@st.composite
def _crafted(draw) -> dict:
    """A sealed baseline with parts replaced, resealed (a crafted file) or not (an edited one)."""
    doc = json.loads(_plain()[0])
    conf = doc["configuration"]
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(["configuration", "step", "preset", "top"]))
        if where == "configuration":
            conf[draw(st.sampled_from(sorted(conf)))] = draw(_any)
        elif where == "step" and isinstance(conf.get("steps"), dict) and conf["steps"]:
            step = draw(st.sampled_from(sorted(conf["steps"])))
            conf["steps"][step] = draw(_any)
        elif where == "preset" and isinstance(conf.get("presets"), list) and conf["presets"]:
            conf["presets"][0] = draw(_any)
        else:
            doc[draw(st.sampled_from(["format", "versions", "seeds", "metrics"]))] = draw(_any)
    return _reseal(doc) if draw(st.booleans()) else doc


@settings(max_examples=100, deadline=None)
@given(doc=_crafted())
def test_a_crafted_baseline_is_refused_in_one_line_or_checked(doc):
    description = json.loads(_plain()[1])
    try:
        base = validate_baseline(json.loads(json.dumps(doc)), "baseline b.json")
        check_configuration(base, description, name="baseline b.json")
    except ValidationError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("baseline b.json")


def test_an_opt_in_experiment_needs_no_baseline_but_another_does(sealed):
    """The robustness experiment is reported, never checked: a baseline without it applies.

    (``--full`` runs it; the stored full baseline is recorded without it.)
    """
    _, doc = sealed
    cfg = dict(TEST_CONFIG, experiments=["response", "robustness"])
    prepare_check(RunConfiguration(methods={"response": PLUGIN}, **cfg), doc)
    cfg = dict(TEST_CONFIG, experiments=["response", "noise"])
    with pytest.raises(ValidationError, match="noise are not in the baseline"):
        prepare_check(RunConfiguration(methods={"response": PLUGIN}, **cfg), doc)


def test_the_peers_flag_reaches_the_configuration_and_is_not_a_condition():
    """``--peers`` ranks the peers in a quick run (the full mode always does); their metrics
    are reported only, so a baseline applies with or without them."""
    import argparse

    from validation.cli import add_validate_arguments, run_configuration
    from validation.config import FULL, QUICK
    from validation.regression import RunConfiguration

    parser = argparse.ArgumentParser()
    add_validate_arguments(parser)
    assert run_configuration(parser.parse_args(["--peers"])).validation_config().peers
    assert not run_configuration(parser.parse_args([])).validation_config().peers
    assert FULL.peers and not QUICK.peers
    on = RunConfiguration(peers=True).validation_config()
    assert on.conditions() == QUICK.conditions()


def test_a_bad_number_of_workers_is_refused_by_the_parser(capsys):
    """``--workers`` takes 1 or 2 (argparse's choice error, as ``--chart``'s and
    ``--profile``'s: status 2, the option named); the API's ``workers`` below 1 is one line."""
    from photoquant.errors import InputError
    from validation.config import TINY
    from validation.experiments import run_validation

    with pytest.raises(SystemExit) as stop:
        main(["validate", "--workers", "3"])
    assert stop.value.code == 2
    assert "argument --workers: invalid choice: 3" in capsys.readouterr().err
    with pytest.raises(InputError, match="`workers` must be an integer >= 1, got 0"):
        run_validation(TINY, 0, workers=0)
