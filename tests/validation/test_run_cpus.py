"""The CPUs of a validation run's two processes: each bound to its share while both work,
and every CPU given back."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

import validation.experiments as experiments
from tests._cpus import SUITE_CPUS
from validation._cpus import split_cpus
from validation.config import TINY
from validation.experiments import run_validation
from validation.experiments.base import ExperimentResult

pytestmark = pytest.mark.skipif(
    len(SUITE_CPUS) < 2, reason="needs two CPUs and a system that binds processes to them"
)


def _sleeper() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])


def test_each_process_gets_its_share_and_both_get_every_cpu_back(all_cpus):
    every = set(SUITE_CPUS)
    child = _sleeper()
    try:
        split = split_cpus(child.pid)
        assert os.sched_getaffinity(0) == set(SUITE_CPUS[0::2])
        assert os.sched_getaffinity(child.pid) == set(SUITE_CPUS[1::2])
        split.rejoin()
        assert os.sched_getaffinity(0) == every
        assert os.sched_getaffinity(child.pid) == every
        split.rejoin()  # a second time: nothing
        assert os.sched_getaffinity(0) == every
        # the other ends before the split is undone: this process gets its CPUs back
        split = split_cpus(child.pid)
        child.kill()
        child.wait()
        split.rejoin()
        assert os.sched_getaffinity(0) == every
    finally:
        child.kill()
        child.wait()
    # a process that has ended is not split with: this one keeps every CPU
    split = split_cpus(child.pid)
    assert os.sched_getaffinity(0) == every
    split.rejoin()
    assert os.sched_getaffinity(0) == every


def _wait_for(path: Path) -> bool:
    deadline = time.monotonic() + 60
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    return path.exists()


def _meeting_experiment(name: str, other: str, folder: Path) -> types.ModuleType:
    """An experiment that notes the CPUs it runs on once the other process's has begun
    (the first process's begins after the split), then waits until the other has noted
    its own: both noted while both processes work."""
    module = types.ModuleType(f"_fake_experiment_{name}")
    module.TITLE = name

    def run(config, seed, workdir, *, shared=None):
        res = ExperimentResult(name, name, "")
        (folder / f"{name}-begun").touch()
        res.paper["met"] = _wait_for(folder / f"{other}-begun")
        res.paper["cpus"] = sorted(os.sched_getaffinity(0))
        (folder / f"{name}-noted").touch()
        res.paper["met"] &= _wait_for(folder / f"{other}-noted")
        return res

    module.run = run
    return module


def test_a_two_process_run_splits_the_cpus_and_gives_the_caller_its_own_back(
    all_cpus, tmp_path, monkeypatch
):
    first = _meeting_experiment("first", "second", tmp_path)
    second = _meeting_experiment("second", "first", tmp_path)
    for module in (first, second):
        monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(
        experiments,
        "EXPERIMENTS",
        {"first": first.__name__, "second": second.__name__},
    )
    monkeypatch.setattr(experiments, "BESIDE", ("second",))
    # no preset calibrated before the fork: the fake experiments read none
    monkeypatch.setattr(experiments, "_calibrate_or_remember", lambda shared, preset: None)
    before = os.sched_getaffinity(0)
    run = run_validation(TINY, 0, workers=2, workdir=tmp_path / "w", progress=lambda _m: None)
    assert os.sched_getaffinity(0) == before
    mine, theirs = run.experiments["first"].paper, run.experiments["second"].paper
    assert mine["met"] and theirs["met"]
    assert mine["cpus"] == SUITE_CPUS[0::2]
    assert theirs["cpus"] == SUITE_CPUS[1::2]


_BOUND_WORKER = """
import os, sys, threading, types
from validation.sweep.worker_logs import WorkerCpus
seen, go = [], threading.Event()
def early():  # started before the binding: bound with the rest of the process
    go.wait()
    seen.append(sorted(os.sched_getaffinity(0)))
thread = threading.Thread(target=early)
thread.start()
WorkerCpus(int(sys.argv[1])).setup(types.SimpleNamespace(name=int(sys.argv[2])))
go.set()
thread.join()
later = threading.Thread(target=lambda: seen.append(sorted(os.sched_getaffinity(0))))
later.start()
later.join()
print(sorted(os.sched_getaffinity(0)), *seen)
"""


@pytest.mark.parametrize("workers", [1, 2])
def test_a_sweep_worker_and_all_its_threads_run_on_its_share(all_cpus, workers):
    for index in range(workers):
        out = subprocess.run(
            [sys.executable, "-c", _BOUND_WORKER, str(workers), str(index)],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).parents[2],
        ).stdout.split("] [")
        share = SUITE_CPUS if workers == 1 else SUITE_CPUS[index::workers]
        expected = str(share).strip("[]")
        assert [part.strip("[]\n") for part in out] == [expected] * 3


def _figure_experiment(name: str, wait_for: Path | None) -> types.ModuleType:
    """An experiment with one small map figure; it waits for ``wait_for`` to exist first."""
    import numpy as np

    from validation.experiments.base import FigureSpec

    module = types.ModuleType(f"_fake_experiment_{name}")
    module.TITLE = name

    def run(config, seed, workdir, *, shared=None):
        if wait_for is not None:
            _wait_for(wait_for)
        res = ExperimentResult(name, name, "")
        image = np.random.default_rng(len(name)).random((12, 16))
        panel = {"title": "t", "image": image, "vmin": 0.0, "vmax": 1.0}
        res.figures.append(FigureSpec(f"{name}_map", "maps", name, "", {"panels": [panel]}))
        return res

    module.run = run
    return module


def test_the_second_process_done_first_draws_its_figures_while_the_first_works(
    all_cpus, tmp_path, monkeypatch
):
    pytest.importorskip("matplotlib")
    import validation.figures as figures

    drawn = tmp_path / "drawn"
    # the first process's experiment ends only once the second has drawn
    first = _figure_experiment("first", drawn)
    second = _figure_experiment("second", None)
    for module in (first, second):
        monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(
        experiments, "EXPERIMENTS", {"first": first.__name__, "second": second.__name__}
    )
    monkeypatch.setattr(experiments, "BESIDE", ("second",))
    monkeypatch.setattr(experiments, "_calibrate_or_remember", lambda shared, preset: None)
    draw_while = figures.draw_while

    def noted(results, go_on):  # its drawing done, noted in a file (the second's first)
        count = draw_while(results, go_on)
        drawn.touch()
        return count

    monkeypatch.setattr(figures, "draw_while", noted)
    run = run_validation(TINY, 0, workers=2, workdir=tmp_path / "w", progress=lambda _m: None)
    res = run.experiments["second"]
    assert list(res.drawn) == ["second_map"]
    assert res.drawn["second_map"] == figures.figure_png(res.figures[0])
