"""What an experiment returns: metrics, table rows, figure data, notes.

Every experiment module has ``run(config, seed, workdir, *, shared=None) ->
ExperimentResult``. Metrics are flat, dotted keys
``<experiment>.<preset | all>.<quantity>`` with plain float values (``None``
for a fit the calibrator refused); each carries a :class:`MetricInfo` that
says which direction is better and whether ``--check`` compares it.
Figures are returned as data (:class:`FigureSpec`) and drawn by
:mod:`validation.report`, the only module that imports matplotlib.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

__all__ = [
    "MetricInfo",
    "Row",
    "FigureSpec",
    "ExperimentResult",
    "compact_map_panels",
    "fmt_pct",
    "fmt_num",
]

Better = Literal["lower", "higher", "both"]


@dataclass(frozen=True)
class MetricInfo:
    """How a metric is read and compared.

    Parameters
    ----------
    better : {"lower", "higher", "both"}
        Which way is an improvement; ``"both"`` (a value with a target, such
        as a slope or a factor): any move beyond the tolerance is a regression.
    unit : str
        ``"fraction"`` (relative errors, printed in %), ``"ln"``, ``"s"``, ...
    check : bool
        Compared by ``--check`` (timings are not).
    description : str
        What it is, in a few words.
    """

    better: Better = "lower"
    unit: str = ""
    check: bool = True
    description: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Row:
    """One line of an experiment's table: our value, the paper's, the truth-based error."""

    quantity: str
    ours: str
    paper: str = "–"
    truth: str = ""
    detail: bool = False
    """Shown in report.md only, not in the terminal table."""


@dataclass(frozen=True)
class FigureSpec:
    """A figure to draw: ``kind`` selects the drawing function of :mod:`validation.report`.

    Kinds: ``"response"`` (curves per preset and channel), ``"maps"`` (images
    with a colour bar), ``"sweep"`` (error against a count, log axes),
    ``"scatter"`` (points coloured by channel with regression lines),
    ``"noise"`` (standard deviation against ``N``, log axes).
    """

    name: str
    kind: str
    title: str
    caption: str
    data: dict[str, Any]


@dataclass
class ExperimentResult:
    """The outcome of one experiment."""

    name: str
    title: str
    reference: str
    metrics: dict[str, float | None] = field(default_factory=dict)
    info: dict[str, MetricInfo] = field(default_factory=dict)
    rows: list[Row] = field(default_factory=list)
    figures: list[FigureSpec] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    paper: dict[str, Any] = field(default_factory=dict)
    figure_paths: list[str] = field(default_factory=list)
    drawn: dict[str, bytes] = field(default_factory=dict, repr=False)
    """Figures already drawn, by name: the PNG bytes of :func:`validation.figures.figure_png`
    (the run draws its own while it waits for its second process)."""
    elapsed_s: float = 0.0
    skipped: str | None = None

    def metric(
        self,
        key: str,
        value: Any,
        *,
        better: Better = "lower",
        unit: str = "",
        check: bool = True,
        description: str = "",
    ) -> float | None:
        """Record metric ``<name>.<key>``; NaN and ``None`` are stored as ``None``."""
        full = f"{self.name}.{key}"
        v = None if value is None else float(value)
        if v is not None and not math.isfinite(v):
            v = None
        self.metrics[full] = v
        self.info[full] = MetricInfo(better, unit, check, description)
        return v

    def row(
        self, quantity: str, ours: str, paper: str = "–", truth: str = "", *, detail: bool = False
    ) -> None:
        self.rows.append(Row(quantity, ours, paper, truth, detail))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (figure data left out; the PNGs hold it)."""
        return {
            "title": self.title,
            "reference": self.reference,
            "rows": [asdict(r) for r in self.rows],
            "notes": list(self.notes),
            "paper": self.paper,
            "figures": list(self.figure_paths),
            "elapsed_s": self.elapsed_s,
            "skipped": self.skipped,
        }


def fmt_pct(value: float | None, digits: int = 2) -> str:
    """A fraction as a percentage, ``"–"`` for ``None``."""
    if value is None or not math.isfinite(value):
        return "–"
    return f"{100 * value:.{digits}f} %"


def fmt_num(value: float | None, spec: str = ".4g") -> str:
    """A number with ``spec``, ``"–"`` for ``None``."""
    if value is None or not math.isfinite(value):
        return "–"
    return format(value, spec)


MAP_PANEL_MAX_SIDE = 512
"""Longest side (pixels) of a ``"maps"`` figure's image once its experiment has ended."""


def compact_map_panels(res: ExperimentResult, max_side: int = MAP_PANEL_MAX_SIDE) -> None:
    """Shrink the images of ``res``'s ``"maps"`` figures to at most ``max_side`` pixels a side.

    A panel is drawn a few inches wide: a 1024 × 768 float64 map shows no more
    than its 2 × 2 block means do, at an eighth of the memory, and the run keeps
    every experiment's figures until the report is drawn. Each image becomes the
    float32 mean of ``b × b`` blocks (``b`` the smallest integer that brings the
    longest side within ``max_side``; a partial last block is dropped) and keeps
    its pixel coordinates as the panel's ``"extent"``. The colour scale
    (``vmin``, ``vmax``) was set on the full map and is kept.
    """
    import numpy as np

    for spec in res.figures:
        if spec.kind != "maps":
            continue
        for panel in spec.data.get("panels", []):
            img = np.asarray(panel.get("image"))
            if img.ndim != 2 or max(img.shape) <= max_side:
                continue
            h, w = img.shape
            b = math.ceil(max(h, w) / max_side)
            hb, wb = h // b, w // b
            blocks = img[: hb * b, : wb * b].reshape(hb, b, wb, b)
            panel["image"] = blocks.mean(axis=(1, 3), dtype=np.float64).astype(np.float32)
            panel.setdefault("extent", (0.0, float(wb * b), float(hb * b), 0.0))
