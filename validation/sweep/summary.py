"""The summary of a sweep: per axis, the errors against the axis value; one HTML page.

:func:`write_summary` writes ``DIR/summary/``: one PNG per axis
(``<axis>.png``) with a panel per headline metric (:data:`HEADLINE`) — the
median over the seeds against the axis value, one line per combination of
the other axes' values (the method and pipeline among them), and the
interquartile range shaded — and ``index.html``, a self-contained page (the
plots inlined as base64) with the table of medians and the failed cells.
When the other axes give more than :data:`MAX_SERIES` combinations, the
lines keep only the ``method``, ``pipeline`` and ``preset`` axes and pool the
rest with the seeds (the panel says so).

Drawn with matplotlib's object API on the Agg canvas (no global pyplot state).
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.io.outputs import folder_of_kind
from validation.sweep.spec import column_value

__all__ = ["HEADLINE", "MAX_SERIES", "write_summary", "summary_rows", "axis_series"]

#: Metrics plotted and tabulated: name → (label, scale to the unit shown).
HEADLINE: Mapping[str, tuple[str, float]] = {
    "scene_e_mean": ("test scene e_mean (eq. 8), %", 100.0),
    "response_rms": ("response g rms (ln), worst channel", 1.0),
    "vignetting_e_mean": ("vignetting e_mean, %", 100.0),
    "lut_e_mean": ("sensor LUT e_mean, %", 100.0),
    "balance_error": ("balance |error|, largest channel, %", 100.0),
    "time_calibrate_s": ("calibration time, s", 1.0),
}
MAX_SERIES = 8
_METHOD_AXES = ("method", "pipeline", "preset")

#: The summary folder inside a sweep folder (what ``write_summary`` may replace).
summary_folder_problem = folder_of_kind("sweep summary", ("*.png", "index.html"), ("index.html",))


def _values(table: Any, column: str) -> list[Any]:
    return list(table.column(column).to_pylist())


def _ok_metric_rows(table: Any) -> list[dict[str, Any]]:
    return [r for r in table.to_pylist() if r["status"] == "ok" and r["metric"] is not None]


def _quartiles(v: Sequence[float]) -> tuple[float, float, float]:
    a = np.asarray([x for x in v if x is not None and math.isfinite(x)], dtype=np.float64)
    if a.size == 0:
        return (math.nan, math.nan, math.nan)
    q1, q2, q3 = np.percentile(a, [25, 50, 75])
    return float(q1), float(q2), float(q3)


def axis_series(
    rows: Sequence[Mapping[str, Any]], axes: Sequence[str], axis: str, metric: str
) -> tuple[list[Any], dict[str, list[tuple[float, float, float]]], str]:
    """The lines of one panel: x values, label → per-x (q1, median, q3) of ``metric``, a note.

    Rows of other metrics and failed cells are left out; each line is one
    combination of the other axes' values (see the module notes).
    """
    others = [a for a in axes if a != axis]
    combos = {tuple(r[a] for a in others) for r in rows}
    note = ""
    if len(combos) > MAX_SERIES:
        kept = [a for a in others if a in _METHOD_AXES]
        pooled = [a for a in others if a not in kept]
        others = kept
        note = f"pooled over {', '.join(pooled)} and the seeds"
        if len({tuple(r[a] for a in others) for r in rows}) > MAX_SERIES:
            others, note = [], "pooled over every other axis and the seeds"
    xs: list[Any] = []
    for r in rows:
        if r[axis] not in xs:
            xs.append(r[axis])
    if all(isinstance(x, int | float) for x in xs):
        xs.sort()
    groups: dict[tuple[Any, ...], dict[Any, list[float]]] = {}
    for r in rows:
        if r["metric"] != metric:
            continue
        key = tuple(r[a] for a in others)
        groups.setdefault(key, {}).setdefault(r[axis], []).append(r["value"])
    series: dict[str, list[tuple[float, float, float]]] = {}
    for key in sorted(groups, key=lambda k: [str(v) for v in k]):
        label = ", ".join(f"{a}={v}" for a, v in zip(others, key, strict=True)) or "all"
        series[label] = [_quartiles(groups[key].get(x, [])) for x in xs]
    return xs, series, note


def _axis_png(rows: Sequence[Mapping[str, Any]], axes: Sequence[str], axis: str) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    metrics = [m for m in HEADLINE if any(r["metric"] == m for r in rows)]
    ncols = 3
    nrows = max(1, math.ceil(len(metrics) / ncols))
    fig = Figure(figsize=(5.2 * ncols, 3.8 * nrows))
    FigureCanvasAgg(fig)
    _fixed_margins(fig, nrows, ncols)
    numeric = all(isinstance(r[axis], int | float) for r in rows)
    notes = set()
    for i, metric in enumerate(metrics):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        xs, series, note = axis_series(rows, axes, axis, metric)
        if note:
            notes.add(note)
        label, scale = HEADLINE[metric]
        pos = np.asarray(xs, dtype=float) if numeric else np.arange(len(xs), dtype=float)
        for name, q in series.items():
            a = np.asarray(q, dtype=float) * scale
            line = ax.plot(pos, a[:, 1], marker="o", label=name)[0]
            ax.fill_between(pos, a[:, 0], a[:, 2], color=line.get_color(), alpha=0.2)
        if metric == "scene_e_mean":
            _, floor, _ = axis_series(rows, axes, axis, "scene_noise_floor")
            for q in floor.values():
                a = np.asarray(q, dtype=float) * scale
                ax.plot(pos, a[:, 1], color="0.4", ls="--", lw=0.8)
        if numeric and len(xs) > 1 and min(xs) > 0 and max(xs) / min(xs) >= 20:
            ax.set_xscale("log")
        if not numeric:
            ax.set_xticks(pos, [str(x) for x in xs], rotation=15, fontsize=7)
        ax.set_xlabel(axis)
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=6)
    title = f"error against {axis}: median over seeds, interquartile range shaded"
    if "scene_e_mean" in metrics:
        title += " (dashed: the scene's noise floor)"
    if notes:
        title += "; " + "; ".join(sorted(notes))
    fig.suptitle(title, fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


def _fixed_margins(fig: Any, nrows: int, ncols: int) -> None:
    """Margins and gaps of a panel grid in inches: room for the tick labels, the axis
    label, the panel titles and the figure's title.

    A fixed layout, not matplotlib's constrained one: that one draws every
    panel's text once more to measure it, half the drawing time of a summary.
    """
    width, height = fig.get_size_inches()
    left, right, bottom, top = 0.75, 0.2, 0.8, 0.65  # inches
    row_gap, col_gap = 1.0, 0.75
    axis_height = (height - bottom - top - (nrows - 1) * row_gap) / nrows
    axis_width = (width - left - right - (ncols - 1) * col_gap) / ncols
    fig.subplots_adjust(
        left=left / width,
        right=1 - right / width,
        bottom=bottom / height,
        top=1 - top / height,
        hspace=row_gap / axis_height,
        wspace=col_gap / axis_width,
    )


def summary_rows(rows: Sequence[Mapping[str, Any]], axes: Sequence[str]) -> list[dict[str, Any]]:
    """One row per combination of the axes' values: the seeds run and each headline's quartiles."""
    groups: dict[tuple[Any, ...], dict[str, list[float]]] = {}
    seeds: dict[tuple[Any, ...], set[int]] = {}
    for r in rows:
        key = tuple(r[a] for a in axes)
        seeds.setdefault(key, set()).add(r["seed"])
        if r["metric"] in HEADLINE:
            groups.setdefault(key, {}).setdefault(r["metric"], []).append(r["value"])
    out = []
    for key in seeds:
        row: dict[str, Any] = dict(zip(axes, key, strict=True))
        row["seeds"] = len(seeds[key])
        for m in HEADLINE:
            row[m] = _quartiles(groups.get(key, {}).get(m, []))
        out.append(row)
    return out


def _fmt(q: tuple[float, float, float], scale: float) -> str:
    if not math.isfinite(q[1]):
        return "–"
    return f"{q[1] * scale:.3g} [{q[0] * scale:.3g}, {q[2] * scale:.3g}]"


def _html(
    spec: Any,
    table: Any,
    rows: Sequence[Mapping[str, Any]],
    images: Mapping[str, bytes],
    columns: Sequence[str],
) -> str:
    axes = list(spec.axes)
    status = _values(table, "status")
    cells = {}
    for cid, st, err, seed in zip(
        _values(table, "cell_id"),
        status,
        _values(table, "error"),
        _values(table, "seed"),
        strict=True,
    ):
        cells[cid] = (st, err, seed)
    n_failed = sum(1 for st, _, _ in cells.values() if st != "ok")
    e = html.escape
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8"><title>photoquant sweep</title>',
        "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse;"
        "font-size:13px}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
        "th{background:#eee}img{max-width:100%}code{background:#f4f4f4}</style></head><body>",
        "<h1>photoquant sweep</h1>",
        f"<p>{len(cells)} cells ({len(cells) - n_failed} ok, {n_failed} failed), "
        f"{len(spec.seeds)} seeds; axes: "
        + ", ".join(f"<code>{e(a)}</code> ({len(spec.axes[a])})" for a in axes)
        + ".</p>",
        "<p>Fixed: "
        + ", ".join(
            f"<code>{e(k)} = {e(str(column_value(k, v)))}</code>"
            for k, v in sorted(spec.fixed.items())
            if k not in spec.axes and k in columns
        )
        + ".</p>",
        "<h2>Errors per axis</h2>",
    ]
    for axis, png in images.items():
        data = base64.b64encode(png).decode("ascii")
        out.append(f'<h3>{e(axis)}</h3><img alt="{e(axis)}" src="data:image/png;base64,{data}">')
    out.append("<h2>Table</h2><p>Median over the seeds [interquartile range].</p><table><tr>")
    out += [f"<th>{e(a)}</th>" for a in axes]
    out.append("<th>seeds ok</th>")
    out += [f"<th>{e(HEADLINE[m][0])}</th>" for m in HEADLINE]
    out.append("</tr>")
    for r in summary_rows(rows, axes):
        out.append("<tr>" + "".join(f"<td>{e(str(r[a]))}</td>" for a in axes))
        out.append(f"<td>{r['seeds']}</td>")
        out += [f"<td>{e(_fmt(r[m], HEADLINE[m][1]))}</td>" for m in HEADLINE]
        out.append("</tr>")
    out.append("</table>")
    if n_failed:
        out.append("<h2>Failed cells</h2><table><tr><th>cell</th><th>seed</th><th>error</th></tr>")
        for cid, (st, err, seed) in cells.items():
            if st != "ok":
                out.append(f"<tr><td>{e(cid)}</td><td>{seed}</td><td>{e(str(err))}</td></tr>")
        out.append("</table>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def summary_images(spec: Any, table: Any) -> dict[str, bytes]:
    """The summary's PNG of each axis (of the ``ok`` cells' rows of ``table``)."""
    rows = _ok_metric_rows(table)
    axes = list(spec.axes)
    return {axis: _axis_png(rows, axes, axis) for axis in axes} if rows else {}


def write_summary(
    spec: Any,
    output: str | Path,
    table: Any,
    columns: Sequence[str],
    images: dict[str, bytes] | None = None,
) -> Path:
    """Write ``output/summary/`` (one PNG per axis, ``index.html``), replacing an older one.

    Parameters
    ----------
    spec : SweepSpec
        The sweep.
    output : str or Path
        The sweep folder.
    table : pyarrow.Table
        Its consolidated results.
    columns : sequence of str
        The parameter columns (:func:`validation.sweep.engine.cell_columns`).
    images : dict, optional
        :func:`summary_images` of ``table`` (drawn here when not given).
    """
    from photoquant.io.atomic import atomic_directory

    rows = _ok_metric_rows(table)
    if images is None:
        images = summary_images(spec, table)
    target = Path(output) / "summary"
    with atomic_directory(
        target, overwrite=True, empty_ok=True, replaceable=summary_folder_problem
    ) as tmp:
        for axis, png in images.items():
            (tmp / f"{_file_name(axis)}.png").write_bytes(png)
        page = _html(spec, table, rows, images, columns)
        (tmp / "index.html").write_text(page, encoding="utf-8")
    return target


def _file_name(axis: str) -> str:
    safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in axis)
    return safe.strip(".") or "axis"
