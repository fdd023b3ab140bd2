"""Shared fixtures and paths for the test suite."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from tests._cpus import SUITE_CPUS, bind_worker, every_cpu

# Property tests draw new examples on every run by default (and remember
# failures in .hypothesis/). CI selects "ci" (HYPOTHESIS_PROFILE=ci, set by
# .ci/run): examples derived from each test's own source, no example
# database, so that a CI run is reproducible and a statistical test cannot
# fail by the luck of the draw. Each test's own @settings (max_examples,
# deadline) still apply on top of the profile.
settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

_BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _share_the_cores_between_workers() -> None:
    """Each pytest-xdist worker on its share of the cores (``-n auto``): its threads and BLAS.

    Every calibration and correction spreads over the CPUs its process may
    run on (:func:`photoquant._checks.default_workers`), and OpenBLAS starts a
    thread per core in every process. With one worker per core, each
    worker's threads then compete with the other workers' for the same
    cores: threads waiting for each other spin (a least-squares solve of the
    size of the validation job's colour-hdri peer took 40 s instead of 6 s
    beside other busy processes), and a fit split over its channels on two
    threads on a core shared with another worker costs more than it saves.
    A worker is therefore bound to its share of the CPUs
    (:func:`tests._cpus.bind_worker`; the processes it starts inherit it),
    and its BLAS libraries get that many threads: those loaded already
    (numpy's) through threadpoolctl, those loaded later (scipy's) and
    subprocesses through the variables. Measured on the 2-core machine
    (2026-12-06, ``-n auto``): the suite 6 min 49 s – 7 min 45 s unbound,
    5 min 43 s – 5 min 53 s bound. A test of several processes or threads
    on several CPUs asks for them back (the :func:`all_cpus` fixture,
    :func:`tests._cpus.every_cpu`). Nothing changes in one process
    (``-n 0``) or where the variables are set already.
    """
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers <= 1 or any(v in os.environ for v in _BLAS_THREAD_VARIABLES):
        return
    from threadpoolctl import threadpool_limits

    bound = bind_worker(workers, os.environ.get("PYTEST_XDIST_WORKER", ""))
    threads = bound or max(1, (len(SUITE_CPUS) or os.cpu_count() or 1) // workers)
    for variable in _BLAS_THREAD_VARIABLES:
        os.environ[variable] = str(threads)
    threadpool_limits(limits=threads, user_api="blas")


_share_the_cores_between_workers()


@pytest.fixture
def all_cpus() -> Iterator[None]:
    """The test on every CPU of the suite (:func:`tests._cpus.every_cpu`): for a test of
    what runs on more than one CPU, such as a second process."""
    with every_cpu():
        yield


def pytest_configure(config: pytest.Config) -> None:
    """SIGINT delivered as from a terminal, however the suite was started, and the
    kernels compiled once for the whole suite (:func:`_compile_the_kernels_once`).

    A run started in the background of a non-interactive shell (``cmd &``, as
    a CI script may do) has SIGINT ignored; Python leaves it ignored and every
    child process inherits that, so the Ctrl-C tests of the write path
    (``tests/test_no_data_loss.py``, ``test_atomic.py``) would fail for a
    reason that is not theirs (seen in a dry run of ``.ci/run`` under nohup).
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    _compile_the_kernels_once(config)


def _compile_the_kernels_once(config: pytest.Config) -> None:
    """The whole suite (``python -m pytest``, its test paths) on an empty kernel cache
    (a clean clone): photoquant's kernels compiled once, on both cores, before the
    workers start (:func:`validation.compile_ahead.compile_both_ways`, the lists of
    the validation job and the demo).

    Each worker compiles the kernels its tests call; the longest files, started
    first on both workers (:data:`RUN_FIRST`), call the same calibration kernels at
    the same time, so each compiled them (numba compiles under a lock per process,
    not per cache). A worker that finds a kernel in the cache loads it. Measured on
    the 2-core machine, each suite from an empty cache, one after the other
    (2026-12-07): 7 min 19 s with it (the quick job's test 65 s, the leaderboard
    module's 22 s) against 7 min 32 s without (87 s and 47 s); it compiled for 12 s.
    Nothing is done in a worker, for a chosen set of tests (which may need no
    kernel), or where the cache holds them already.
    """
    if hasattr(config, "workerinput") or config.args_source != pytest.Config.ArgsSource.TESTPATHS:
        return
    from validation.compile_ahead import compile_both_ways, load_kernels

    try:
        kernels = load_kernels("validate")
        kernels += [k for k in load_kernels("demo") if k not in kernels]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return
    compile_both_ways(kernels, lambda note: print(f"tests: {note}", file=sys.stderr, flush=True))


REPO = Path(__file__).resolve().parents[1]
# ``../shared`` beside the checkout; PHOTOQUANT_SHARED points elsewhere (e.g. from a worktree)
SHARED = Path(os.environ.get("PHOTOQUANT_SHARED", REPO.parent / "shared"))
FROBISHER = SHARED / "data" / "real" / "frobisher_001"
MEMORIAL = SHARED / "data" / "real" / "memorial_debevec"


RUN_FIRST = (
    "tests/validation/test_validate_quick.py",
    "tests/validation/test_leaderboard.py",
    "tests/validation/test_validate_job.py",
    "tests/test_disturbance_combinations.py",
    "tests/photoquant/test_response_covariance.py",
    "tests/validation/test_sweep_robustness.py",
    "tests/test_plugins.py",
    "tests/test_no_data_loss.py",
    "tests/validation/test_sweep_run.py",
    "tests/validation/test_sweep_dask.py",
    "tests/photoquant/test_crossval.py",
    "tests/pqsim/test_twin_closed_loop.py",
    "tests/validation/test_twin_check.py",
)
"""The longest files, in the order they are started: those whose module fixtures run a
validation job or a whole leaderboard (the quick job the longest), then the others of
more than 20 s (summed test durations on 2 cores, 2026-12-06): longest first, so that
no long file is left for one worker to finish alone while the other waits."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The longest files first, each file's tests in their order.

    ``--dist loadfile --no-loadscope-reorder`` (``pyproject.toml``) hands the
    files to the workers in the order collected, and most of these come last
    (``tests/validation``; xdist's default order, most tests first, puts them
    last too): started first, they run while the other worker goes through
    the many short files, instead of after them.
    """
    del config
    first = {name: i for i, name in enumerate(RUN_FIRST)}

    def rank(item: pytest.Item) -> int:
        path = item.path.resolve()
        rel = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else ""
        return first.get(rel, len(RUN_FIRST))

    items.sort(key=rank)  # stable: the order within each group is kept


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: tests are deterministic."""
    return np.random.default_rng(20261126)


@pytest.fixture
def frobisher_dir() -> Path:
    """The real Canon bracket of ``../shared`` (skipped when absent)."""
    if not FROBISHER.is_dir():
        pytest.skip("../shared/data/real/frobisher_001 is not available")
    return FROBISHER
