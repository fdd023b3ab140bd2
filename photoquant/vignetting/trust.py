"""Trust checks of a fitted vignetting beyond its solver's own (residuals the model cannot explain).

A vignetting fit from correspondences (§5.5 of [PQ]_) states a map
uncertainty from its residuals, as if they were independent noise. When the
views' values at the correspondences do not follow one photoquantity times
a vignetting — a response that is wrong between the levels a point takes in
different views, compression artefacts, clipped values spread by a camera's
processing, a moving scene, wrong correspondences — the residuals are
systematic: the map's error can then be many times its stated uncertainty
(measured on pqsim's ccd camera with JPEG frames at quality 90: pair
residuals of 4–10 % rms, map uncertainty 0.13–0.33 %, map error 1.9 %;
clean, 0.33–0.36 % rms and a map error of 0.085 %). The check here flags
such a fit in the calibration's notes; it does not refuse it (its map may
still be the best estimate there is: the paper's own real camera had a map
error of 1.6 %).

References
----------
.. [PQ] The photoquantity paper, §5.5, §6.3.
.. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration
   and compensation", ICCV 2005 (the pair residuals of the fit).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["RESIDUAL_WARN_RMS", "residual_warnings"]

RESIDUAL_WARN_RMS = 0.02
"""Pair residual rms (relative, track-normalised) above which a fit is flagged.

Six times the clean presets' 0.33–0.36 % (8 bits, N = 4, 3×3 sample
windows) and twice a Bayer-demosaiced camera's 0.9 %: values that follow
eq. 1 do not scatter so much about one vignetting."""


def residual_warnings(
    residual_rms: Any,
    map_uncertainty: Any = None,
    channels: Sequence[str] | None = None,
    limit: float = RESIDUAL_WARN_RMS,
) -> list[str]:
    """One note per channel whose pair residuals exceed ``limit`` (rms, relative).

    Parameters
    ----------
    residual_rms : array_like, shape (C,)
        The fit's residual rms per channel (``VignettingFit.residual_rms``,
        relative for the track-normalised residuals).
    map_uncertainty : array_like, shape (C,), optional
        The fit's stated map uncertainty, quoted beside.
    channels : sequence of str, optional
        Channel names; indices otherwise.
    limit : float
        Largest residual rms not flagged.

    Returns
    -------
    list of str
        Empty when every channel's residuals are within ``limit``.
    """
    rms = np.atleast_1d(np.asarray(residual_rms, dtype=np.float64))
    unc = (
        np.full(rms.shape, np.nan)
        if map_uncertainty is None
        else np.atleast_1d(np.asarray(map_uncertainty, dtype=np.float64))
    )
    names = list(channels) if channels is not None else [str(i) for i in range(rms.size)]
    out = []
    for name, r, u in zip(names, rms, unc, strict=True):
        if not r <= limit:
            stated = (
                f"; its stated map uncertainty {u:.2%} is a lower bound" if np.isfinite(u) else ""
            )
            out.append(
                f"vignetting channel {name}: pair residuals {r:.1%} rms (more than {limit:.0%}): "
                "the views' values at the correspondences do not follow one photoquantity "
                "times a vignetting (a response wrong between levels, compression artefacts, "
                f"a moving scene or wrong correspondences){stated}"
            )
    return out
