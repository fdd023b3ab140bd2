"""Tests of photoquant._interp: ``np.interp`` on evenly spaced tables, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from photoquant import _interp
from photoquant._interp import interp

needs_numba = pytest.mark.skipif(_interp._interp_even_nb is None, reason="needs numba")

_SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -0.0]


def _bits(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return np.where(np.isnan(a), np.nan, a).view(np.uint64)  # one NaN for every NaN


def _assert_same_bits(x, xp, fp) -> None:
    got = interp(x, xp, fp)
    want = np.interp(x, xp, fp)
    assert got.shape == np.shape(want)
    np.testing.assert_array_equal(_bits(got), _bits(want))


@needs_numba
@settings(max_examples=300, deadline=None)
@given(
    n=st.integers(2, 40),
    start=st.floats(-300, 300),
    step=st.floats(1e-3, 50),
    jitter=st.floats(0, 0.2),
    seed=st.integers(0, 2**32 - 1),
)
def test_interp_matches_numpy_bit_for_bit(n, start, step, jitter, seed):
    # even and nearly even grids, tables with infinities and NaNs, values on the grid
    # points, between them, just beside them, outside, NaN and infinite
    rng = np.random.default_rng(seed)
    xp = start + step * (np.arange(n) + jitter * rng.uniform(-1, 1, n))
    xp = np.unique(xp)
    if xp.size < 2:
        return
    fp = rng.normal(0, 10, xp.size)
    fp[rng.uniform(size=xp.size) < 0.1] = rng.choice(_SPECIAL)
    x = np.concatenate(
        [
            xp,
            np.nextafter(xp, np.inf),
            np.nextafter(xp, -np.inf),
            rng.uniform(xp[0] - 2 * step, xp[-1] + 2 * step, 200),
            _SPECIAL,
        ]
    )
    _assert_same_bits(x, xp, fp)
    grid = x[: x.size // 5 * 5].reshape(-1, 5)
    _assert_same_bits(grid[:, ::2], xp, fp)  # a strided 2-D view keeps its shape


@needs_numba
@given(hnp.arrays(np.float64, st.integers(0, 50), elements=st.floats(allow_nan=True)))
def test_interp_any_values_on_the_response_levels(x):
    levels = np.arange(256.0)
    g = np.log(np.maximum(levels, 0.5))  # -inf-free, with a flat start
    _assert_same_bits(x, levels, g)


def test_interp_uneven_and_short_tables_are_numpy():
    xp = np.array([0.0, 1.0, 10.0, 11.0])  # uneven: numpy itself
    fp = np.array([1.0, 2.0, 3.0, 5.0])
    x = np.linspace(-1, 12, 27)
    _assert_same_bits(x, xp, fp)
    _assert_same_bits(x, [2.0], [7.0])  # one point
    assert not _interp._evenly_spaced(xp)
    assert _interp._evenly_spaced(np.arange(5.0))


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(2, 30),
    even=st.booleans(),
    rows=st.integers(1, 4),
    seed=st.integers(0, 2**32 - 1),
)
def test_a_value_located_once_reads_every_table_as_numpy(n, even, rows, seed):
    # the held-out read-back of cross-validation's intervals: one interval search per
    # value, every factor row of the response's covariance read there as np.interp does
    from photoquant._interp import at_interval, at_interval_py, interp_slopes, interval, interval_py

    locate = interval or interval_py
    read = at_interval or at_interval_py
    rng = np.random.default_rng(seed)
    xp = np.arange(n) * 1.5 - 4 if even else np.cumsum(rng.uniform(0.01, 3, n))
    fps = rng.normal(0, 10, (rows, n))
    fps[rng.uniform(size=fps.shape) < 0.1] = rng.choice(_SPECIAL)
    slopes = interp_slopes(xp, fps)
    x = np.concatenate(
        [xp, np.nextafter(xp, np.inf), rng.uniform(xp[0] - 2, xp[-1] + 2, 50), _SPECIAL]
    )
    for v in x:
        case, j = locate(float(v), xp)
        with np.errstate(all="ignore"):  # the plain-Python twins' numpy scalars (no numba)
            got = np.array([read(float(v), xp, fps[r], slopes[r], case, j) for r in range(rows)])
        want = np.array([np.interp(v, xp, fps[r]) for r in range(rows)])
        np.testing.assert_array_equal(_bits(got), _bits(want))
