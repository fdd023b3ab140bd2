"""The validation report's figures: each :class:`~validation.experiments.base.FigureSpec`
drawn by its kind with matplotlib's non-interactive Agg backend, imported lazily.

:func:`draw_figure` writes one PNG file; :func:`figure_png` gives the same
bytes, which :func:`validation.experiments.run_validation` keeps in a result's
``drawn`` when its process draws the figures of its own experiments while it
waits for the second process; :func:`validation.report.write_report` writes
those as they are and draws the rest.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from validation.experiments.base import ExperimentResult, FigureSpec
from validation.plots import _plt

__all__ = ["CHANNEL_COLOURS", "draw_figure", "draw_while", "figure_png"]

CHANNEL_COLOURS = {"R": "#d62728", "G": "#2ca02c", "B": "#1f77b4"}


def _fig_response(plt, spec: FigureSpec):
    presets = spec.data["presets"]
    fig, axes = plt.subplots(
        2,
        len(presets),
        figsize=(5.2 * len(presets), 6.4),
        squeeze=False,
        gridspec_kw={"height_ratios": [2.2, 1]},
        sharex="col",
    )
    for j, (preset, d) in enumerate(presets.items()):
        top, bottom = axes[0, j], axes[1, j]
        levels = np.asarray(d["levels"])
        for ch, name in enumerate(d["channels"]):
            colour = CHANNEL_COLOURS.get(name, None)
            valid = np.asarray(d["valid"][ch], dtype=bool)
            est = np.asarray(d["g_est"][ch], dtype=float)
            true = np.asarray(d["g_true"][ch], dtype=float)
            top.plot(levels, est, color=colour, lw=1.4, label=f"{name} recovered")
            top.plot(levels, true, color=colour, lw=1.0, ls="--", label=f"{name} true")
            diff = np.where(valid, est - true, np.nan)
            bottom.plot(levels, diff, color=colour, lw=1.0, label=name)
        top.set_title(f"{preset}")
        top.set_ylabel("g = ln f⁻¹(c/a)  (ln exposure)")
        top.legend(fontsize=7, ncol=2)
        top.grid(alpha=0.3)
        bottom.axhline(0, color="k", lw=0.6)
        bottom.set_xlabel("pixel value c")
        bottom.set_ylabel("recovered − true (ln)")
        bottom.grid(alpha=0.3)
    return fig


def _panel_grid(plt, n_panels: int, ncols: int, panel_size: tuple[float, float]):
    """A figure with ``n_panels`` axes on a grid of ``ncols`` columns; spare axes hidden."""
    nrows = max(1, math.ceil(n_panels / ncols))
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(panel_size[0] * ncols, panel_size[1] * nrows), squeeze=False
    )
    for ax in axes.ravel()[n_panels:]:
        ax.axis("off")
    return fig, axes


def _fig_maps(plt, spec: FigureSpec):
    panels = spec.data["panels"]
    fig, axes = _panel_grid(plt, len(panels), int(spec.data.get("ncols", 3)), (4.4, 3.4))
    for ax, p in zip(axes.ravel(), panels, strict=False):
        img = np.asarray(p["image"], dtype=float)
        im = ax.imshow(
            img,
            cmap=p.get("cmap", "viridis"),
            vmin=p.get("vmin"),
            vmax=p.get("vmax"),
            interpolation="nearest",
            extent=p.get("extent"),
        )
        ax.set_title(p["title"], fontsize=9)
        ax.set_xlabel("px")
        ax.set_ylabel("py")
        cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
        if p.get("unit"):
            cb.set_label(p["unit"])
    return fig


def _fig_sweep(plt, spec: FigureSpec):
    panels = spec.data["panels"]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0), squeeze=False)
    for ax, p in zip(axes[0], panels, strict=True):
        x = np.asarray(p["x"], dtype=float)
        for s in p["series"]:
            y = np.array([np.nan if v is None else v for v in s["y"]], dtype=float)
            style = s.get("style")
            ax.plot(x, y, style or "-", marker=None if style else "o", ms=4, label=s["label"])
        if p.get("logx"):
            ax.set_xscale("log")
        if p.get("logy"):
            ax.set_yscale("log")
        refused = np.asarray(p.get("refused", np.zeros(x.size)), dtype=float)
        if np.any(refused > 0):
            ylo = ax.get_ylim()[0]
            ax.plot(
                x[refused > 0],
                np.full(int(np.sum(refused > 0)), ylo),
                "kx",
                ms=9,
                clip_on=False,
                label="fit refused (some or all draws)",
            )
        for h in p.get("hlines", []):
            ax.axhline(h["y"], color="grey", ls=":", lw=1.0)
            ax.annotate(
                h["label"],
                (x.min(), h["y"]),
                fontsize=7,
                color="grey",
                xytext=(2, 2),
                textcoords="offset points",
            )
        ticks = np.asarray(p.get("xticks", x), dtype=float)  # every point's x by default
        ax.set_xticks(ticks)
        ax.set_xticklabels([f"{v:g}" for v in ticks], fontsize=8)
        ax.set_xlabel(p["xlabel"])
        ax.set_ylabel(p["ylabel"])
        ax.set_title(p["title"], fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    return fig


def _fig_scatter(plt, spec: FigureSpec):
    panels = spec.data["panels"]
    fig, axes = _panel_grid(plt, len(panels), int(spec.data.get("ncols", 2)), (5.0, 4.4))
    for ax, p in zip(axes.ravel(), panels, strict=False):
        x = np.asarray(p["x"], dtype=float)
        y = np.asarray(p["y"], dtype=float)
        ch = np.asarray(p["channel"], dtype=int)
        clipped = np.asarray(p["clipped"], dtype=bool)
        for k, name in enumerate(p["channels"]):
            sel = (ch == k) & ~clipped
            ax.scatter(x[sel], y[sel], s=14, color=CHANNEL_COLOURS.get(name), label=name)
            sel = (ch == k) & clipped
            if np.any(sel):
                ax.scatter(x[sel], y[sel], s=22, marker="x", color=CHANNEL_COLOURS.get(name))
        a, b = p["fit"]
        xs = np.array([0.0, max(255.0, float(np.nanmax(x)))])
        ax.plot(xs, a * xs + b, "k-", lw=1.0)
        sign = "+" if b >= 0 else "−"
        ax.set_title(
            f"{p['title']}\ny = {a:.2f}x {sign} {abs(b):.2f}, "
            f"residual norm {p['residual_norm']:.2f}",
            fontsize=9,
        )
        ax.set_xlabel(p["xlabel"], fontsize=8)
        ax.set_ylabel(p["ylabel"], fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    return fig


def _fig_response_curves(plt, spec: FigureSpec):
    from validation.plots import figure_response_curves

    return figure_response_curves(plt, spec.data["curves"], title=spec.title)


def _fig_error_vs_time(plt, spec: FigureSpec):
    from validation.plots import figure_error_vs_time

    return figure_error_vs_time(plt, spec.data["panels"], title=spec.title)


_DRAW = {
    "response": _fig_response,
    "maps": _fig_maps,
    "sweep": _fig_sweep,
    "scatter": _fig_scatter,
    "response_curves": _fig_response_curves,
    "error_vs_time": _fig_error_vs_time,
}


def draw_figure(spec: FigureSpec, path: str | os.PathLike[str] | io.BytesIO) -> Path | None:
    """Draw ``spec`` to the PNG file ``path`` (Agg backend); returns its path (``None``
    where ``path`` is a binary buffer)."""
    plt = _plt()
    fig = _DRAW[spec.kind](plt, spec)
    try:
        fig.suptitle(spec.title, fontsize=11)
        fig.tight_layout()
        fig.savefig(path, format="png", dpi=110)
    finally:
        plt.close(fig)
    return None if isinstance(path, io.BytesIO) else Path(path)


def figure_png(spec: FigureSpec) -> bytes:
    """``spec`` drawn as the PNG bytes :func:`draw_figure` writes."""
    buffer = io.BytesIO()
    draw_figure(spec, buffer)
    return buffer.getvalue()


def draw_while(results: Iterable[ExperimentResult], go_on: Callable[[], bool]) -> int:
    """Draw the figures of ``results`` into their ``drawn`` while ``go_on()`` holds (asked
    before each figure); returns how many were drawn. Nothing is drawn where matplotlib
    is not installed; a figure that fails to draw ends the drawing here and is drawn again
    by the report, where its error is raised as before."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return 0
    count = 0
    for res in results:
        for spec in res.figures:
            if spec.name in res.drawn:
                continue
            if not go_on():
                return count
            try:
                res.drawn[spec.name] = figure_png(spec)
            except Exception:  # noqa: BLE001 - the report's to say, where it draws it again
                return count
            count += 1
    return count
