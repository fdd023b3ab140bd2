"""Resident memory of the long validation jobs."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable
from typing import Any

__all__ = ["KEPT_BLOCK_BYTES", "keep_freed_blocks", "return_free_memory"]


KEPT_BLOCK_BYTES = 64 * 2**20
"""Largest block the job's allocator serves from (and keeps in) its heap: see
:func:`keep_freed_blocks`."""

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
"""glibc's ``mallopt`` parameters (``malloc.h``)."""


@functools.cache
def _libc_function(name: str) -> Callable[..., Any] | None:
    """A glibc function, or ``None`` where the C library is not glibc or lacks it."""
    lib = ctypes.util.find_library("c")
    if lib is None:
        return None
    try:
        return getattr(ctypes.CDLL(lib), name)
    except (OSError, AttributeError):
        return None


def keep_freed_blocks() -> bool:
    """Let this process's allocator reuse freed blocks of up to :data:`KEPT_BLOCK_BYTES`.

    For the validation jobs, which own their process (called by the command,
    never by the library). glibc serves a block above its mmap threshold
    (which rises from 128 KiB to at most 32 MiB as such blocks are freed)
    with fresh pages from the system and returns them when it is freed, so
    every stack of floats a simulation or a calibration makes and drops is
    zeroed by the kernel again: on this project's 2-core machine first
    touching memory costs ~1.3 s of system time a GB. With the threshold at
    64 MiB and the heap trimmed only above 128 MiB free (measured
    2026-12-05, renders cached): the response experiment at the paper's size
    alone 69.2 → 65.0 s (system time 18.3 → 8.5 s); ``--full`` 673 → 633 s
    at a peak of 3.90 GB over its two processes (with 256 MiB: 629 s, but
    4.12 GB, above the job's 4 GB). The experiments still give the heap back
    between them (:func:`return_free_memory`), and the results are the same
    bits. Returns whether the settings were made (glibc only).
    """
    mallopt = _libc_function("mallopt")
    if mallopt is None:
        return False
    ok = mallopt(_M_MMAP_THRESHOLD, KEPT_BLOCK_BYTES)
    ok = mallopt(_M_TRIM_THRESHOLD, 2 * KEPT_BLOCK_BYTES) and ok
    return bool(ok)


def return_free_memory() -> None:
    """Give the memory the allocator holds free back to the system (glibc's
    ``malloc_trim``; nothing elsewhere).

    Called between experiments and between a board's methods: their arrays are freed when
    they end, but glibc keeps freed blocks below its mmap threshold (which rises towards
    32 MiB as large arrays are freed) in its heap, so the resident memory of a long run
    grows by what the next step happens not to reuse (0.3–0.5 GB an experiment at
    1024×768, measured).
    """
    trim = _libc_function("malloc_trim")
    if trim is not None:
        trim(0)
