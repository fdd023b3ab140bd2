"""Resident memory of the long validation jobs."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable
from typing import Any

__all__ = ["return_free_memory"]


@functools.cache
def _malloc_trim() -> Callable[[int], Any] | None:
    """glibc's ``malloc_trim``, or ``None`` where the C library is not glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None


def return_free_memory() -> None:
    """Give the memory the allocator holds free back to the system (glibc's
    ``malloc_trim``; nothing elsewhere).

    Called between experiments and between a board's methods: their arrays are freed when
    they end, but glibc keeps freed blocks below its mmap threshold (which rises towards
    32 MiB as large arrays are freed) in its heap, so the resident memory of a long run
    grows by what the next step happens not to reuse (0.3–0.5 GB an experiment at
    1024×768, measured).
    """
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
