"""``photoquant validate`` prints a compact summary; the tables are in the report."""

from __future__ import annotations

from types import SimpleNamespace

from validation.config import QUICK
from validation.experiments import EXPERIMENTS
from validation.experiments.base import ExperimentResult
from validation.headlines import MAX_LINES, format_summary

# The command's own summary of a tiny job (``photoquant validate --tiny``):
# tests/validation/test_validate_job.py::test_the_summary_is_short_and_names_the_report,
# which shares that job's run with the determinism test.


def _result(name: str, rows: list[tuple[str, str]]) -> ExperimentResult:
    res = ExperimentResult(name, f"{name} experiment", "")
    for quantity, ours in rows:
        res.row(quantity, ours, "–", "")
    return res


def test_every_experiment_at_once_stays_within_the_line_budget():
    experiments = {name: _result(name, [(f"{name}: a quantity", "1.0")]) for name in EXPERIMENTS}
    board = [(f"response: #{i} Method {i}", "0.1") for i in range(1, 13)]
    board += [(f"vignetting: #{i} Model {i}", "0.2") for i in range(1, 6)]
    board += [
        ("response: n/a Peer", "not installed (install: pip install colour-hdri)"),
        ("response: #13 Broken", "failed: ccd: it broke"),
        ("vignetting: n/a Flat Field", "n/a: needs a flat field"),
    ]
    experiments["leaderboard"] = _result("leaderboard", board)
    run = SimpleNamespace(config=QUICK, seed=0, elapsed_s=1.0, experiments=experiments)
    text = format_summary(run, report="validation-report/report.md")
    lines = text.splitlines()
    assert len(lines) <= MAX_LINES, text
    assert any("Method 1" in line for line in lines)
    assert any("1 failed" in line and "1 not installed" in line for line in lines), text
