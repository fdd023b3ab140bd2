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


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 3000),
    n_ch=st.integers(1, 4),
    dtype=st.sampled_from([np.uint8, np.uint16, np.int16, np.int32]),
    centred=st.booleans(),
)
def test_channel_histograms_are_bincounts(seed, n, n_ch, dtype, centred):
    # the defect search's integer medians and the processed saturation detection count
    # each channel of an interleaved integer plane in one pass
    rng = np.random.default_rng(seed)
    low = 0 if np.dtype(dtype).kind == "u" else -200
    x = rng.integers(low, 256, size=(n, n_ch)).astype(dtype)
    offset = int(x.min())
    center2 = rng.integers(-300, 300, n_ch) if centred else None
    keys = [
        (x[:, c].astype(np.int64) - offset)
        if center2 is None
        else np.abs(2 * x[:, c].astype(np.int64) - center2[c])
        for c in range(n_ch)
    ]
    n_bins = max(int(k.max()) for k in keys) + 3
    want = np.stack([np.bincount(k, minlength=n_bins) for k in keys])
    np.testing.assert_array_equal(_select.channel_histograms(x, offset, n_bins, center2), want)


@pytest.mark.skipif(_select._channel_counts is None, reason="numba is not installed")
@pytest.mark.parametrize("centred", [False, True])
def test_channel_histograms_shared_among_threads_add_up_to_the_bincounts(monkeypatch, centred):
    """Large inputs are counted in row spans on several threads: the same counts."""
    rng = np.random.default_rng(3)
    x = rng.integers(0, 256, size=(10_007, 3)).astype(np.uint8)
    x[::7] = 255  # a pile: many increments of one bin
    center2 = np.array([10, 255, 500]) if centred else None
    n_bins = 520
    want = _select.channel_histograms(x, 0, n_bins, center2)  # one pass (10 007 rows)
    spans = []

    def recording(fn, items, workers=None):
        items = list(items)
        spans.append(len(items))
        return [fn(item) for item in items]

    monkeypatch.setattr(_select, "THREADED_ROWS", 1000)
    monkeypatch.setattr(_select, "default_workers", lambda: 4)
    monkeypatch.setattr(_select, "thread_map", recording)
    np.testing.assert_array_equal(_select.channel_histograms(x, 0, n_bins, center2), want)
    assert spans == [4]
    keys = [
        x[:, c].astype(np.int64)
        if center2 is None
        else np.abs(2 * x[:, c].astype(np.int64) - center2[c])
        for c in range(3)
    ]
    np.testing.assert_array_equal(want, np.stack([np.bincount(k, minlength=n_bins) for k in keys]))
