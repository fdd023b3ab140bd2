"""The thread helpers: spans of work for the threads, and the map over threads."""

from __future__ import annotations

import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from photoquant._threads import BackgroundMap, even_spans, thread_map


@given(n=st.integers(0, 10_000), parts=st.integers(1, 64))
def test_even_spans_cover_the_range_once_in_order(n, parts):
    spans = even_spans(n, parts)
    assert len(spans) == max(1, min(parts, n))
    assert spans[0].start == 0 and spans[-1].stop == n
    assert all(a.stop == b.start for a, b in zip(spans[:-1], spans[1:], strict=True))
    sizes = [s.stop - s.start for s in spans]
    assert max(sizes) - min(sizes) <= 1  # nearly equal
    assert n == 0 or min(sizes) >= 1


@given(n=st.integers(0, 40), workers=st.integers(1, 4))
def test_thread_map_returns_every_result_in_order(n, workers):
    assert thread_map(lambda i: i * i, range(n), workers) == [i * i for i in range(n)]


def test_thread_map_runs_jobs_on_the_caller_and_on_other_threads():
    # two jobs that each wait for the other: they finish only when run at the same time
    barrier = threading.Barrier(2, timeout=10)
    names = thread_map(lambda _: (barrier.wait(), threading.current_thread().name)[1], range(2), 2)
    assert threading.current_thread().name in names and len(set(names)) == 2


def test_thread_map_raises_the_first_error_in_order_and_starts_nothing_after_one():
    started = []
    second_failed = threading.Event()

    def job(i: int) -> int:
        started.append(i)
        if i == 1:
            second_failed.set()
            raise ValueError("job 1")
        if i == 0:  # fails after job 1 has failed: still the first in order
            assert second_failed.wait(10)
            raise KeyError("job 0")
        return i

    with pytest.raises(KeyError, match="job 0"):
        thread_map(job, range(50), 2)
    assert sorted(started) == [0, 1]  # no job taken after job 1 failed


def test_thread_map_raises_an_interrupt_before_the_errors_of_jobs():
    interrupted = threading.Event()

    def job(i: int) -> None:
        if i == 0:  # fails after job 1 was interrupted
            assert interrupted.wait(10)
            raise ValueError("job 0")
        interrupted.set()
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        thread_map(job, range(2), 2)


def _wait_until(condition, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.001)


def test_a_switched_map_runs_the_items_begun_again_with_the_new_context_after_the_others():
    log = []
    hold = threading.Event()

    def fn(item: int, context: str, again: bool) -> str:
        log.append(("start", item, context, again))
        if (item, context) == (0, "a"):  # still running when the context switches
            assert hold.wait(10)
        log.append(("end", item, context))
        return f"{item}{context}"

    begun = BackgroundMap(fn, range(4), "a", threads=1)
    _wait_until(lambda: ("start", 0, "a", False) in log)  # the thread holds item 0
    begun.switch("b")
    threading.Timer(0.05, hold.set).start()  # item 0's first run ends while the others run
    assert begun.finish() == ["0b", "1b", "2b", "3b"]
    assert ("start", 0, "b", True) in log  # run again, told so
    assert log.index(("end", 0, "a")) < log.index(("start", 0, "b", True))  # after the first
    assert {entry[1] for entry in log if entry[2] == "a"} == {0}  # the rest with "b" only
    assert sum(entry[0] == "start" for entry in log) == 5


def test_an_error_of_the_switched_context_is_dropped_and_the_threads_start_again():
    failed = threading.Event()

    def fn(item: int, context: str, again: bool) -> tuple[int, str, bool]:
        if context == "a" and item == 1:
            failed.set()
            raise ValueError("with context a")
        return item, context, again

    begun = BackgroundMap(fn, range(3), "a", threads=1)
    assert failed.wait(10)
    begun._threads[0].join(10)  # the thread took no item after the failure and ended
    assert not begun._threads[0].is_alive()
    begun.switch("b")
    assert len(begun._threads) == 2  # one thread started again for the items left
    assert begun.finish() == [(0, "b", True), (1, "b", True), (2, "b", False)]


def test_a_stopped_map_begins_nothing_more_and_leaves_no_thread():
    started = []
    hold = threading.Event()

    def fn(item: int, context: None, again: bool) -> None:
        started.append(item)
        assert hold.wait(10)

    before = threading.active_count()
    begun = BackgroundMap(fn, range(5), None, threads=2)
    _wait_until(lambda: len(started) == 2)
    threading.Timer(0.02, hold.set).start()
    begun.stop()
    assert sorted(started) == [0, 1]  # the two running ended; none begun after
    assert threading.active_count() <= before + 1  # the timer's thread at most
