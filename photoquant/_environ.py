"""The environment variables photoquant reads, checked before a command runs.

A variable read deep inside the work (``PHOTOQUANT_MAX_PIXELS`` by every
image reader) would otherwise fail only there: once per frame, or once per
cell of a sweep on every worker. The command-line entry points call
:func:`check_environment` after parsing their arguments, so that a malformed
value is one line and exit status 2 before anything is read or written.
"""

from __future__ import annotations

import os
from collections.abc import Callable

__all__ = ["ENVIRONMENT_CHECKS", "check_environment", "prefer_small_pages"]


def _max_pixels() -> None:
    from photoquant.io.images import max_pixels_limit

    max_pixels_limit()


#: Variable name → a function that raises :class:`~photoquant.errors.InputError` for a bad value.
ENVIRONMENT_CHECKS: dict[str, Callable[[], None]] = {"PHOTOQUANT_MAX_PIXELS": _max_pixels}


def check_environment() -> None:
    """Check every variable of :data:`ENVIRONMENT_CHECKS` (the first bad one raises).

    Raises
    ------
    InputError
        One line naming the variable and its value.
    """
    for check in ENVIRONMENT_CHECKS.values():
        check()


#: numpy's variable: ``0`` stops it advising huge pages for its large arrays (read at import).
HUGEPAGE_VARIABLE = "NUMPY_MADVISE_HUGEPAGE"


def prefer_small_pages() -> bool:
    """Stop numpy advising transparent huge pages for this process's large arrays.

    On Linux, numpy asks the kernel for transparent huge pages
    (``madvise(MADV_HUGEPAGE)``) for every array of 4 MiB or more. A command
    touches most of its memory once, fresh, and the kernel zeroes a huge page
    whole at its first touch. Measured on a 2-core virtual machine
    (2026-12-07), ``photoquant calibrate`` at the paper's settings (V = 3,
    K = 8, N = 10, 1024×768 PNG frames): 21 % of the command's CPU samples in
    the kernel's page clearing with the advice, 2 % without; 2.6–3.1 s of
    system time against 1.3–1.5 s, and 6.5–6.9 s against 5.5–6.5 s from
    start to camera written (four runs each). A correction repeated in one
    process, which reuses its memory, ran as fast either way. The command-line
    entry points call this before any work; a library call never does (the
    process is the caller's).

    The user's choice wins: where ``NUMPY_MADVISE_HUGEPAGE`` is set, nothing
    changes. Otherwise the variable is set to ``0`` as well, so that the
    processes a command starts (a sweep's workers, the validation job's
    second process) read the same.

    Returns
    -------
    bool
        Whether the advice was turned off (False where the user set the
        variable, or numpy has no such switch).
    """
    if HUGEPAGE_VARIABLE in os.environ:
        return False
    import numpy as np

    # numpy's own switch for the variable it reads at import (numpy._core from 2.0)
    core = getattr(np, "_core", None) or getattr(np, "core", None)
    switch = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if switch is None:  # pragma: no cover - a numpy without it
        return False
    os.environ[HUGEPAGE_VARIABLE] = "0"
    switch(False)
    return True
