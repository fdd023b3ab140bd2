"""Experiment 7 — Fig. 7 of [PQ]: linear regression of measured against ground truth.

On the chart measurements of Table 1 (:func:`validation.experiments.table1.chart_measurements`),
each (patch, channel) gives a point ``(x, y)``: ``x`` the ground truth,
``y`` the measured value. The paper plots both on the 8-bit display scale,
so here ``x = 255 · truth / max(truth)``; ``y`` is the LDR pixel value (DN)
for the uncorrected image and ``255 · l̂ / max(l̂)`` for the corrected HDR
image (the paper's "linearly tone-mapped" image). The least-squares line
``y = a x + b`` and the residual norm ``‖y − (a x + b)‖₂`` over the 72 points
are reported (paper, CCD outdoor against the chart maker's values:
``y = 0.7x − 29.47``, residual norm 215.35, uncorrected;
``y = 1.09x − 11.68``, 126.34, corrected).

The paper's case (CCD, outdoor, CIE RGB truth) is drawn beside the same fit
against the true camera photoquantity; every combination is in the results.

References
----------
.. [PQ] The photoquantity paper: §6.3
   "Linearization and colour-correction", Fig. 6, Fig. 7.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, FigureSpec
from validation.experiments.shared import Shared
from validation.experiments.table1 import (
    chart_experiment,
    chart_measurements,
    pipeline_measurements,
    pipeline_rows,
)

__all__ = ["run", "linear_fit", "PAPER", "TITLE"]

TITLE = "Fig. 7: regression of measured vs ground truth"

CACHE_KEYS = ("chart", "chart-pipeline", "pipeline-model", "chart-hdr")
"""The :attr:`~validation.experiments.shared.Shared.cache` entries this experiment reads."""

PAPER = {
    "uncorrected": {"slope": 0.7, "intercept": -29.47, "residual_norm": 215.35},
    "corrected": {"slope": 1.09, "intercept": -11.68, "residual_norm": 126.34},
    "case": "CCD outdoor, chart maker's values",
}


def linear_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares ``y = a x + b`` over finite pairs: ``(a, b, ‖residual‖₂)``."""
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    a, b = np.polyfit(x[ok], y[ok], 1)
    return float(a), float(b), float(np.linalg.norm(y[ok] - (a * x[ok] + b)))


def _display(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return 255.0 * v / np.nanmax(v)


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Regression lines per preset, lighting and ground truth; the Fig. 7 scatter plot."""
    shared = shared or Shared(config, seed, workdir)
    res, lighting, columns = chart_experiment("fig7", TITLE, "§6.3, Fig. 6–7", PAPER, config)
    if res.skipped:
        return res
    panels = []
    extra = pipeline_rows(config)
    row_names = {key: name for key, name, _ in extra}
    for preset, label in columns:
        m = chart_measurements(config, shared, preset, label, lighting[label])
        others = [
            (
                key,
                _display(
                    pipeline_measurements(
                        config, shared, preset, label, lighting[label], key, steps
                    )["hdr"]
                ),
                f"{name} HDR (tone-mapped)",
            )
            for key, name, steps in extra
        ]
        n_ch = m["ldr"].shape[1]
        channel = np.tile(np.arange(n_ch), (m["ldr"].shape[0], 1))
        paper_case = (preset, label) == columns[0]
        for gt, gt_name in (("cie", "CIE RGB (D65)"), ("camera", "camera photoquantity")):
            x = _display(m[f"truth_{gt}"])
            for row, y, name in (
                ("uncorrected", m["ldr"], "uncorrected LDR (DN)"),
                ("corrected", _display(m["hdr"]), "corrected HDR (tone-mapped)"),
                *others,
            ):
                a, b, r = linear_fit(x, y)
                key = f"{preset}.{label}.{row}.{gt}"
                res.metric(f"{key}.slope", a, better="both", description=f"slope, {row} vs {gt}")
                res.metric(
                    f"{key}.intercept",
                    b,
                    better="both",
                    description=f"intercept (display units), {row} vs {gt}",
                )
                res.metric(f"{key}.residual_norm", r, description=f"‖residual‖₂, {row} vs {gt}")
                p = PAPER.get(row)
                res.row(
                    f"{preset} {label}, {row_names.get(row, row)} vs {gt_name}",
                    f"y = {a:.2f}x {'+' if b >= 0 else '−'} {abs(b):.2f}, residual norm {r:.2f}",
                    (
                        f"y = {p['slope']}x − {abs(p['intercept'])}, {p['residual_norm']}"
                        if gt == "cie" and paper_case and isinstance(p, dict)
                        else "–"
                    ),
                    "",
                    detail=not paper_case,
                )
                if paper_case:
                    panels.append(
                        {
                            "title": f"{preset.upper()} {label}: {name}",
                            "xlabel": f"ground truth: {gt_name} (×255/max)",
                            "ylabel": name,
                            "x": x.ravel(),
                            "y": np.asarray(y, dtype=np.float64).ravel(),
                            "channel": channel.ravel(),
                            "channels": ["R", "G", "B"][:n_ch],
                            "clipped": (
                                m["ldr_clipped"].ravel()
                                if row == "uncorrected"
                                else np.zeros(x.size, dtype=bool)
                            ),
                            "fit": [a, b],
                            "residual_norm": r,
                        }
                    )
    if panels:
        p0 = columns[0]
        res.figures.append(
            FigureSpec(
                "fig7_regression",
                "scatter",
                f"Correlation to ground truth ({p0[0].upper()} {p0[1]})",
                "Each point is one channel of one ColorChecker patch (colour = channel); the "
                "line is the least-squares fit; crosses are LDR patches with clipped pixels. "
                "Top: against the chart maker's CIE RGB (the paper's Fig. 7); bottom: against "
                "the true camera photoquantity. Columns: uncorrected, corrected, then the "
                "other pipelines (Table 1's rows: "
                + (", ".join(name for _, name, _ in extra) or "none")
                + ").",
                {"panels": panels, "ncols": 2 + len(extra)},
            )
        )
    res.notes.append(
        "Scales: x = 255·truth/max(truth); LDR y in DN; HDR y = 255·l̂/max(l̂). Slopes, "
        "intercepts and residual norms depend on these display scales (the paper's are not "
        "stated), so compare their pattern: the corrected fit has the smaller residual."
    )
    return res
