"""Helpers for a user's own test suite: hold a method or a camera preset to a recorded baseline.

A baseline is recorded once with ``photoquant validate ... --write-baseline
FILE`` (any configuration, any registered method, plug-ins included); a
test then holds later versions of the method to it::

    from photoquant.testing import check_against_baseline

    def test_my_response_method_holds_its_baseline():
        check_against_baseline("my_method.baseline.json", methods={"response": "My Method"})

The run, the comparison and the baseline format belong to the validation
package (``validation.regression``), which drives the synthetic camera that
photoquant itself never imports. It is found through the entry-point group
:data:`ENTRY_POINT_GROUP` (``photoquant.testing``), which the photoquant
distribution declares for its validation package; without it the helper
says so in one line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import metadata
from os import PathLike
from typing import Any

from photoquant.errors import PhotoquantError

__all__ = ["ENTRY_POINT_GROUP", "TestingUnavailableError", "check_against_baseline"]

ENTRY_POINT_GROUP = "photoquant.testing"
"""Entry-point group of the testing helpers (``check_against_baseline``)."""


class TestingUnavailableError(PhotoquantError):
    """The package that runs the validation (``validation``) is not installed."""

    __test__ = False  # not a pytest test class


def _helper(name: str) -> Callable[..., Any]:
    found = [ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
    if not found:
        raise TestingUnavailableError(
            f"photoquant.testing.{name} needs the validation package, which is not installed "
            f"(no entry point {name!r} in group {ENTRY_POINT_GROUP!r}): pip install photoquant"
        )
    try:
        function = found[0].load()
    except ImportError as exc:
        raise TestingUnavailableError(
            f"photoquant.testing.{name}: the validation package failed to import: {exc}"
        ) from None
    if not callable(function):
        raise TestingUnavailableError(
            f"photoquant.testing.{name}: entry point {found[0].value!r} is not callable"
        )
    return function


def check_against_baseline(
    baseline: str | PathLike[str] | Mapping[str, Any] | None = None, **configuration: Any
) -> Any:
    """Run a validation configuration and compare its metrics with a recorded baseline.

    Parameters
    ----------
    baseline : path, mapping or None
        A baseline file written by ``photoquant validate --write-baseline``
        (format ``photoquant.validation-baseline/2``), a loaded one, or
        ``None`` for the baseline stored for ``mode``.
    **configuration
        ``mode`` (``"quick"``, ``"full"``), ``profile``, ``methods`` (step →
        method name, ``(name, options)`` or options), ``presets`` (names or
        preset files), ``chart``, ``rendered_capture``, ``experiments``;
        also ``seed`` (the baseline's by default) and ``junit`` (a JUnit XML
        report to write).

    Returns
    -------
    validation.baseline.CheckResult
        The comparison, when no metric regressed.

    Raises
    ------
    AssertionError
        Listing every regressed metric: its value, the baseline's and the tolerance.
    PhotoquantError
        When the baseline is not one, is of a newer format, was edited, or
        does not describe the configuration (before anything runs);
        :class:`TestingUnavailableError` when the validation package is missing.

    References
    ----------
    The tolerance of each metric is ``K`` seed-to-seed spreads
    (``validation.baseline``: 5 spreads over 8 seeds).
    """
    return _helper("check_against_baseline")(baseline, **configuration)
