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


def test_each_worker_gets_its_own_share_of_the_cpus():
    from tests._cpus import worker_share

    cpus = [0, 1, 2, 3, 4]
    shares = [worker_share(cpus, 2, i) for i in range(2)]
    assert shares == [{0, 2, 4}, {1, 3}]  # disjoint, every CPU, the first one more
    assert [worker_share(cpus[:2], 2, i) for i in range(2)] == [{0}, {1}]
    # more workers than CPUs: one each, shared in turn
    assert [worker_share([3, 7], 3, i) for i in range(3)] == [{3}, {7}, {3}]


def test_a_bound_worker_runs_on_its_share_and_every_cpu_gives_them_back():
    import pytest

    from tests._cpus import SUITE_CPUS, every_cpu

    if not SUITE_CPUS:
        pytest.skip("no CPU affinity on this platform")
    before = os.sched_getaffinity(0)
    assert before <= set(SUITE_CPUS)
    with every_cpu():
        assert os.sched_getaffinity(0) == set(SUITE_CPUS)
    assert os.sched_getaffinity(0) == before
