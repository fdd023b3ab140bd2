"""The sweep's local workers keep their log lines out of the user's terminal."""

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
