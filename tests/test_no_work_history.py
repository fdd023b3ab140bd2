"""The product carries no development history.

README, changelog, documentation, docstrings, messages and the report's text
speak to users: no issue numbers, no numbered development passes, no
"session", and no path to a local copy of the paper (the paper is cited by
its reference). ``benchmarks/results/`` keeps one run, not a history.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

HISTORY = re.compile(
    r"\b(issue|issues) [0-9]+\b"
    r"|\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth) pass\b"
    r"|\bsession\b",
    re.IGNORECASE,
)
LOCAL_PAPER = re.compile(r"shared/reference|paper\.txt")

# what users read: the packages, the README, the changelog and the documentation's sources
PRODUCT = ["README.md", "CHANGELOG.md", "docs", "photoquant", "pqsim", "validation"]
TEXT_SUFFIXES = {".py", ".md", ".rst", ".txt", ".toml", ".json", ".bib", ".cfg", ".css", ".html"}
SKIP_PARTS = {"_build", "auto_examples", "generated", "__pycache__", "gen_modules"}


def _product_files() -> list[Path]:
    files: list[Path] = []
    for name in PRODUCT:
        path = ROOT / name
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            for f in sorted(path.rglob("*")):
                rel = f.relative_to(ROOT)
                if f.is_file() and f.suffix in TEXT_SUFFIXES and not SKIP_PARTS & set(rel.parts):
                    files.append(f)
    return files


def _hits(pattern: re.Pattern[str]) -> list[str]:
    hits = []
    for f in _product_files():
        try:
            text = f.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if pattern.search(line):
                hits.append(f"{f.relative_to(ROOT)}:{n}: {line.strip()}")
    return hits


def test_files_to_check_are_found():
    names = {f.relative_to(ROOT).as_posix() for f in _product_files()}
    assert "README.md" in names
    assert "photoquant/__init__.py" in names
    assert "validation/report.py" in names


def test_no_issue_numbers_passes_or_sessions_in_the_product():
    hits = _hits(HISTORY)
    assert not hits, "development history in the product:\n" + "\n".join(hits)


def test_the_paper_is_cited_not_pointed_to_by_a_local_path():
    hits = _hits(LOCAL_PAPER)
    assert not hits, "a path to a local copy of the paper:\n" + "\n".join(hits)


def test_the_pattern_catches_what_it_is_for():
    for text in ("(issue 8)", "Issues 12 and", "the eighth pass", "this session's"):
        assert HISTORY.search(text), text
    for text in ("an issue with the input", "a pass over the frames", "passes 3 tests"):
        assert not HISTORY.search(text), text


def test_benchmark_results_keep_the_latest_run_only():
    results = ROOT / "benchmarks" / "results"
    if not results.is_dir():
        pytest.skip("no benchmarks/results folder (an installed package)")
    assert not [p.name for p in results.iterdir() if p.is_dir()], (
        "benchmarks/results/ keeps the latest run (results.json, results.md), not folders of past runs"
    )


def test_experiment_titles_carry_no_history():
    from validation.experiments import EXPERIMENTS

    for key in EXPERIMENTS:
        module = __import__(f"validation.experiments.{key}", fromlist=["TITLE"])
        title = getattr(module, "TITLE", "")
        assert not HISTORY.search(title), (key, title)
        assert "(issue" not in title.lower(), (key, title)
