"""Index arithmetic on pixel grids: the mirrored border the neighbourhood steps read."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from photoquant._grid import mirror_index


@given(st.integers(1, 40), st.integers(0, 120))
def test_mirror_index_is_numpys_reflect_padding(n, pad):
    """Every index within ``pad`` of the grid lands where numpy's ``"reflect"`` padding
    (scipy.ndimage's ``"mirror"``) takes its value from."""
    index = np.arange(-pad, n + pad)
    if n == 1:
        expected = np.zeros_like(index)  # one pixel: every neighbour is that pixel
    else:
        expected = np.pad(np.arange(n), pad, mode="reflect")
    np.testing.assert_array_equal(mirror_index(index, n), expected)
