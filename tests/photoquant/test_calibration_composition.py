"""``calibrate`` is a composition of named steps (:mod:`photoquant.calibration_steps`).

Its body stays within :data:`MAX_CALIBRATE_LINES` lines: it checks the inputs,
composes the steps and returns the camera. (``tools/calibration_digests.py``
checks that a refactoring of the steps keeps every bit.)
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from collections.abc import Callable
from typing import Any

from photoquant import calibration

MAX_CALIBRATE_LINES = 60


def _body_lines(function: Callable[..., Any]) -> int:
    """Source lines of ``function``'s body, its docstring left out."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]
    return body[-1].end_lineno - body[0].lineno + 1


def test_calibrate_stays_a_composition_that_fits_on_a_screen():
    lines = _body_lines(calibration.calibrate)
    assert lines <= MAX_CALIBRATE_LINES, (
        f"calibrate() has {lines} lines of body (at most {MAX_CALIBRATE_LINES}): it checks the "
        "inputs and composes the named steps of photoquant.calibration_steps; put new work in "
        "a step (or a new step there), not in calibrate()"
    )


def test_the_line_count_sees_a_long_body():
    def long(x: int) -> int:
        """Docstring."""
        x += 1
        x += 2
        x += 3
        return x

    assert _body_lines(long) == 4
