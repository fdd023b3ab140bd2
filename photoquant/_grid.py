"""Index arithmetic on pixel grids shared by the steps that read neighbourhoods."""

from __future__ import annotations

import numpy as np

__all__ = ["mirror_index"]


def mirror_index(index: np.ndarray, n: int) -> np.ndarray:
    """``index`` reflected into ``[0, n)`` about the border pixels (``n ≥ 1``).

    The reflection without repeating the edge (``… 2 1 | 0 1 2 … n−1 | n−2 …``:
    numpy's ``"reflect"`` padding, scipy.ndimage's ``"mirror"`` mode), for any
    distance beyond the border (periodic with period ``2 (n − 1)``).
    """
    if n == 1:
        return np.zeros_like(index)
    period = 2 * (n - 1)
    index = np.abs(index) % period
    return np.where(index >= n, period - index, index)
