"""The hypothesis profile CI runs under (selected by ``HYPOTHESIS_PROFILE`` in ``.ci/run``)."""

from __future__ import annotations

import os
import re
from pathlib import Path

from hypothesis import settings

REPO = Path(__file__).resolve().parents[1]


def test_ci_profile_is_derandomised_without_a_database():
    ci = settings.get_profile("ci")
    assert ci.derandomize is True
    assert ci.database is None


def test_the_selected_profile_is_in_force():
    expected = settings.get_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
    assert settings.default.derandomize == expected.derandomize
    assert settings.default.database == expected.database


def test_ci_script_selects_the_ci_profile_and_runs_the_readme_command():
    script = (REPO / ".ci" / "run").read_text()
    lines = [line.strip() for line in script.splitlines() if not line.lstrip().startswith("#")]
    assert "export HYPOTHESIS_PROFILE=ci" in lines
    # the profile is exported before the README's test command, which is the last line
    assert lines.index("export HYPOTHESIS_PROFILE=ci") < len(lines) - 1
    assert [line for line in lines if line][-1] == "python -m pytest"
    for check in ("ruff check .", "ruff format --check .", "mypy photoquant"):
        assert check in lines
    assert any(re.fullmatch(r"python -m pytest --doctest-modules photoquant.*", x) for x in lines)


def test_the_files_started_first_exist():
    # a renamed file would silently fall back to the collected order
    from tests.conftest import RUN_FIRST

    assert len(set(RUN_FIRST)) == len(RUN_FIRST)
    missing = [name for name in RUN_FIRST if not (REPO / name).is_file()]
    assert not missing, missing
