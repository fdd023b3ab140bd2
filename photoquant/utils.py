"""Stable helpers for packages built on photoquant (input checks, JSON values, threads).

This is the public home of the small infrastructure functions that photoquant
uses at its own public boundary and that other packages (the synthetic camera
``pqsim``, ``validation``, plug-ins) may rely on: their names, signatures and
error behaviour are kept stable. The implementations live in private modules
(``photoquant._checks``, ``photoquant._json``, ``photoquant._threads``), which
other packages must not import: they may change with photoquant's internals.
None of these helpers holds method code (response, merge, vignetting ...), so
importing this module does not tie a caller to the calibrator's model.

Input checks (each raises :class:`~photoquant.errors.InputError` with a message
naming the argument, never a numpy traceback):

- :func:`check_array` — an array of a given rank, shape and dtype kind.
- :func:`check_int` — an integer (not a bool, not a float) within optional bounds.
- :func:`check_positive` — a finite positive (or non-negative) number.
- :func:`check_exposure_times` — exposure times: finite, positive, unique seconds.
- :func:`check_bit_depth` — a bit depth between 8 and 16.
- :func:`check_workers`, :func:`default_workers` — a thread count (every CPU by default).
- :func:`validate_method` — a registry key looked up case-insensitively, the
  error listing the valid names.

Other helpers:

- :func:`emor_basis` — the EMoR basis of real camera responses shipped in the package (data, Grossberg & Nayar 2004).
- :func:`to_json_value` — numpy scalars and arrays, tuples and paths as plain JSON values.
- :func:`thread_map` — ``[fn(x) for x in items]`` on threads, in order.
- :func:`handle_signals`, :class:`Terminated` — SIGTERM and Ctrl-C as clean exits (temporaries removed), for a command's ``main()``.
- :func:`safe_stdio` — standard output and error that print any text whatever the locale,
  :func:`check_environment` — photoquant's environment variables checked before a command runs, and
  :func:`prefer_small_pages` — a command's process without numpy's huge-page advice.

Examples
--------
>>> from photoquant.utils import check_int, to_json_value
>>> check_int(3, "repeats", 1)
3
>>> check_int(True, "repeats", 1)
Traceback (most recent call last):
    ...
photoquant.errors.InputError: `repeats` must be an integer >= 1, got True
>>> import numpy as np
>>> to_json_value({"t": np.array([0.5, 1.0]), "n": np.int64(4)})
{'t': [0.5, 1.0], 'n': 4}
"""

from __future__ import annotations

from photoquant._checks import (
    check_array,
    check_bit_depth,
    check_exposure_times,
    check_int,
    check_positive,
    check_workers,
    default_workers,
    validate_method,
)
from photoquant._emor_data import emor_basis
from photoquant._environ import check_environment, prefer_small_pages
from photoquant._json import load_json, to_json_value
from photoquant._signals import Terminated, handle_signals
from photoquant._stdio import safe_stdio
from photoquant._threads import thread_map

__all__ = [
    "safe_stdio",
    "check_environment",
    "prefer_small_pages",
    "load_json",
    "Terminated",
    "handle_signals",
    "check_array",
    "check_bit_depth",
    "check_exposure_times",
    "check_int",
    "check_positive",
    "check_workers",
    "default_workers",
    "emor_basis",
    "thread_map",
    "to_json_value",
    "validate_method",
]
