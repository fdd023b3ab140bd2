"""Plots where a picture beats a table: recovered curves over the truth, error against time.

Plain functions that draw with matplotlib (``Agg``) into a PNG file and
return its path, or ``None`` when there is nothing to draw; the leaderboard
(:func:`validation.leaderboard.write_report`) and the validation report use
them. Error *maps* are drawn by the report's ``maps`` figures
(:mod:`validation.report`).

- :func:`plot_response_curves`: per camera, each method's recovered log
  inverse response ``g = ln f⁻¹`` of one channel over the true one, after the
  one additive constant that the global scale of photoquantity leaves free
  (eq. 7 of [PQ]), with the residual below.
- :func:`plot_error_vs_time`: each method's error against its calibration
  time, one panel per step (log–log), the noise floor as a line.

References
----------
.. [PQ] The photoquantity paper, eq. 7.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "aligned_response",
    "figure_error_vs_time",
    "figure_response_curves",
    "plot_error_vs_time",
    "plot_response_curves",
]


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def aligned_response(
    g_est: np.ndarray, g_true: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(g_est − c, mask)``: the estimate shifted by the weighted mean offset ``c`` to the truth.

    ``mask`` marks the levels where both are finite and the weight positive
    (the levels scored by :func:`validation.compare.compare_with_truth`).
    """
    ge = np.asarray(g_est, dtype=np.float64)
    gt = np.asarray(g_true, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    mask = np.isfinite(ge) & np.isfinite(gt) & (w > 0)
    if not np.any(mask):
        return ge, mask
    c = float(np.sum(w[mask] * (ge[mask] - gt[mask])) / np.sum(w[mask]))
    return ge - c, mask


def plot_response_curves(
    curves: Mapping[str, Mapping[str, Mapping[str, np.ndarray]]],
    path: str | Path,
    *,
    channel: int = 1,
    title: str = "Recovered response over the truth",
) -> Path | None:
    """Each method's recovered ``g`` of one channel over the truth, one column per camera.

    Parameters
    ----------
    curves : mapping
        ``camera → method → {"levels", "g_est" (C, L), "g_true" (C, L), "weights" (C, L)}``.
    path : path
        The PNG to write.
    channel : int
        The channel drawn (green by default; the first for one-channel cameras).

    Returns
    -------
    Path or None
        ``path``, or ``None`` when no curve was given.
    """
    cameras = [c for c in curves if curves[c]]
    if not cameras:
        return None
    plt = _plt()
    fig = figure_response_curves(plt, curves, channel=channel, title=title)
    out = Path(path)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def figure_response_curves(
    plt: Any,
    curves: Mapping[str, Mapping[str, Mapping[str, np.ndarray]]],
    *,
    channel: int = 1,
    title: str = "Recovered response over the truth",
) -> Any:
    """The figure of :func:`plot_response_curves` (a matplotlib Figure, not saved)."""
    cameras = [c for c in curves if curves[c]]
    fig, axes = plt.subplots(
        2,
        len(cameras),
        figsize=(4.2 * len(cameras), 6.2),
        squeeze=False,
        sharex="col",
        gridspec_kw={"height_ratios": [2.2, 1]},
    )
    methods = sorted({m for c in cameras for m in curves[c]}, key=str.casefold)
    colours = {m: f"C{i % 10}" for i, m in enumerate(methods)}
    for j, cam in enumerate(cameras):
        top, bottom = axes[0, j], axes[1, j]
        truth_drawn = False
        for method, data in curves[cam].items():
            levels = np.asarray(data["levels"], dtype=np.float64)
            ch = min(channel, np.asarray(data["g_est"]).shape[0] - 1)
            g_true = np.asarray(data["g_true"], dtype=np.float64)[ch]
            g, mask = aligned_response(data["g_est"][ch], g_true, data["weights"][ch])
            if not truth_drawn:
                ok = np.isfinite(g_true)
                top.plot(levels[ok], g_true[ok], "k-", lw=3, alpha=0.35, label="truth")
                truth_drawn = True
            top.plot(levels[mask], g[mask], lw=1, color=colours[method], label=method)
            bottom.plot(levels[mask], (g - g_true)[mask], lw=1, color=colours[method])
        top.set_title(cam)
        top.set_ylabel("g = ln f⁻¹ (aligned)")
        bottom.set_ylabel("g − g_true")
        bottom.set_xlabel("pixel value")
        bottom.axhline(0.0, color="k", lw=0.5)
        bottom.set_ylim(-0.3, 0.3)
    axes[0, 0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_error_vs_time(
    panels: Sequence[Mapping[str, Any]], path: str | Path, *, title: str = "Error against time"
) -> Path | None:
    """A scatter of error against calibration time per method, one panel per step.

    Parameters
    ----------
    panels : sequence of mapping
        ``{"title", "xlabel", "ylabel", "points": [(label, time_s, error)], "floor": float | None}``;
        points with a missing or non-positive value are left out.
    path : path
        The PNG to write.

    Returns
    -------
    Path or None
        ``path``, or ``None`` when no panel has a point.
    """
    drawn = [p for p in panels if _drawable(p)]
    if not drawn:
        return None
    plt = _plt()
    fig = figure_error_vs_time(plt, drawn, title=title)
    out = Path(path)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def _drawable(p: Mapping[str, Any]) -> bool:
    return any(
        t is not None and e is not None and t > 0 and e > 0 and math.isfinite(e)
        for _, t, e in p["points"]
    )


def figure_error_vs_time(
    plt: Any, panels: Sequence[Mapping[str, Any]], *, title: str = "Error against time"
) -> Any:
    """The figure of :func:`plot_error_vs_time` (a matplotlib Figure, not saved)."""
    drawn = [p for p in panels if _drawable(p)] or list(panels[:1])
    fig, axes = plt.subplots(1, len(drawn), figsize=(5.2 * len(drawn), 4.2), squeeze=False)
    for ax, p in zip(axes[0], drawn, strict=True):
        times = []
        for i, (label, t, e) in enumerate(p["points"]):
            if t is None or e is None or not (t > 0 and e > 0 and math.isfinite(e)):
                continue
            times.append(t)
            ax.scatter([t], [e], color=f"C{i % 10}", s=28, zorder=3)
            ax.annotate(label, (t, e), fontsize=7, xytext=(3, 3), textcoords="offset points")
        if p.get("floor"):
            ax.axhline(p["floor"], ls="--", color="k", lw=0.8, label="noise floor")
            ax.legend(fontsize=7)
        # times within a factor 3 of each other: a linear axis (a log axis spanning less than
        # half a decade labels every minor tick, and they overlap)
        if times and max(times) > 3 * min(times):
            ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(p["title"])
        ax.set_xlabel(p.get("xlabel", "calibration time (s)"), fontsize=8)
        ax.set_ylabel(p.get("ylabel", "error"), fontsize=8)
        ax.grid(True, which="both", alpha=0.25)
    fig.suptitle(title)
    fig.tight_layout()
    return fig
