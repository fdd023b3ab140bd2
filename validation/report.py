"""The validation report: a terminal table, ``report.md``, ``results.json`` and PNG figures.

:func:`write_report` writes the whole report folder atomically: every file
goes into a temporary sibling folder first, which then replaces the target
in one rename (an existing target only with ``overwrite``), so that a
report folder is never half written. Figures are drawn by
:mod:`validation.figures` (matplotlib's non-interactive Agg backend,
imported lazily), those the run has not drawn already on two processes;
without matplotlib the report says the figures are missing and the rest is
written.

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
from validation.figures import draw_figure

__all__ = [
    "format_table",
    "results_json",
    "render_markdown",
    "write_report",
    "draw_figure",
    "ERROR_DEFINITION",
]

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
    from validation.plots import _plt

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
                if spec.name in res.drawn:  # drawn by the run while it waited (the same bytes)
                    (tmp / rel).write_bytes(res.drawn[spec.name])
                else:
                    jobs.append((spec, tmp / rel))
                res.figure_paths.append(rel)
        if jobs and progress is not None:
            progress(f"validate: drawing {len(jobs)} figures ...")
        _draw_figures(jobs)
        write_text_atomic(tmp / "results.json", results_json(run, check))
        write_text_atomic(tmp / "report.md", render_markdown(run, check))
    return target
