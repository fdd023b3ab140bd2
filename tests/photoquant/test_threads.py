"""The thread helpers: spans of work for the threads."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from photoquant._threads import even_spans


@given(n=st.integers(0, 10_000), parts=st.integers(1, 64))
def test_even_spans_cover_the_range_once_in_order(n, parts):
    spans = even_spans(n, parts)
    assert len(spans) == max(1, min(parts, n))
    assert spans[0].start == 0 and spans[-1].stop == n
    assert all(a.stop == b.start for a, b in zip(spans[:-1], spans[1:], strict=True))
    sizes = [s.stop - s.start for s in spans]
    assert max(sizes) - min(sizes) <= 1  # nearly equal
    assert n == 0 or min(sizes) >= 1
