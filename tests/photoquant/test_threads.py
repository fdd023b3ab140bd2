"""The thread helpers: spans of work for the threads, and the map over threads."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from photoquant._threads import even_spans, thread_map


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
