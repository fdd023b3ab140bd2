"""The sweep's local workers: their log lines out of the user's terminal, each on its
share of the CPUs."""

from __future__ import annotations

import logging
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin


class QuietWorkerLogs(WorkerPlugin):
    """A Dask worker plugin: the local cluster's workers log nothing to the terminal.

    ``LocalCluster(silence_logs=...)`` quiets a worker's handlers only while
    it runs: they are restored when it closes, and a heartbeat that races the
    scheduler's close then prints a traceback under the sweep's one-line
    message. The plugin raises the level of the worker's ``distributed``
    logger for the life of its process instead. A cell that fails is reported
    through its part's status and error, not through the log. Only the sweep's
    own local cluster gets it; a user's scheduler keeps its logging.
    """

    def setup(self, worker: Any) -> None:  # noqa: ARG002 - the same for every worker
        logging.getLogger("distributed").setLevel(logging.CRITICAL + 1)


class WorkerCpus(WorkerPlugin):
    """A Dask worker plugin: worker ``i`` of the local cluster's ``workers`` bound to its
    share of the CPUs (:func:`validation._cpus.worker_share`).

    A cell's calibration spreads its array work over the CPUs its process may
    use; with every worker on every CPU, the workers' threads outnumber the
    CPUs and wait for each other (:mod:`validation._cpus`). Only the sweep's own
    local cluster gets it, whose workers are named ``0 … workers − 1``; a
    worker of another name keeps every CPU.
    """

    def __init__(self, workers: int) -> None:
        self.workers = int(workers)

    def setup(self, worker: Any) -> None:
        import os

        from validation._cpus import bind_process, worker_share

        if not hasattr(os, "sched_getaffinity") or not isinstance(worker.name, int):
            return
        cpus = sorted(os.sched_getaffinity(0))
        share = worker_share(cpus, self.workers, worker.name)
        if share != set(cpus):
            bind_process(share)
