"""The validation report: a terminal table, ``report.md``, ``results.json`` and PNG figures.

:func:`write_report` writes the whole report folder atomically: every file
goes into a temporary sibling folder first, which then replaces the target
in one rename (an existing target only with ``overwrite``), so that a
report folder is never half written. Figures are drawn here and only here,
with matplotlib's non-interactive Agg backend, imported lazily; without
matplotlib the report says the figures are missing and the rest is written.

References
----------
.. [PQ] The photoquantity paper, §6.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from importlib import import_module
from pathlib import Path
from typing import Any

import numpy as np

from validation.experiments import EXPERIMENTS, ValidationRun
from validation.experiments.base import ExperimentResult, FigureSpec

__all__ = [
    "format_table",
    "results_json",
    "render_markdown",
    "write_report",
    "draw_figure",
    "ERROR_DEFINITION",
]

CHANNEL_COLOURS = {"R": "#d62728", "G": "#2ca02c", "B": "#1f77b4"}

ERROR_DEFINITION = """\
Every relative error of a photoquantity is eq. 8 of the paper,
`e_p = ‖c_p − s·ĉ_p‖₂ / ‖c_p‖₂` over the colour channels of pixel (or patch) `p`,
with `c_p` the reference and `ĉ_p` the computed colour, after **one global scale fit**
`s`: photoquantity is defined only up to one scale, which the method cannot know.
`s` is the median over pixels of each pixel's own least-squares scale
`(c_p·ĉ_p)/(ĉ_p·ĉ_p)` (`validation.metrics.fit_global_scale`), so that a few pixels at
the physical limit cannot shift the error of all the others. Pixels the method flags
(no valid exposure) are left out. Over the pixels, `e_max` is the maximum, `e_mean`
the mean and `e_std` the sample standard deviation (the paper prints
`1/(#P−1)·√Σ(e−ē)²`, evidently for the usual `√(Σ(e−ē)²/(#P−1))`).

The reference is the simulator's true photoquantity. The calibrated camera outputs
*white-balanced* photoquantity; the calibration scene's white chart has equal
photoquantity in every channel, so the true `l` is directly the reference (for the
ColorChecker, both are balanced on its white patch). Maps that are normalised by
definition — the sensor LUT (mean 1) and the vignetting (1 at its centre) — are
compared directly, `|est − true| / true` per pixel and channel, without a scale fit.
The response `g = ln f⁻¹` is compared after removing its additive gauge per channel.

The paper's numbers come from a real 1024×768 CCD against measured references;
ours from a synthetic camera against its exact ground truth."""


# ---------------------------------------------------------------------------- text


def _rows(res: ExperimentResult, detail: bool) -> list:
    return [r for r in res.rows if detail or not r.detail]


def format_table(run: ValidationRun, check: Any = None) -> str:
    """The terminal table: every experiment's main rows, ours beside the paper's."""
    cfg = run.config
    header = ("quantity", "ours", "paper", "truth-based error / reference")
    lines = [
        f"photoquant validate — {cfg.name}: {cfg.describe()}; presets "
        f"{', '.join(cfg.presets)}; seed {run.seed}; {run.elapsed_s:.0f} s",
    ]
    if cfg.is_degraded:
        lines.append(
            f"  (calibrator degraded on purpose: calibrate_kwargs {dict(cfg.calibrate_kwargs)}, "
            f"skip_vignetting {cfg.skip_vignetting})"
        )
    body: list[tuple[str, ...] | str] = []
    for i, res in enumerate(run.experiments.values(), 1):
        body.append(f"{i} {res.title}" + (f" — {res.skipped}" if res.skipped else ""))
        for r in _rows(res, detail=False):
            body.append(("  " + r.quantity, r.ours, r.paper, r.truth))
    cells = [b for b in body if isinstance(b, tuple)]
    widths = [
        min(max([len(header[j])] + [len(c[j]) for c in cells]), cap)
        for j, cap in enumerate((58, 34, 26, 80))
    ]

    def fmt(c: tuple[str, ...]) -> str:
        return "  ".join(s.ljust(w) for s, w in zip(c, widths, strict=True)).rstrip()

    lines += ["", fmt(header), "  ".join("-" * w for w in widths)]
    for b in body:
        lines.append(fmt(b) if isinstance(b, tuple) else b)
    lines.append("")
    chart = "rendered by Mitsuba 3" if run.config.chart == "rendered" else "analytic, not rendered"
    lines.append(
        "Relative errors: eq. 8 after one global scale fit (photoquantity is defined up to "
        "scale); maps (u, v) compared directly. Table 1's Hugin row is Hugin's own "
        f"calibration (vig_optimize, where installed); the ColorChecker is {chart}."
    )
    if check is not None:
        lines.append("")
        lines.append(check.summary())
    return "\n".join(lines)


def _clean(value: Any) -> Any:
    """JSON-ready: numpy to Python, NaN/inf to None, tuples to lists."""
    if isinstance(value, Mapping):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return value.as_posix()
    return value


def results_json(run: ValidationRun, check: Any = None) -> str:
    """``results.json``: every metric, its meaning, the configuration, seeds and versions."""
    data = run.to_dict()
    data["error_definition"] = ERROR_DEFINITION
    data["check"] = None if check is None else check.to_dict()
    return json.dumps(_clean(data), indent=1, allow_nan=False) + "\n"


_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def _docstring_markdown(module_name: str) -> str:
    """An experiment module's docstring, without its References, as Markdown."""
    doc = import_module(module_name).__doc__ or ""
    doc = doc.split("\nReferences\n")[0].strip()
    doc = _ROLE.sub(r"`\1`", doc).replace("``", "`")
    lines = doc.splitlines()
    if len(lines) > 1 and lines[1].strip() == "":
        lines = lines[2:]  # the title line is the section heading already
    return "\n".join(lines).strip()


def _md_escape(s: str) -> str:
    return s.replace("|", "\\|")


def render_markdown(run: ValidationRun, check: Any = None) -> str:
    """``report.md``: per experiment what was done, the table, the figures, the notes."""
    cfg = run.config
    out = [
        "# photoquant validation report",
        "",
        f"Configuration **{cfg.name}**: {cfg.describe()}; presets {', '.join(cfg.presets)}; "
        f"master seed {run.seed}; run time {run.elapsed_s:.1f} s. "
        "Simulate (numpy synthetic camera, `pqsim`) → calibrate → correct (`photoquant`) → "
        "compare with the ground truth, beside the numbers the paper reports (§6). "
        "(An experiment's time includes simulating and calibrating the presets when it is "
        "the first to need them; each preset is calibrated once per run.)",
        "",
    ]
    if cfg.is_degraded:
        out += [
            f"> **The calibrator was degraded on purpose** (calibrate_kwargs "
            f"`{dict(cfg.calibrate_kwargs)}`, skip_vignetting `{cfg.skip_vignetting}`).",
            "",
        ]
    if check is not None:
        out += ["## Regression check", "", "```", check.summary(), "```", ""]
    out += ["## How errors are computed", "", ERROR_DEFINITION, ""]
    for i, (name, res) in enumerate(run.experiments.items(), 1):
        out += [
            f"## {i}. {res.title}",
            "",
            f"*Paper: {res.reference}.* Experiment `{name}`, {res.elapsed_s:.1f} s.",
            "",
        ]
        out += [_docstring_markdown(EXPERIMENTS[name]), ""]
        if res.skipped:
            out += [f"**Not run: {res.skipped}**", ""]
        if res.rows:
            out += [
                "| quantity | ours | paper | truth-based error / reference |",
                "| --- | --- | --- | --- |",
            ]
            out += [
                f"| {_md_escape(r.quantity)} | {_md_escape(r.ours)} | {_md_escape(r.paper)} | "
                f"{_md_escape(r.truth)} |"
                for r in res.rows
            ]
            out.append("")
        for fig, path in zip(res.figures, res.figure_paths, strict=False):
            out += [f"![{fig.title}]({path})", "", f"*{fig.title}.* {fig.caption}", ""]
        if res.figures and not res.figure_paths:
            out += [
                "*(figures not drawn: matplotlib is not installed — `pip install '.[plot]'`)*",
                "",
            ]
        if res.notes:
            out += [f"- {n}" for n in res.notes]
            out.append("")
    out += [
        "## Configuration, seeds, versions",
        "",
        "Every metric, with its description, unit and the direction that is better, is in "
        "`results.json`, with the configuration, the seed of every random stream "
        "(derived from the master seed by `validation.config.stream_seed`) and the versions "
        "below.",
        "",
        "```json",
        json.dumps(_clean(cfg.as_dict()), indent=1),
        "```",
        "",
    ]
    from validation.experiments import package_versions

    out += [f"- {k}: {v or 'not installed'}" for k, v in package_versions().items()]
    out.append("")
    return "\n".join(out)


# ---------------------------------------------------------------------------- figures


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


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


def draw_figure(spec: FigureSpec, path: str | os.PathLike[str]) -> Path:
    """Draw ``spec`` to the PNG file ``path`` (Agg backend)."""
    plt = _plt()
    fig = _DRAW[spec.kind](plt, spec)
    try:
        fig.suptitle(spec.title, fontsize=11)
        fig.tight_layout()
        fig.savefig(path, format="png", dpi=110)
    finally:
        plt.close(fig)
    return Path(path)


def _draw_figures(jobs: list[tuple[FigureSpec, Path]]) -> None:
    """:func:`draw_figure` of each ``(spec, path)``, on two forked processes where the
    machine has two CPUs (:func:`validation.experiments._default_workers`; the same
    files: each figure is drawn alone from its spec)."""
    from validation.experiments import _default_workers

    if len(jobs) < 2 or _default_workers() < 2:
        for spec, path in jobs:
            draw_figure(spec, path)
        return
    import multiprocessing

    from validation.experiments import ignore_interrupts

    _plt()  # imported once, before the fork
    # an interrupt is this process's to handle (one line): leaving the pool ends the workers
    with multiprocessing.get_context("fork").Pool(2, initializer=ignore_interrupts) as pool:
        pool.starmap(draw_figure, jobs, chunksize=1)


def _have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


# ---------------------------------------------------------------------------- folder


def write_report(
    run: ValidationRun,
    folder: str | os.PathLike[str],
    *,
    check: Any = None,
    overwrite: bool = False,
    progress: Any = None,
) -> Path:
    """Write ``report.md``, ``results.json`` and ``figures/*.png`` into ``folder``, atomically.

    Raises :class:`photoquant.errors.OutputExistsError` when ``folder`` exists
    and ``overwrite`` is false, or is not a report folder (it holds anything
    besides ``report.md``, ``results.json`` and ``figures/*.png``).
    """
    from photoquant.io import write_text_atomic
    from photoquant.io.atomic import atomic_directory
    from photoquant.io.outputs import report_folder_problem

    target = Path(folder)
    # refused before anything is drawn, and again at the final rename: an existing
    # folder only with ``overwrite``, and only one that holds nothing but a report
    with atomic_directory(target, overwrite=overwrite, replaceable=report_folder_problem) as tmp:
        figures = tmp / "figures"
        figures.mkdir()
        draw = _have_matplotlib()
        jobs = []
        for res in run.experiments.values():
            res.figure_paths = []
            if not draw:
                continue
            for spec in res.figures:
                rel = f"figures/{spec.name}.png"
                jobs.append((spec, tmp / rel))
                res.figure_paths.append(rel)
        if jobs and progress is not None:
            progress(f"validate: drawing {len(jobs)} figures ...")
        _draw_figures(jobs)
        write_text_atomic(tmp / "results.json", results_json(run, check))
        write_text_atomic(tmp / "report.md", render_markdown(run, check))
    return target
