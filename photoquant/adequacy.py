"""Model adequacy: how far a bracket departs from one global response per channel.

Eq. 1 of [PQ]_ has one response ``f_λ`` per channel for the whole image and a
static scene. A phone's JPEG is tone-mapped locally (the response changes
over the image), and a scene that moves between exposures has no single
photoquantity per pixel: no global response fits either, and a calibration
from such data carries errors that its fit residuals, averaged over the
image, hide. What gives them away is *structure*: with one global response
the prediction errors of eq. 1 — each value ``z_pk`` against the value the
response predicts from the merge of the pixel's exposures,

    r_pk = f(E_p · t_k) − z_pk,    ln E_p the merge (eq. 6),

in code values, as :mod:`photoquant.crossval` scores — are noise,
independent from pixel to pixel; a local tone curve or a moving object
makes them agree over regions. :func:`global_response_departure` removes
what a wrong *global* response explains (the mean error at each level of
each exposure and channel), averages the rest over square blocks, and
compares the blocks' spread with what the values' own scatter predicts for
a block mean:

    departure² = var(block means) − mean(within-block variance / n).

``departure`` (code values) is the rms of the misfit that varies over the
image at the block's scale beyond the noise: 0 (to its sampling error) for a
camera that follows eq. 1 (pqsim's CCD preset: 0.005–0.008 DN at 8 bits).
Measured 2026-12-05 on the shared real sets (8-bit DN unless said; JPEG
files read with the manifest's default ``saturation_spread``): Memorial 0.49,
frobisher 0.11, St. Louis (a compact camera's JPEG, moving water) 0.71, the
12-bit machine-vision bracket (hand-held) 19.4 DN of 4095.

References
----------
.. [PQ] The photoquantity paper (eq. 1: one response per channel, a static
   scene).
.. [Grossberg2003] M. D. Grossberg, S. K. Nayar, "Determining the camera
   response from images: what is knowable?", IEEE PAMI 25(11), 2003 (the
   response as a global, spatially uniform function).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._threads import thread_map
from photoquant.holdout import predict_values
from photoquant.stack import ExposureStack, _compare_per_channel

__all__ = ["ADEQUACY_WARN", "ModelAdequacy", "global_response_departure"]

ADEQUACY_WARN = 1.0 / 255.0
"""Departure, as a fraction of the code range, above which calibrate warns: 1 DN at
8 bits, three times the rounding error of an 8-bit value (0.29 DN rms) and over a hundred
times what a camera that follows eq. 1 shows."""


@dataclass(frozen=True)
class ModelAdequacy:
    """How far a bracket departs from one global response per channel (module notes).

    Attributes
    ----------
    departure : float
        RMS (code values) of the prediction errors' block means beyond their
        noise, pooled over channels: the spatially structured misfit.
    noise : float
        RMS (code values) that noise alone gives a block mean.
    block_px : int
        Side of the square blocks.
    n_blocks : int
        Blocks used (those with enough valid values).
    code_range : float
        ``2**bit_depth − 1``.
    """

    departure: float
    noise: float
    block_px: int
    n_blocks: int
    code_range: float = 255.0

    @property
    def adequate(self) -> bool:
        """``departure <= ADEQUACY_WARN · code_range`` (NaN, nothing measured: adequate)."""
        return not self.departure > ADEQUACY_WARN * self.code_range

    @classmethod
    def from_dict(cls, record: Any) -> ModelAdequacy | None:
        """The adequacy of a report's record (:meth:`as_dict`); ``None`` if it is not one."""
        fields = ("departure", "noise", "block_px", "n_blocks", "code_range")
        if not isinstance(record, dict) or not all(
            isinstance(record.get(k), int | float) and not isinstance(record.get(k), bool)
            for k in fields
        ):
            return None
        return cls(**{k: record[k] for k in fields})

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (for a calibration report; ``None`` where nothing was measured)."""

        def number(value: float) -> float | None:
            return float(value) if np.isfinite(value) else None

        return {
            "departure": number(self.departure),
            "noise": number(self.noise),
            "block_px": int(self.block_px),
            "n_blocks": int(self.n_blocks),
            "code_range": float(self.code_range),
            "adequate": bool(self.adequate),
        }

    def describe(self) -> str:
        """One line for a user."""
        head = (
            f"the data depart from one global response per channel by {self.departure:.3g} DN "
            f"rms over {self.block_px}-px blocks beyond their noise ({self.noise:.3g} DN)"
        )
        if self.adequate:
            return head
        return (
            head + ": eq. 1 does not hold here (a locally tone-mapped image, or a scene that "
            "moved between exposures), and no global response fits it"
        )


def _level_bins(z: np.ndarray, top: float, n_bins: int) -> np.ndarray:
    return np.clip((z / max(top, 1.0) * n_bins).astype(np.int64), 0, n_bins - 1)


def global_response_departure(
    stack: ExposureStack,
    log_photoquantity: np.ndarray,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    valid: np.ndarray | None = None,
    *,
    valid_min: np.ndarray | None = None,
    saturation_level: np.ndarray | None = None,
    block_px: int = 16,
    n_level_bins: int = 32,
    min_values: int = 32,
) -> ModelAdequacy:
    """The spatially structured misfit of eq. 1 in a bracket (module notes).

    Parameters
    ----------
    stack : ExposureStack
        The bracket (its repeats averaged).
    log_photoquantity : ndarray, shape (H, W, C)
        ``ln E`` of its merge with the response (NaN where none).
    levels, log_inverse_response : ndarray
        The response ``g`` per channel, tabulated at ``levels``.
    valid : ndarray, shape (K, H, W, C) of bool, optional
        Values to use; by default those not clipped (at ``saturation_level``
        or the dark floor).
    valid_min : ndarray, shape (C,), optional
        The response's lowest trusted level per channel (a toe where ``g``
        is flat, e.g. a film scan's floor, tells nothing of eq. 1).
    saturation_level : ndarray, shape (C,), optional
        Where ``valid`` is not given: the level at which a value counts as
        saturated (the response's), the stack's own by default.
    block_px : int
        Side of the blocks the residuals are averaged over.
    n_level_bins : int
        Level bins of the global correction (per exposure and channel).
    min_values : int
        Values a block needs to be used.

    Only the well-exposed values are used (``[10, 245]`` at 8 bits, the same
    fraction at other depths, as :mod:`photoquant.crossval` scores), on a
    regular subsample of at most about two million values.

    Returns
    -------
    ModelAdequacy
    """
    # at most ~2 million values: every s-th row and column (blocks keep their size in
    # pixels), taken before any per-value test (the same values, a fraction of the passes)
    n_k = stack.n_exposures
    height, width = stack.image_shape
    n_ch = stack.n_channels
    step = max(1, int(np.ceil(np.sqrt(n_k * height * width * n_ch / 2e6))))
    # the subsample's own stack: its mean and clipping are those of the whole stack there
    # (value by value), at a fraction of the cost
    sub = stack.with_frames(np.ascontiguousarray(stack.frames[:, :, ::step, ::step]))
    z = sub.mean()  # (K, H', W', C)
    if valid is None:
        valid = ~(sub.saturated(saturation_level) | sub.dark_clipped())
    else:
        valid = valid[:, ::step, ::step]
    # the well-exposed values only (crossval's scored range): in the toe and the shoulder
    # g is steep and a value's noise, not the model, dominates its residual
    top = 2.0**stack.bit_depth - 1
    valid = valid & (z >= 10 / 255 * top) & (z <= 245 / 255 * top)
    if valid_min is not None:
        valid = valid & _compare_per_channel(
            np.greater_equal, z, np.broadcast_to(np.asarray(valid_min, dtype=np.float64), (n_ch,))
        )
    top_level = np.asarray(stack.saturation_level, dtype=np.float64)
    log_photoquantity = log_photoquantity[::step, ::step]
    height, width = z.shape[1:3]
    side = max(block_px // step, 4)  # in the subsample's pixels
    block_px = side * step  # reported in the image's
    by, bx = np.arange(height) // side, np.arange(width) // side
    n_bx = int(bx.max()) + 1
    block = (by[:, None] * n_bx + bx[None, :]).ravel()
    n_blocks = int(block.max()) + 1
    log_t = np.log(stack.exposure_s)
    n_pix = height * width

    def channel(ch: int) -> tuple[float, float, int] | None:
        """The channel's excess and sampling variances between blocks, and its blocks."""
        g = np.asarray(log_inverse_response[ch], dtype=np.float64)
        ln_e = log_photoquantity[..., ch].ravel()
        # every exposure at once, exposure-major (each exposure's values in raster order)
        z_ch = z[..., ch].reshape(n_k, n_pix)
        ok = valid[..., ch].reshape(n_k, n_pix) & np.isfinite(ln_e)[None]
        k_of, p_of = np.nonzero(ok)
        z_ok = z_ch[k_of, p_of]
        # the value predicted from the merge through the response, in code values
        # (as crossval scores): a steep toe does not blow a value's noise up
        log_x = (ln_e[p_of] + log_t[k_of])[:, None]
        r = predict_values(levels, g[None], top_level[ch : ch + 1], log_x)[:, 0] - z_ok
        # what a wrong global response explains: the mean residual at each level, per
        # exposure (one bincount over (exposure, level bin))
        cell = k_of * n_level_bins + _level_bins(z_ok, float(levels[-1]), n_level_bins)
        size = n_k * n_level_bins
        mean = np.bincount(cell, r, size) / np.maximum(np.bincount(cell, None, size), 1)
        r = r - mean[cell]
        # the blocks' sums per exposure, added exposure by exposure
        b = k_of * n_blocks + block[p_of]
        size = n_k * n_blocks
        per_k = [np.bincount(b, w, size).reshape(n_k, n_blocks) for w in (r, r * r, None)]
        sums, squares, counts = (np.zeros(n_blocks) for _ in range(3))
        for k in range(n_k):
            sums += per_k[0][k]
            squares += per_k[1][k]
            counts += per_k[2][k]
        keep = counts >= min_values
        if keep.sum() < 2:
            return None
        means = sums[keep] / counts[keep]
        within = squares[keep] / counts[keep] - means**2
        sampling = float(np.mean(within * counts[keep] / (counts[keep] - 1) / counts[keep]))
        between = float(np.var(means))
        return max(between - sampling, 0.0), sampling, int(keep.sum())

    # the channels on every core (numpy's passes release the GIL), in channel order
    found = [c for c in thread_map(channel, range(n_ch)) if c is not None]
    excess = [c[0] for c in found]
    noise = [c[1] for c in found]
    used = max((c[2] for c in found), default=0)
    if not excess:
        return ModelAdequacy(float("nan"), float("nan"), block_px, 0, top)
    return ModelAdequacy(
        float(np.sqrt(np.mean(excess))), float(np.sqrt(np.mean(noise))), block_px, used, top
    )
