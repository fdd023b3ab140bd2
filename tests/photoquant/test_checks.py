"""The shared input checks: each refusal names the argument and the rule."""

from __future__ import annotations

import numpy as np
import pytest

from photoquant._checks import check_int, check_workers
from photoquant.errors import InputError


def test_check_int_bounds_and_types():
    assert check_int(np.int16(3), "n", 1, 3) == 3 and type(check_int(np.int64(2), "n")) is int
    for value, lo, hi, rule in [
        (0, 1, None, ">= 1"),
        (9, 1, 8, r"in \[1, 8\]"),
        (9, None, 8, "<= 8"),
        (True, None, None, ", got True"),
        (2.0, 1, None, ">= 1, got 2.0"),
    ]:
        with pytest.raises(InputError, match=f"`n` must be an integer ?{rule}"):
            check_int(value, "n", lo, hi)


def test_check_workers_defaults_to_the_cpus():
    assert check_workers(None) >= 1 and check_workers(3) == 3
    with pytest.raises(InputError, match=r"`workers` must be an integer in \[1, 1024\]"):
        check_workers(0)
