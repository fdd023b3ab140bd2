"""Threads for the array work that releases the GIL (numpy samplers and ufuncs, OpenCV codecs)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from photoquant._checks import check_workers

__all__ = ["even_spans", "thread_map"]

T = TypeVar("T")


def thread_map(fn: Callable[[Any], T], items: Iterable[Any], workers: int | None = None) -> list[T]:
    """``[fn(item) for item in items]`` on ``workers`` threads (every CPU by default).

    Results come in the order of ``items``, and the first exception in that
    order is raised; with one worker or one item nothing is threaded.
    """
    jobs = list(items)
    n_workers = min(check_workers(workers), len(jobs))
    if n_workers <= 1:
        return [fn(job) for job in jobs]
    with ThreadPoolExecutor(max_workers=n_workers) as pool:
        return list(pool.map(fn, jobs))


def even_spans(n: int, parts: int) -> list[slice]:
    """``[0, n)`` cut into ``parts`` consecutive slices of nearly equal length (work for
    :func:`thread_map`; fewer when ``n < parts``, none empty unless ``n`` is 0)."""
    parts = max(1, min(int(parts), n))
    bounds = [n * i // parts for i in range(parts + 1)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
