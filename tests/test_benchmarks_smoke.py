"""The benchmark harness runs a case end to end at a tiny size (the benchmarks themselves never run here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.harness import Case, Config, Measured, run_case
from benchmarks.run import main

pytest.importorskip("cv2")


def test_run_case_interleaves_and_scores() -> None:
    calls: list[str] = []

    def impl(name: str):
        def fn(ctx: dict) -> Measured:
            calls.append(name)
            return Measured(ctx["x"] * 2, {"bytes": 8.0})

        return fn

    case = Case(
        name="toy",
        title="toy",
        setup=lambda cfg: {"x": np.arange(3.0)},
        implementations={"ours": impl("ours"), "peer": impl("peer")},
        accuracy=lambda ctx, name, out: {"max_err": float(np.max(np.abs(out - 2 * ctx["x"])))},
    )
    res = run_case(case, Config(repeats=3))
    # interleaved, not all of one then the other, each repeat starting one further on
    assert calls == ["ours", "peer", "peer", "ours", "ours", "peer"]
    assert len(res.results["ours"].times_s) == 3
    assert res.results["peer"].accuracy == {"max_err": 0.0}
    assert res.results["ours"].metrics == {"bytes": 8.0}
    assert set(res.ratios()) == {"peer"}


def test_a_failing_implementation_is_its_row_not_the_run() -> None:
    """One peer's failure is recorded (its type and last line) and tried no more; the rest run."""
    calls: list[str] = []

    def ours(ctx: dict) -> float:
        calls.append("ours")
        return 1.0

    def broken(ctx: dict) -> float:
        calls.append("broken")
        raise RuntimeError("peer: crashed\nlast line: out of memory")

    case = Case(
        name="toy",
        title="toy",
        setup=lambda cfg: {},
        implementations={"ours": ours, "broken": broken},
    )
    res = run_case(case, Config(repeats=3))
    assert calls == ["ours", "broken", "ours", "ours"]  # repeat 2 starts with the broken one
    assert res.results["broken"].error == "RuntimeError: last line: out of memory"
    assert res.results["broken"].times_s == []
    assert res.results["ours"].error is None and len(res.results["ours"].times_s) == 3
    assert res.ratios() == {}  # no ratio to a failed peer
    assert res.to_dict()["implementations"][1]["error"].startswith("RuntimeError")


def test_runner_writes_json_and_markdown(tmp_path) -> None:
    out = tmp_path / "results"
    rc = main(
        ["--quick", "--size", "48x32", "--repeats", "1", "--only", "merge-hat", "-o", str(out)]
    )
    assert rc == 0
    data = json.loads((out / "results.json").read_text())
    (case,) = data["cases"]
    impls = {i["name"]: i for i in case["implementations"]}
    assert {"photoquant", "OpenCV MergeDebevec"} <= set(impls)
    # the hat merge with the true response is accurate to a few % at 48x32 (8-bit
    # quantisation and shot noise of one frame per exposure), far from a broken merge
    assert impls["photoquant"]["accuracy"]["median_err_pct"] < 5.0
    assert "| HDR merge (hat) | photoquant |" in (out / "results.md").read_text()


def test_a_subset_never_replaces_the_stored_whole_run(tmp_path, monkeypatch) -> None:
    """``--only`` without ``-o`` writes ``benchmarks/partial-results``: the stored whole run,
    which the documentation's table is generated from, is left as it was, and its folder
    holds that run alone."""
    monkeypatch.chdir(tmp_path)
    stored = tmp_path / "benchmarks" / "results"
    stored.mkdir(parents=True)
    (stored / "results.json").write_text("the whole run")
    assert main(["--quick", "--size", "48x32", "--repeats", "1", "--only", "merge-hat"]) == 0
    assert (stored / "results.json").read_text() == "the whole run"
    assert sorted(p.name for p in stored.iterdir()) == ["results.json"]
    data = json.loads((tmp_path / "benchmarks" / "partial-results" / "results.json").read_text())
    assert [c["name"] for c in data["cases"]] == ["merge-hat"]


def test_user_path_rows_are_listed_apart() -> None:
    from benchmarks.harness import discover

    cases = discover(Config(quick=True))
    user = [c.name for c in cases if c.user_path]
    assert {
        "calibrate-view-K8",
        "calibrate-view-K4",
        "calibrate-files",
        "correct-defaults-exact",
        "correct-defaults-jittered",
    } <= set(user)
    assert {"response", "calibrate-paper", "merge-hat", "correct"}.isdisjoint(user)


def test_user_path_rows_run_and_come_first(tmp_path) -> None:
    """The public API with its defaults and the CLI as a subprocess, at a tiny size."""
    out = tmp_path / "results"
    only = ["merge-hat", "calibrate-view-K4", "calibrate-files", "correct-defaults-exact"]
    rc = main(["--quick", "--size", "64x48", "--repeats", "1", "--only", *only, "-o", str(out)])
    assert rc == 0
    data = json.loads((out / "results.json").read_text())
    names = [c["name"] for c in data["cases"]]
    assert names == ["calibrate-view-K4", "calibrate-files", "correct-defaults-exact", "merge-hat"]
    for case in data["cases"]:
        for impl in case["implementations"]:
            assert impl["error"] is None, (case["name"], impl)
            assert len(impl["times_s"]) == 1
    files = next(c for c in data["cases"] if c["name"] == "calibrate-files")
    lib, cli = files["implementations"]
    assert "subprocess" in cli["name"]
    # the command wrote the camera the library call returns
    assert cli["accuracy"] == pytest.approx(lib["accuracy"])
    md = (out / "results.md").read_text()
    assert md.index("## On the user's path") < md.index("## Breakdown")
    assert md.index("| pq.calibrate([stack])") < md.index("## Breakdown") < md.index("| HDR merge")
