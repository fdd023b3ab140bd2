"""A tampered or foreign baseline for ``photoquant validate --check`` fails before the run.

Every case exits with status 2 and one line ``photoquant: error: ...`` within
a second or two: the baseline is read, validated and compared with the run's
conditions before any simulation (a regression is status 1, after the run).
"""

from __future__ import annotations

import copy
import json
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.cli import main
from validation.baseline import (
    DEFAULT_BASELINE,
    check_baseline_applies,
    check_results,
    load_baseline,
    validate_baseline,
)
from validation.config import QUICK, TINY, ValidationError

STORED = json.loads(DEFAULT_BASELINE.read_text(encoding="utf-8"))
KEY = next(iter(STORED["metrics"]))


def _tampered(change) -> dict:
    doc = copy.deepcopy(STORED)
    change(doc)
    return doc


def _set(path: tuple, value):
    def change(doc):
        target = doc
        for p in path[:-1]:
            target = target[p]
        target[path[-1]] = value

    return change


def _drop(path: tuple):
    def change(doc):
        target = doc
        for p in path[:-1]:
            target = target[p]
        del target[path[-1]]

    return change


CASES = {
    "not an object": (lambda doc: None, "[1, 2]", "not a validation baseline"),
    "foreign format": (_set(("format",), "photoquant.camera/1"), None, "not a validation baseline"),
    "a results.json": (_drop(("format",)), None, "not a validation baseline"),
    "no metrics": (_drop(("metrics",)), None, "lacks `metrics`"),
    "metrics a list": (_set(("metrics",), [1, 2]), None, "lacks `metrics`"),
    "conditions a string": (_set(("conditions",), "quick"), None, "`conditions`"),
    "empty metrics": (_set(("metrics",), {}), None, "no metrics"),
    "metric a number": (_set(("metrics", KEY), 0.5), None, "must be an object"),
    "value a string": (_set(("metrics", KEY, "value"), "0.1"), None, "`value` must be"),
    "value a bool": (_set(("metrics", KEY, "value"), True), None, "`value` must be"),
    "no tolerance": (_drop(("metrics", KEY, "tolerance")), None, "lacks `tolerance`"),
    "negative tolerance": (_set(("metrics", KEY, "tolerance"), -1), None, "`tolerance`"),
    "tolerance null": (_set(("metrics", KEY, "tolerance"), None), None, "`tolerance`"),
    "unknown direction": (_set(("metrics", KEY, "better"), "up"), None, "`better` must be"),
    "allow_none a string": (_set(("metrics", KEY, "allow_none"), "yes"), None, "`allow_none`"),
    "description a list": (_set(("metrics", KEY, "description"), []), None, "`description`"),
    "NaN value": (lambda doc: None, '{"format": "x", "v": NaN}', "NaN"),
    "deeply nested": (lambda doc: None, "[" * 5000 + "]" * 5000, "nested deeper"),
    "not JSON": (lambda doc: None, '{"format": ', "not valid JSON"),
    "other conditions": (_set(("conditions", "n_repeats"), 7), None, "differs from this run"),
}


def _write(tmp_path: Path, name: str) -> Path:
    change, text, _ = CASES[name]
    path = tmp_path / "baseline.json"
    path.write_text(text if text is not None else json.dumps(_tampered(change)), encoding="utf-8")
    return path


def test_the_stored_baseline_is_valid_and_applies_to_the_quick_job():
    base = load_baseline(DEFAULT_BASELINE)
    assert validate_baseline(base) is base
    check_baseline_applies(base, QUICK.conditions())
    with pytest.raises(ValidationError, match="shape"):
        check_baseline_applies(base, TINY.conditions())


@pytest.mark.parametrize("name", sorted(set(CASES) - {"other conditions"}))
def test_load_baseline_refuses_with_one_line(tmp_path, name):
    path = _write(tmp_path, name)
    with pytest.raises(ValidationError, match=CASES[name][2]) as info:
        load_baseline(path)
    assert "\n" not in str(info.value)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("name", sorted(CASES))
def test_validate_check_exits_2_before_the_run(tmp_path, capsys, name):
    """``photoquant validate --check TAMPERED`` answers at once: nothing was simulated."""
    path = _write(tmp_path, name)
    t0 = time.perf_counter()
    status = main(["validate", "-q", "-o", str(tmp_path / "report"), "--check", str(path)])
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("photoquant: error: ") and err.count("\n") == 1, err
    assert CASES[name][2] in err
    assert not (tmp_path / "report").exists()
    assert elapsed < 5, f"the check took {elapsed:.1f} s: it ran the job first"


def test_the_check_refuses_before_any_simulation(tmp_path, monkeypatch, capsys):
    """Stronger than timing: the run's entry point is never called."""
    import validation.experiments as experiments

    def boom(*args, **kwargs):
        raise AssertionError("the validation ran before the baseline was checked")

    monkeypatch.setattr(experiments, "run_validation", boom)
    path = _write(tmp_path, "no tolerance")
    assert main(["validate", "--tiny", "-q", "-o", str(tmp_path / "r"), "--check", str(path)]) == 2
    assert "lacks `tolerance`" in capsys.readouterr().err


# ---------------------------------------------------------------------------- property


def _results_matching(baseline: dict) -> dict:
    """A results.json dict that reproduces the stored baseline's values exactly."""
    metrics = {k: ref["value"] for k, ref in STORED["metrics"].items()}
    return {
        "config": dict(STORED["conditions"], name="quick"),
        "metrics": metrics,
        "metric_info": {k: {"check": True} for k in metrics},
        "experiments_run": sorted({k.split(".")[0] for k in metrics}),
        "experiments": {},
        "presets": ["ccd", "cmos"],
    }


_json_leaf = st.none() | st.booleans() | st.integers(-5, 5) | st.floats(allow_nan=False)
_json_any = st.recursive(
    _json_leaf | st.text(max_size=6),
    lambda kids: (
        st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=6), kids, max_size=3)
    ),
    max_leaves=8,
)
_FIELDS = ["value", "tolerance", "better", "allow_none", "description", "unit", "spread", "mean"]


@st.composite
def _mutated_baseline(draw) -> dict:
    doc = copy.deepcopy(STORED)
    keys = sorted(doc["metrics"])
    for _ in range(draw(st.integers(1, 4))):
        where = draw(st.sampled_from(["metric", "field", "drop", "top"]))
        key = draw(st.sampled_from(keys))
        if not isinstance(doc["metrics"], dict) or key not in doc["metrics"]:
            continue  # the metrics were replaced by an earlier mutation
        if where == "metric":
            doc["metrics"][key] = draw(_json_any)
        elif where == "field" and isinstance(doc["metrics"][key], dict):
            doc["metrics"][key][draw(st.sampled_from(_FIELDS))] = draw(_json_any)
        elif where == "drop" and isinstance(doc["metrics"][key], dict):
            doc["metrics"][key].pop(draw(st.sampled_from(_FIELDS)), None)
        elif where == "top":
            doc[draw(st.sampled_from(["format", "metrics", "conditions", "config_name"]))] = draw(
                _json_any
            )
    return doc


def test_the_stored_baseline_passes_a_run_that_reproduces_it():
    result = check_results(_results_matching(STORED), load_baseline(DEFAULT_BASELINE))
    assert result.ok and result.compared == len(STORED["metrics"])


@pytest.mark.parametrize("installed", [True, False])
def test_a_peer_programs_rows_are_expected_where_it_is_installed(monkeypatch, installed):
    from photoquant.peers import hugin

    monkeypatch.setattr(hugin, "available", lambda: installed)
    results = _results_matching(STORED)
    peer_rows = [k for k in results["metrics"] if ".hugin." in k]
    assert peer_rows  # Table 1's Hugin column is in the stored baseline
    for key in peer_rows:
        del results["metrics"][key]
    result = check_results(results, load_baseline(DEFAULT_BASELINE))
    missing = {f.key for f in result.regressions if f.kind == "missing"}
    assert missing == (set(peer_rows) if installed else set())
    assert result.not_run == (0 if installed else len(peer_rows))


def test_a_condition_named_with_a_line_break_is_refused_on_one_line():
    """A baseline whose conditions name a key with a line break (found by the property
    below): the refusal names it escaped, on one line."""
    doc = copy.deepcopy(STORED)
    doc["conditions"] = {**doc["conditions"], "a\nb": False}
    base = validate_baseline(json.loads(json.dumps(doc)), "baseline b.json")
    with pytest.raises(ValidationError) as info:
        check_results(_results_matching(STORED), base)
    assert "\n" not in str(info.value) and "'a\\nb'" in str(info.value)


@settings(max_examples=200, deadline=None)
@given(doc=_mutated_baseline())
def test_a_baseline_is_refused_on_load_or_checks_without_crashing(doc):
    """Tampered baselines: one-line ValidationError on load, or a check that runs to the end."""
    try:
        base = validate_baseline(json.loads(json.dumps(doc)), "baseline b.json")
    except ValidationError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("baseline b.json")
        return
    try:
        result = check_results(_results_matching(STORED), base)
    except ValidationError as exc:  # the conditions differ: refused, one line
        assert "\n" not in str(exc)
        return
    result.summary()
    json.dumps(result.to_dict())
