"""Private fast path of the merges: per-value quantities looked up on the grid of the means.

The mean of ``N`` integer repeats lies on the grid ``j / N`` (``j`` the exact
integer sum), so any function of the denoised value alone (a weight, ``g``,
the slope of ``g``, a predicted variance) can be evaluated once per grid
point and channel and gathered per pixel with one ``take``, instead of an
``np.interp`` per pixel. The result is the same as evaluating the function
at ``stack.mean()`` to the last bit (the grid values are the same floats:
``j / N``). Stacks whose sums exceed the table size are evaluated directly.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoquant.stack import ExposureStack

__all__ = ["ValueTables", "fits_tables"]

MAX_TABLE_SIZE = 1 << 22
"""Largest integer sum (per channel) for which look-up tables are used."""


def fits_tables(stack: ExposureStack) -> bool:
    """Whether every possible sum of ``stack``'s repeats has a table entry (the sums lie
    below :data:`MAX_TABLE_SIZE`): :class:`ValueTables` then tabulates."""
    return stack.n_repeats * stack.c_max < MAX_TABLE_SIZE


ValueFunction = Callable[[np.ndarray, int], np.ndarray]
"""``fn(mean_values, channel) -> per-value quantity`` (same shape)."""


class ValueTables:
    """Evaluate functions of a stack's denoised values, through tables where they fit.

    Parameters
    ----------
    stack : ExposureStack
        The stack whose means ``stack.mean()`` the functions are evaluated at.
    """

    def __init__(self, stack: ExposureStack) -> None:
        self.n_channels = stack.n_channels
        self.n_exposures = stack.n_exposures
        top = stack.n_repeats * stack.c_max
        self.tabulated = fits_tables(stack)
        self._stack = stack
        self._index: dict[int, np.ndarray] = {}
        if self.tabulated:
            self.grid = np.arange(top + 1, dtype=np.float64) / stack.n_repeats
            self._size = top + 1

    def mean(self, k: int) -> np.ndarray:
        """Denoised values ``(H, W, C)`` of exposure ``k``."""
        return self._stack.mean()[k]

    def _indices(self, k: int) -> np.ndarray:
        if k not in self._index:
            values = self._stack.repeat_sum()[k]
            # the channel offsets as one row of W·C (long inner loops, not numpy's
            # length-C broadcast), added while casting to intp
            offsets = np.arange(self.n_channels, dtype=np.intp) * self._size
            rows = values.reshape(-1, values.shape[-2] * values.shape[-1])
            index = np.add(rows, np.tile(offsets, values.shape[-2]), dtype=np.intp)
            self._index[k] = index.reshape(values.shape)
        return self._index[k]

    def table(self, fn: ValueFunction) -> np.ndarray | ValueFunction:
        """``fn`` tabulated on the grid, ``(C · G,)``; ``fn`` itself without tables."""
        if not self.tabulated:
            return fn
        return np.concatenate([fn(self.grid, ch) for ch in range(self.n_channels)])

    def take_rows(self, table: np.ndarray, k: int) -> np.ndarray:
        """Rows of a table of several quantities ``(C · G, R)`` (tabulated stacks only) at
        every value of exposure ``k``: ``(H, W, C, R)``, one gather of ``R`` numbers each."""
        return table[self._indices(k)]

    def take(self, table: np.ndarray | ValueFunction, k: int) -> np.ndarray:
        """The tabulated quantity at every value ``(H, W, C)`` of exposure ``k``."""
        if isinstance(table, np.ndarray):
            return table.take(self._indices(k))
        values = self.mean(k)
        out = np.empty(values.shape, dtype=np.float64)
        for ch in range(self.n_channels):
            out[..., ch] = table(values[..., ch], ch)
        return out
