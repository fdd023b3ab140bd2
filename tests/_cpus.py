"""The CPUs of the test suite's workers: each bound to its share, and given them all back.

``tests/conftest.py`` binds each pytest-xdist worker to its share of the CPUs
(:func:`bind_worker`); a test, or a module fixture, of what runs on more
than one CPU (a second process, threads over tiles) takes every CPU of the
suite for its duration with :func:`every_cpu`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from validation._cpus import worker_share

SUITE_CPUS: list[int] = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_setaffinity") else []
"""The CPUs the suite may run on, as the process found them on import (before any binding)."""


def bind_worker(workers: int, worker: str) -> int | None:
    """Bind this process, pytest-xdist's ``worker`` (``"gw0"``, ...) of ``workers``, to its
    share of :data:`SUITE_CPUS`; the CPUs it got, ``None`` where it cannot be bound."""
    if not SUITE_CPUS or not (worker.startswith("gw") and worker[2:].isdigit()):
        return None
    share = worker_share(SUITE_CPUS, workers, int(worker[2:]))
    os.sched_setaffinity(0, share)
    return len(share)


@contextlib.contextmanager
def every_cpu() -> Iterator[None]:
    """Every CPU of the suite for the block (and the processes it starts), this
    process's share restored after it."""
    if not SUITE_CPUS:
        yield
        return
    share = os.sched_getaffinity(0)
    os.sched_setaffinity(0, set(SUITE_CPUS))
    try:
        yield
    finally:
        os.sched_setaffinity(0, share)
