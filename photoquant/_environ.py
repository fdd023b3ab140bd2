"""The environment variables photoquant reads, checked before a command runs.

A variable read deep inside the work (``PHOTOQUANT_MAX_PIXELS`` by every
image reader) would otherwise fail only there: once per frame, or once per
cell of a sweep on every worker. The command-line entry points call
:func:`check_environment` after parsing their arguments, so that a malformed
value is one line and exit status 2 before anything is read or written.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["ENVIRONMENT_CHECKS", "check_environment"]


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
