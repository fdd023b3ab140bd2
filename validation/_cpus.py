"""The CPUs of the validation jobs' processes: each bound to its share while they all work.

A calibration spreads its array work over the CPUs its process may use
(:func:`photoquant._threads.thread_map`, as many threads as CPUs). With two
processes working at once on a machine's CPUs, each process's threads would
take every CPU and the two sets share them: more threads than CPUs, which wait
for each other at every step. Bound to half the CPUs each, each process runs
one thread a CPU; measured on the quick job (2 CPUs, four runs each,
interleaved, 2026-12-07): every experiment 8–12 % faster, the job 37.8–42.1 s
against 41.3–42.6 s (in a slower hour, 52.6–52.9 s against 55.8–59.0 s), the
same metrics. The sweep's local Dask workers, one
cell each at a time, are bound the same way (:func:`bind_process`, from the
worker plugin :class:`validation.sweep.worker_logs.WorkerCpus`): the example
sweep 12.7–13.6 s against 13.3–14.0 s (three runs each, interleaved).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = ["CpuSplit", "bind_process", "split_cpus", "worker_share"]


def worker_share(cpus: list[int], workers: int, index: int) -> set[int]:
    """The CPUs of worker ``index`` of ``workers``: every ``workers``-th of ``cpus`` from
    its own (the first workers one more where they do not divide), one where there are
    more workers than CPUs (a CPU shared, as the scheduler would share it).

    Examples
    --------
    >>> worker_share([0, 1, 2, 3], 2, 1)
    {1, 3}
    >>> worker_share([0, 1], 3, 2)
    {0}
    """
    if workers >= len(cpus):
        return {cpus[index % len(cpus)]}
    return set(cpus[index::workers])


def bind_process(cpus: set[int]) -> bool:
    """Bind every thread of this process to ``cpus`` (the threads it starts later inherit
    their starter's CPUs); ``False`` where the system cannot (not Linux)."""
    if not hasattr(os, "sched_setaffinity"):
        return False
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for thread in threads:
        try:
            os.sched_setaffinity(thread, cpus)
        except OSError:  # a thread that has ended since the listing
            pass
    return True


@dataclass
class CpuSplit:
    """This process and another bound to their shares of this process's CPUs, until
    :meth:`rejoin` gives both of them every CPU again.

    ``cpus`` are this process's CPUs before the split (empty: nothing was split).
    """

    cpus: frozenset[int]
    other: int

    def rejoin(self) -> None:
        """Every CPU of the split back to this process and to the other (which may have
        ended already); nothing happens a second time."""
        if not self.cpus:
            return
        cpus, self.cpus = self.cpus, frozenset()
        os.sched_setaffinity(0, cpus)
        try:
            os.sched_setaffinity(self.other, cpus)
        except OSError:  # it has ended: nothing to give back
            pass


def split_cpus(other: int) -> CpuSplit:
    """Bind this process to every second of its CPUs from the first, and process ``other``
    to the rest (the other one more on an odd count); nothing changes where there is
    one CPU, where the system cannot bind processes, or where ``other`` has ended."""
    if not hasattr(os, "sched_setaffinity"):
        return CpuSplit(frozenset(), other)
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return CpuSplit(frozenset(), other)
    try:
        os.sched_setaffinity(other, cpus[1::2])
    except OSError:  # it has ended (or may not be bound): this process keeps every CPU
        return CpuSplit(frozenset(), other)
    os.sched_setaffinity(0, cpus[0::2])
    return CpuSplit(frozenset(cpus), other)
