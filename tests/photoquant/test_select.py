"""The compiled kernels' exact median (photoquant._select) against numpy's."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant import _select

_KERNELS = [pytest.param(False, id="python")]
if _select.HAVE_NUMBA:
    _KERNELS.append(pytest.param(True, id="compiled"))


def _kernel(name: str, compiled: bool):
    fn = getattr(_select, name)
    return fn if compiled or not hasattr(fn, "py_func") else fn.py_func


@pytest.mark.parametrize("compiled", _KERNELS)
@settings(max_examples=150, deadline=None)
@given(
    values=st.lists(
        st.one_of(st.integers(-3, 3).map(float), st.floats(-1e6, 1e6, allow_nan=False)),
        min_size=1,
        max_size=90,
    ),
    data=st.data(),
)
def test_selection_and_median_are_numpys(compiled, values, data):
    """Ties (few distinct values: quantised data), odd and even sizes, any order."""
    a = np.array(values, dtype=np.float64)
    k = data.draw(st.integers(0, a.size - 1))
    scratch = a.copy()
    kth = _kernel("select_inplace", compiled)(scratch, k)
    assert kth == np.sort(a)[k]
    assert np.all(scratch[:k] <= kth) and np.all(scratch[k + 1 :] >= kth)
    np.testing.assert_array_equal(np.sort(scratch), np.sort(a))  # reordered, nothing lost
    median = _kernel("median_inplace", compiled)(a.copy())
    assert np.float64(median).view(np.int64) == np.median(a).view(np.int64)


@pytest.mark.parametrize("compiled", _KERNELS)
def test_large_sorted_reversed_and_constant_inputs(compiled):
    """The orders that defeat a naive pivot, and a constant array, at sizes a kernel sees."""
    rng = np.random.default_rng(3)
    median = _kernel("median_inplace", compiled)
    for a in (
        np.arange(20_001, dtype=np.float64),
        np.arange(20_000, dtype=np.float64)[::-1].copy(),
        np.full(10_000, 7.0),
        rng.integers(0, 4, 30_000).astype(np.float64),
        rng.normal(size=30_001),
    ):
        assert median(a.copy()) == np.median(a)
