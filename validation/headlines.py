"""The compact summary ``photoquant validate`` prints: one headline per experiment.

Each experiment's headline is its main figure for every preset, beside the
paper's figure and the physics noise floor where there is one; the full
tables are in ``report.md``. :func:`format_summary` keeps the summary within
:data:`MAX_LINES` lines (a ``--check`` verdict adds its own lines: every
regression is named).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["MAX_LINES", "headlines", "format_summary"]

MAX_LINES = 40
"""Most lines of the summary without a ``--check`` verdict."""

Headline = tuple[str, str, str, str]
"""(what, photoquant's figure, the paper's figure, the noise floor)."""


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100 * v:.2f}"


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "–" if v is None else format(v, fmt)


class _Metrics:
    """Look-ups of one run's metrics by preset, joined as ``a / b``."""

    def __init__(self, metrics: dict[str, float | None], presets: Sequence[str]) -> None:
        self.m = metrics
        self.presets = list(presets)

    def get(self, key: str) -> float | None:
        return self.m.get(key)

    def has(self, pattern: str) -> bool:
        return any(self.m.get(pattern.format(p=p)) is not None for p in self.presets)

    def worst(self, pattern: str, channels: Sequence[str], p: str) -> float | None:
        vals = [self.m.get(pattern.format(p=p, c=c)) for c in channels]
        vals = [abs(v) for v in vals if v is not None]
        return max(vals) if vals else None

    def join(self, pattern: str, fmt: Callable[[float | None], str] = _pct) -> str:
        return " / ".join(fmt(self.m.get(pattern.format(p=p))) for p in self.presets)

    def join_worst(
        self, pattern: str, channels: Sequence[str], fmt: Callable[[float | None], str]
    ) -> str:
        return " / ".join(fmt(self.worst(pattern, channels, p)) for p in self.presets)


def _response(m: _Metrics) -> list[Headline]:
    ours = m.join_worst("response.{p}.g_rms.{c}", "RGB", _num)
    return [("g rms (ln), worst channel", ours, "curves only", "–")]


def _balance(m: _Metrics) -> list[Headline]:
    ours = m.join_worst("balance.{p}.factor_abs_error.{c}", "RB", _pct)
    return [("factor error %, worst channel", ours, "–", "–")]


def _sensor_lut(m: _Metrics) -> list[Headline]:
    return [
        (
            "LUT e_mean %",
            m.join("sensor_lut.{p}.e_mean"),
            "–",
            m.join("sensor_lut.{p}.noise_floor"),
        )
    ]


def _vignetting(m: _Metrics) -> list[Headline]:
    return [("map e_mean %", m.join("vignetting.{p}.e_mean"), "1.6", "–")]


def _noise(m: _Metrics) -> list[Headline]:
    out = []
    if m.has("noise.{p}.n4.e_mean"):
        out.append(
            (
                "N = 4, chart e_mean %",
                m.join("noise.{p}.n4.e_mean"),
                "0.4",
                m.join("noise.{p}.n4.predicted_e_mean"),
            )
        )
    if m.has("noise.{p}.n1_vs_n10.e_mean"):
        out.append(
            (
                "N = 1 vs N = 10 e_mean %",
                m.join("noise.{p}.n1_vs_n10.e_mean"),
                "0.8",
                m.join("noise.{p}.n1_vs_n10.predicted_e_mean"),
            )
        )
    if m.has("noise.{p}.hdr_scene.e_mean"):
        out.append(
            (
                "HDR test scene e_mean %",
                m.join("noise.{p}.hdr_scene.e_mean"),
                "–",
                m.join("noise.{p}.hdr_scene.predicted_e_mean"),
            )
        )
    return out


def _table1(m: _Metrics) -> list[Headline]:
    ours = " / ".join(
        f"{_num(m.get(f'table1.{p}.outdoor.corrected.r_cie'), '.2f')}, "
        f"{_num(m.get(f'table1.{p}.indoor.corrected.r_cie'), '.2f')}"
        for p in m.presets
    )
    return [("r corrected vs CIE, out, in", ours, "0.87, 0.84 / 0.90, 0.86", "–")]


def _uncertainty(m: _Metrics) -> list[Headline]:
    if not m.has("uncertainty.{p}.stated.z_spread"):
        return []
    return [
        (
            "z spread (stated σ vs truth)",
            m.join("uncertainty.{p}.stated.z_spread", lambda v: _num(v, ".2f")),
            "–",
            "1",
        ),
        (
            "within nominal 95 % %",
            m.join("uncertainty.{p}.stated.within_95", lambda v: _num(v and 100 * v, ".1f")),
            "–",
            "95",
        ),
    ] + (
        [
            (
                "z spread vs l + dark light",
                m.join("uncertainty.{p}.stated_dark_light.z_spread", lambda v: _num(v, ".2f")),
                "–",
                "1",
            )
        ]
        if m.has("uncertainty.{p}.stated_dark_light.z_spread")
        else []
    )


def _coverage(m: _Metrics) -> list[Headline]:
    out = []
    for key, quantity in (
        ("lut", "sensor LUT z spread; in 95 %"),
        ("vignetting", "vignetting z spread; in 95 %"),
        ("balance", "balance z spread; in 95 %"),
        ("balance_jackknife", "jackknife g: balance, the same"),
    ):
        pattern = f"coverage.{{p}}.{key}"
        if m.has(pattern + ".spread"):
            spread = m.join(pattern + ".spread", lambda v: _num(v, ".2f"))
            within = m.join(pattern + ".within_95", lambda v: _num(v and 100 * v, ".1f"))
            out.append((quantity, f"{spread}; {within} %", "–", "1; 95 %"))
    return out


def _fig7(m: _Metrics) -> list[Headline]:
    p = m.presets[0]
    key = f"fig7.{p}.outdoor.corrected.cie"
    a, b, r = (m.get(f"{key}.{q}") for q in ("slope", "intercept", "residual_norm"))
    if a is None or b is None or r is None:
        return []
    sign = "+" if b >= 0 else "−"
    ours = f"y = {a:.2f}x {sign} {abs(b):.1f}, res. {r:.0f}"
    return [(f"{p} outdoor, corrected vs CIE", ours, "y = 1.09x − 11.7, res. 126", "–")]


def _timings(m: _Metrics) -> list[Headline]:
    ours = m.join("timings.{p}.calibrate_total_s", lambda v: _num(v, ".2f"))
    return [("calibration time s", ours, "< 300 (1024×768)", "–")]


def _ablation(m: _Metrics) -> list[Headline]:
    return [
        (
            "scene e_mean %, paper profile",
            m.join("ablation.{p}.paper.scene"),
            "–",
            m.join("ablation.{p}.scene_noise_floor"),
        ),
        ("scene e_mean %, photoquant", m.join("ablation.{p}.photoquant.scene"), "–", ""),
    ]


def _rendered(m: _Metrics) -> list[Headline]:
    keys = [k for k in m.m if k.startswith("rendered.") and k.endswith(".scene.e_mean")]
    if not keys:
        return []
    return [("test scene e_mean %", m.join("rendered.{p}.scene.e_mean"), "–", "")]


SHORT = {
    "response": "response (Fig. 3)",
    "balance": "balance (§5.3)",
    "sensor_lut": "sensor LUT (§5.4)",
    "vignetting": "vignetting (Fig. 9)",
    "noise": "noise (§6.3, Fig. 8)",
    "uncertainty": "stated uncertainty",
    "table1": "Table 1",
    "fig7": "Fig. 7",
    "timings": "timings (§6.1)",
    "rendered": "rendered set",
    "ablation": "ablation",
    "leaderboard": "leaderboard",
    "coverage": "coverage over seeds",
    "robustness": "robustness",
    "robustness_pairs": "robustness (pairs)",
}
"""The experiments' short names in the summary (the report has their titles)."""

HEADLINES: dict[str, Callable[[_Metrics], list[Headline]]] = {
    "response": _response,
    "balance": _balance,
    "sensor_lut": _sensor_lut,
    "vignetting": _vignetting,
    "noise": _noise,
    "uncertainty": _uncertainty,
    "coverage": _coverage,
    "table1": _table1,
    "fig7": _fig7,
    "timings": _timings,
    "ablation": _ablation,
    "rendered": _rendered,
}


def _leaderboard(res: Any) -> list[Headline]:
    """The best method of each step, and how many rows failed, were n/a or are not installed."""
    out: list[Headline] = []
    status = {"failed": 0, "n/a": 0, "not installed": 0}
    for row in res.rows:
        step, _, rest = row.quantity.strip().partition(": ")
        if rest.startswith("#1 "):
            out.append((f"best {step} method", rest[3:], "–", ""))
        for key in status:
            if row.ours.startswith(key):
                status[key] += 1
    others = ", ".join(f"{n} {k}" for k, n in status.items() if n)
    if out and others:
        out.append(("rows not ranked", others, "", ""))
    return out


def headlines(run: Any) -> list[tuple[str, list[Headline]]]:
    """Each experiment's short name and headline rows (its first table row when it has none)."""
    metrics: dict[str, float | None] = {}
    for res in run.experiments.values():
        metrics.update(res.metrics)
    m = _Metrics(metrics, run.config.presets)
    out = []
    for name, res in run.experiments.items():
        if res.skipped:
            continue
        if name == "leaderboard":
            rows = _leaderboard(res)
        elif name in HEADLINES:
            rows = HEADLINES[name](m)
        else:
            rows = []
        if all(set(h[1]) <= set("–/, ") for h in rows):  # none of its metrics were measured
            rows = []
        if not rows:
            main = [r for r in res.rows if not r.detail]
            rows = [(main[0].quantity, main[0].ours, main[0].paper, "")] if main else []
        out.append((SHORT.get(name, name), rows))
    return out


def _clip(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


def format_summary(run: Any, check: Any = None, report: Path | str | None = None) -> str:
    """The compact terminal summary: a header, the experiments' headlines, the report's path."""
    cfg = run.config
    presets = " / ".join(cfg.presets)
    lines = [
        f"photoquant validate — {cfg.name}: {cfg.describe()}; seed {run.seed}; "
        f"{run.elapsed_s:.0f} s",
        f"photoquant: synthetic cameras {presets} vs their truth; paper: its real camera; "
        "floor: the camera's noise limit",
        "",
    ]
    head = ("experiment", "quantity", f"photoquant ({presets})", "paper", "floor")
    rows: list[tuple[str, ...]] = []
    for name, hl in headlines(run):
        for i, h in enumerate(hl):
            rows.append((name if i == 0 else "", *h))
    widths = [
        min(max(len(c[j]) for c in [head, *rows]), cap)
        for j, cap in enumerate((20, 30, 34, 26, 13))
    ]

    def fmt(c: Sequence[str]) -> str:
        return "  ".join(_clip(s, w).ljust(w) for s, w in zip(c, widths, strict=True)).rstrip()

    lines += [fmt(head), "  ".join("-" * w for w in widths)]
    lines += [fmt(r) for r in rows]
    budget = MAX_LINES - 3
    if len(lines) > budget:
        lines = lines[: budget - 1] + ["… (more in the report)"]
    if report is not None:
        lines += ["", f"full tables, figures and definitions: {report}"]
    if check is not None:
        lines += ["", check.summary()]
    return "\n".join(lines)
