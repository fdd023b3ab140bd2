"""The first run's helper: the recorded kernels match the code, compiling fills numba's
cache for another process, stale entries are skipped, the helper starts and stops."""

from __future__ import annotations

import inspect
import json
import multiprocessing
import os
import subprocess
import sys
import textwrap
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from tests._cpus import SUITE_CPUS, every_cpu  # noqa: E402
from validation.compile_ahead import (  # noqa: E402
    JOBS,
    KERNELS_FORMAT,
    KernelSignature,
    compile_ahead,
    load_kernels,
    record_kernels,
    resolve_kernel,
    start_compile_ahead,
    write_kernels,
)

INDICES_OF = KernelSignature(
    "photoquant._pair_kernels",
    "_indices_of",
    "(Array(bool, 1, 'C', False, aligned=True), Array(int64, 1, 'C', False, aligned=True))",
)
LONGEST_RUN = KernelSignature(
    "photoquant._pair_kernels", "_longest_run", "(Array(int64, 1, 'C', False, aligned=True), int64)"
)


@pytest.mark.parametrize("job", list(JOBS))
def test_the_recorded_kernels_name_compiled_kernels_with_their_number_of_arguments(job):
    kernels = load_kernels(job)
    assert len(kernels) >= 20  # the calibration's, the correction's, the uncertainty's
    assert len(set(kernels)) == len(kernels)
    for kernel in kernels:
        resolved = resolve_kernel(kernel)
        assert resolved is not None, kernel
        dispatcher, args = resolved
        assert len(args) == len(inspect.signature(dispatcher.py_func).parameters), kernel


def test_stale_entries_resolve_to_nothing_and_are_skipped():
    stale = [
        KernelSignature("photoquant.stack", "no_such_kernel", "(int64,)"),
        KernelSignature("photoquant.no_such_module", "_indices_of", "(int64,)"),
        KernelSignature(INDICES_OF.module, INDICES_OF.function, "(NoSuchType(1),)"),
    ]
    assert all(resolve_kernel(k) is None for k in stale)
    wrong_arity = KernelSignature(INDICES_OF.module, INDICES_OF.function, "(int64,)")
    assert resolve_kernel(wrong_arity) is not None
    assert compile_ahead([*stale, wrong_arity]) == 0  # numba refuses the types: skipped


def test_record_kernels_keeps_the_outermost_compilations_in_order():
    import numba

    @numba.njit
    def inner(x):
        return x + 1

    @numba.njit
    def outer(x):
        return inner(x) * 2

    def job():
        outer(1.5)
        inner(np.int64(2))
        outer(2.5)  # compiled already: not recorded again

    found = record_kernels(job)
    assert [(k.function.rsplit(".", 1)[-1], k.args) for k in found] == [
        ("outer", "(float64,)"),
        ("inner", "(int64,)"),
    ]
    assert all(k.module == __name__ for k in found)


def _in_fresh_process(cache: Path, *code: str) -> str:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run(
        [sys.executable, "-c", "\n".join(textwrap.dedent(part) for part in code)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return out.stdout.strip()


def test_compiled_ahead_kernels_are_loaded_by_another_process_from_the_cache(tmp_path):
    entries = f"""
        from validation.compile_ahead import KernelSignature, compile_ahead
        first = KernelSignature(*{astuple(INDICES_OF)!r})
        second = KernelSignature(*{astuple(LONGEST_RUN)!r})
    """
    compiled = _in_fresh_process(tmp_path, entries, "print(compile_ahead([first]))")
    assert compiled == "1"
    # another process: the first kernel is loaded, not compiled, and the helper stops
    # there (a cache an earlier run filled), leaving the second alone
    again = _in_fresh_process(
        tmp_path,
        entries,
        """
        from validation.compile_ahead import resolve_kernel
        print(compile_ahead([first, second]))
        dispatcher, _ = resolve_kernel(first)
        print(sum(dispatcher.stats.cache_hits.values()))
        dispatcher, _ = resolve_kernel(second)
        print(len(dispatcher.overloads))
        """,
    )
    assert again.split() == ["0", "1", "0"]


@pytest.mark.skipif(
    len(SUITE_CPUS) < 2 or "fork" not in multiprocessing.get_all_start_methods(),
    reason="the helper runs beside a job on a second core, started by fork",
)
def test_a_first_run_starts_the_helper_and_the_next_finds_its_work_cached(tmp_path):
    with every_cpu():  # the suite binds each worker to one CPU: the helper needs two
        out = _first_run_then_the_next(tmp_path)
    assert out.split() == ["False", "False", "True", "True", "0", "True", "True", "False", "True"]


def _first_run_then_the_next(tmp_path: Path) -> str:
    return _in_fresh_process(
        tmp_path,
        f"""
        from validation.compile_ahead import KernelSignature, is_cached, start_compile_ahead
        first = KernelSignature(*{astuple(INDICES_OF)!r})
        second = KernelSignature(*{astuple(LONGEST_RUN)!r})
        print(is_cached(first), is_cached(second))
        helper = start_compile_ahead([second, first])  # the last kernel first
        print(helper.first_run, helper.process is not None)
        helper.process.join(timeout=100)  # both compiled, then it ends
        print(helper.process.exitcode)
        helper.stop()
        print(is_cached(first), is_cached(second))
        again = start_compile_ahead([second, first])
        print(again.first_run, again.process is None)
        """,
    )


@pytest.mark.skipif(
    len(SUITE_CPUS) < 2 or "fork" not in multiprocessing.get_all_start_methods(),
    reason="the helper compiles beside this process on a second core, started by fork",
)
def test_compiling_both_ways_caches_every_kernel_once_and_then_nothing(tmp_path):
    third = KernelSignature(
        "photoquant._pair_kernels",
        "_longest_run",
        "(Array(int64, 1, 'A', False, aligned=True), int64)",
    )
    with every_cpu():
        out = _in_fresh_process(
            tmp_path,
            f"""
            from validation.compile_ahead import KernelSignature, compile_both_ways, is_cached
            kernels = [KernelSignature(*k) for k in {[astuple(k) for k in (INDICES_OF, LONGEST_RUN, third)]!r}]
            here = compile_both_ways(kernels)
            print(1 <= here <= 3, [is_cached(k) for k in kernels])
            print(compile_both_ways(kernels))  # all cached: nothing started, nothing compiled
            """,
        )
    assert out.splitlines() == ["True [True, True, True]", "0"]


def test_the_helper_starts_and_stops_and_starts_nothing_where_the_list_is_not_here():
    stale = KernelSignature("photoquant.stack", "no_such_kernel", "()")
    helper = start_compile_ahead([stale, INDICES_OF])  # its last kernel first
    process = helper.process
    if process is not None:  # two cores and fork
        helper.stop(wait_s=60.0)
        assert process.exitcode == 0
        assert helper.process is None
    helper.stop()  # a second stop does nothing
    # nothing to compile, or a last kernel that is not compiled here (numba missing or
    # turned off, a stale list): no process
    assert start_compile_ahead([]).process is None
    assert start_compile_ahead([INDICES_OF, stale]).process is None
    assert start_compile_ahead("no such job").process is None


def test_the_kernel_lists_round_trip_and_another_format_is_refused(tmp_path):
    path = tmp_path / "kernels.json"
    write_kernels(path, {"validate": [INDICES_OF, LONGEST_RUN], "demo": [LONGEST_RUN]})
    assert load_kernels("validate", path) == [INDICES_OF, LONGEST_RUN]
    assert load_kernels("demo", path) == [LONGEST_RUN]
    assert load_kernels("another job", path) == []
    data = json.loads(path.read_text())
    assert data["format"] == KERNELS_FORMAT
    assert data["jobs"]["validate"]["command"] == JOBS["validate"]
    data["format"] = "something else/1"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="not a photoquant.first-run-kernels/1 file"):
        load_kernels("validate", path)
