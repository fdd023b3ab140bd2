"""Regression check of a validation run against a stored baseline (``--check``).

A baseline (``validation/baselines/default.json`` for the default quick
configuration) stores, for every checked metric, the value of the reference
run (master seed 0), the direction that is better, and a tolerance derived
from the seed-to-seed spread::

    tolerance = max(K_SIGMA · s, REL_FLOOR · |value|, ABS_FLOOR)

where ``s`` is the sample standard deviation of the metric over
``n`` master seeds (each seed draws new noise, new calibration worlds and
new subsets — everything random in the run), ``K_SIGMA = 5``. With ``n = 8``
seeds, ``5 s`` exceeds ``2.5 σ`` with probability ≈ 0.97 even when ``s``
underestimates ``σ`` (χ² with 7 degrees of freedom), so a run with *another*
seed rarely trips a healthy metric, while a run with the baseline's own seed
reproduces it exactly (the floors absorb floating-point differences between
machines). A metric with a preferred direction (errors: lower; correlations:
higher) fails only when it moves the wrong way by more than its tolerance;
one with a target (a slope, an exponent) fails either way. A metric missing
from the run (its experiment failed, or a fit that was trusted in the
baseline is now refused) fails too. Timings are never compared.

Fewer seeds
-----------
With ``n`` seeds the sample spread ``s`` is less certain, so ``K_SIGMA``
grows to keep the false-alarm rate of the ``n = 8`` rule
(:func:`k_sigma_for`): ``K(n) = 2.5 · √((n − 1) / q)`` with ``q`` the
``1 − p₈`` quantile of χ² with ``n − 1`` degrees of freedom and
``p₈ = P(χ²₇ > 7 · 0.25) ≈ 0.97``, so that ``P(K(n) · s > 2.5 σ) = p₈``
for every ``n``: ``K(8) = 5``, ``K(4) ≈ 9.0``, ``K(3) ≈ 14.9``, ``K(2) ≈ 72``.

Formats
-------
``photoquant.validation-baseline/1`` (the stored quick baseline) holds the
run's *conditions* only. ``photoquant.validation-baseline/2``
(:func:`seal_baseline`, written by ``photoquant validate --write-baseline``,
:mod:`validation.regression`) is self-describing: it adds the whole
configuration (profile, each step's method and options, presets — a user
preset file by its SHA-256 and content —, chart, experiments), the
versions of photoquant, Python and the numeric libraries, and a SHA-256
checksum over its canonical JSON, so that a hand-edited file is refused.
A format newer than this code reads is refused, naming it.

``python -m validation.baseline --config quick --seeds 0 1 2 3 4 5 6 7 -o
validation/baselines/default.json`` regenerates the baseline (format 1;
``photoquant validate --write-baseline`` writes format 2).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from validation.config import NOT_CONDITIONS, ValidationError

__all__ = [
    "BASELINE_FORMAT",
    "BASELINE_FORMAT_2",
    "FULL_BASELINE",
    "k_sigma_for",
    "seal_baseline",
    "baseline_checksum",
    "DEFAULT_BASELINE",
    "K_SIGMA",
    "Finding",
    "CheckResult",
    "make_baseline",
    "load_baseline",
    "validate_baseline",
    "check_baseline_applies",
    "check_results",
    "main",
]

BASELINE_FORMAT = "photoquant.validation-baseline/1"
BASELINE_FORMAT_2 = "photoquant.validation-baseline/2"
"""The self-describing format (configuration, versions, checksum)."""
_FORMAT_PREFIX = "photoquant.validation-baseline/"
_FORMATS = {BASELINE_FORMAT: 1, BASELINE_FORMAT_2: 2}
DEFAULT_BASELINE = Path(__file__).resolve().parent / "baselines" / "default.json"
"""The stored baseline of the default (quick) configuration."""
FULL_BASELINE = Path(__file__).resolve().parent / "baselines" / "full.json"
"""The stored baseline of the ``--full`` configuration (format 2)."""

K_SIGMA = 5.0
"""Tolerance in seed-to-seed standard deviations (with 8 seeds; :func:`k_sigma_for`)."""


def k_sigma_for(n_seeds: int) -> float:
    """``K_SIGMA`` for a spread from ``n_seeds`` seeds, at the false-alarm rate of 8 seeds.

    ``K(n) = 2.5 · √((n − 1) / q)``, ``q`` the ``1 − p₈`` quantile of χ²
    with ``n − 1`` degrees of freedom, ``p₈ = P(χ²₇ > 1.75)`` (module notes).

    Examples
    --------
    >>> round(k_sigma_for(8), 6), round(k_sigma_for(3), 1)
    (5.0, 14.9)
    """
    from scipy.stats import chi2

    n = int(n_seeds)
    if n < 2:
        raise ValidationError("a baseline needs runs with at least two seeds for the spread")
    p8 = float(chi2.sf(7 * (2.5 / K_SIGMA) ** 2, 7))
    return float(2.5 * math.sqrt((n - 1) / chi2.ppf(1 - p8, n - 1)))


REL_FLOOR = 1e-6
"""Smallest tolerance relative to the value (floating-point differences between machines)."""
ABS_FLOOR = 1e-9
"""Smallest absolute tolerance."""


@dataclass(frozen=True)
class Finding:
    """One metric that moved (or is missing)."""

    key: str
    kind: str  # "regression", "missing", "improvement"
    value: float | None
    baseline: float | None
    tolerance: float | None
    better: str
    description: str = ""

    def message(self) -> str:
        if self.kind == "missing":
            why = "no value (fit refused)" if self.value is None else "not produced"
            return f"{self.key}: {why}; baseline {_f(self.baseline)} — {self.description}"
        delta = None if self.value is None or self.baseline is None else self.value - self.baseline
        n_tol = (
            f"{abs(delta) / self.tolerance:.1f}× tolerance"
            if delta is not None and self.tolerance
            else ""
        )
        return (
            f"{self.key}: {_f(self.value)} vs baseline {_f(self.baseline)} "
            f"(Δ {_f(delta, signed=True)}, tolerance ±{_f(self.tolerance)}, {n_tol}; "
            f"{self.better} is better) — {self.description}"
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "kind": self.kind,
            "value": self.value,
            "baseline": self.baseline,
            "tolerance": self.tolerance,
            "better": self.better,
            "description": self.description,
        }


def _f(v: float | None, signed: bool = False) -> str:
    if v is None:
        return "none"
    return f"{v:+.4g}" if signed else f"{v:.4g}"


@dataclass
class CheckResult:
    """Outcome of :func:`check_results`."""

    baseline: str
    regressions: list[Finding] = field(default_factory=list)
    improvements: list[Finding] = field(default_factory=list)
    compared: int = 0
    not_run: int = 0
    new: int = 0
    notes: list[str] = field(default_factory=list)
    """What differs without failing the check (versions, a method's resolved options)."""

    @property
    def ok(self) -> bool:
        return not self.regressions

    def summary(self) -> str:
        """Human-readable lines: the verdict, then each regression by name."""
        head = (
            f"check against {self.baseline}: {self.compared} metrics compared, "
            f"{len(self.regressions)} regression(s), {len(self.improvements)} improvement(s)"
            + (f", {self.not_run} not run" if self.not_run else "")
            + (f", {self.new} not in the baseline" if self.new else "")
        )
        lines = [("PASS — " if self.ok else "FAIL — ") + head]
        lines += [f"  {n}" for n in self.notes]
        lines += [f"  REGRESSION {f.message()}" for f in self.regressions]
        if self.improvements:
            lines.append(
                "  improved beyond tolerance (consider regenerating the baseline): "
                + ", ".join(f.key for f in self.improvements)
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "baseline": self.baseline,
            "ok": self.ok,
            "compared": self.compared,
            "not_run": self.not_run,
            "new": self.new,
            "regressions": [f.as_dict() for f in self.regressions],
            "improvements": [f.as_dict() for f in self.improvements],
            "notes": list(self.notes),
        }


# ---------------------------------------------------------------------------- baseline


def make_baseline(
    runs: Sequence[Mapping[str, Any]],
    *,
    k_sigma: float = K_SIGMA,
    rel_floor: float = REL_FLOOR,
    abs_floor: float = ABS_FLOOR,
) -> dict[str, Any]:
    """Build a baseline from the ``results.json`` dicts of runs with different seeds.

    The first run gives the values; all of them give the spread.
    """
    if len(runs) < 2:
        raise ValidationError("a baseline needs runs with at least two seeds for the spread")
    ref = runs[0]
    cond = _conditions(ref)
    for r in runs[1:]:
        if _conditions(r) != cond:
            raise ValidationError("the runs of a baseline must share their configuration")
    metrics: dict[str, Any] = {}
    for key, info in ref["metric_info"].items():
        if not info.get("check", True):
            continue
        vals = [r["metrics"].get(key) for r in runs]
        nums = np.array([v for v in vals if v is not None], dtype=np.float64)
        value = ref["metrics"].get(key)
        spread = float(nums.std(ddof=1)) if nums.size > 1 else 0.0
        scale = abs(value) if value is not None else (float(np.abs(nums).max()) if nums.size else 0)
        tol = max(k_sigma * spread, rel_floor * scale, abs_floor)
        metrics[key] = {
            "value": value,
            "tolerance": tol,
            "spread": spread,
            "mean": float(nums.mean()) if nums.size else None,
            "n_values": int(nums.size),
            "allow_none": bool(any(v is None for v in vals)),
            "better": info.get("better", "lower"),
            "unit": info.get("unit", ""),
            "description": info.get("description", ""),
        }
    return {
        "format": BASELINE_FORMAT,
        "config_name": ref["config"]["name"],
        "conditions": cond,
        "seed": ref["seed"],
        "seeds": [r["seed"] for r in runs],
        "tolerance_rule": {
            "formula": "max(k_sigma * spread, rel_floor * |value|, abs_floor)",
            "spread": "sample standard deviation over the seeds",
            "k_sigma": k_sigma,
            "rel_floor": rel_floor,
            "abs_floor": abs_floor,
        },
        "versions": ref.get("versions", {}),
        "metrics": dict(sorted(metrics.items())),
    }


def _conditions(results: Mapping[str, Any]) -> dict[str, Any]:
    """The run's conditions (:meth:`validation.config.ValidationConfig.conditions`) from its results dict."""
    cfg = dict(results["config"])
    for key in NOT_CONDITIONS:
        cfg.pop(key, None)
    return cfg


_BETTER = ("lower", "higher", "both")
_MAX_BASELINE_BYTES = 16 * 2**20


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _check_metric(where: str, key: Any, ref: Any) -> None:
    """Refuse a baseline metric entry whose fields have the wrong types."""
    if not isinstance(key, str) or not key:
        raise ValidationError(f"{where}: a metric name must be a non-empty string, got {key!r}")
    at = f"{where}: metric {key!r}"
    if not isinstance(ref, dict):
        raise ValidationError(f"{at} must be an object, got {type(ref).__name__}")
    for field_ in ("value", "tolerance", "better"):
        if field_ not in ref:
            raise ValidationError(f"{at} lacks `{field_}`")
    if ref["value"] is not None and not _is_number(ref["value"]):
        raise ValidationError(
            f"{at}: `value` must be a finite number or null, got {ref['value']!r}"
        )
    if not _is_number(ref["tolerance"]) or ref["tolerance"] < 0:
        raise ValidationError(
            f"{at}: `tolerance` must be a finite non-negative number, got {ref['tolerance']!r}"
        )
    if ref["better"] not in _BETTER:
        raise ValidationError(
            f"{at}: `better` must be one of {', '.join(_BETTER)}, got {ref['better']!r}"
        )
    if not isinstance(ref.get("allow_none", False), bool):
        raise ValidationError(
            f"{at}: `allow_none` must be true or false, got {ref['allow_none']!r}"
        )
    for field_ in ("description", "unit"):
        if not isinstance(ref.get(field_, ""), str):
            raise ValidationError(f"{at}: `{field_}` must be a string, got {ref[field_]!r}")
    for field_ in ("spread", "mean"):
        v = ref.get(field_)
        if v is not None and not _is_number(v):
            raise ValidationError(f"{at}: `{field_}` must be a finite number or null, got {v!r}")
    n = ref.get("n_values", 0)
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValidationError(f"{at}: `n_values` must be a non-negative integer, got {n!r}")


def validate_baseline(data: Any, name: str = "baseline") -> dict[str, Any]:
    """Check a parsed baseline: its format, `conditions`, and every metric's fields.

    Returns ``data``; raises :class:`ValidationError` with one line naming the
    first problem (a foreign file, a missing key, a wrong type), so that
    ``--check`` fails before the run rather than with a ``KeyError`` after it.
    """
    if not isinstance(data, dict):
        raise ValidationError(
            f"{name} is not a validation baseline (a JSON object of format "
            f"{BASELINE_FORMAT_2!r} expected, got {type(data).__name__})"
        )
    got = data.get("format")
    if not isinstance(got, str) or got not in _FORMATS:
        newer = _newer_format(got)
        if newer:
            raise ValidationError(
                f"{name} is of a newer format ({got!r}) than this photoquant reads "
                f"(up to {BASELINE_FORMAT_2!r}): upgrade photoquant"
            )
        raise ValidationError(
            f"{name} is not a validation baseline (format {BASELINE_FORMAT_2!r} expected, "
            f"got {str(got)[:80]!r})"
        )
    if _FORMATS[got] >= 2:
        stored = data.get("checksum")
        if not isinstance(stored, dict) or not isinstance(stored.get("sha256"), str):
            raise ValidationError(f"{name} lacks its `checksum` (an object with `sha256`)")
        if stored["sha256"] != baseline_checksum(data):
            raise ValidationError(
                f"{name} was edited after it was written (checksum mismatch): record it again "
                "with photoquant validate --write-baseline"
            )
        if not isinstance(data.get("configuration"), dict):
            raise ValidationError(f"{name} lacks `configuration` (an object)")
        _check_configuration(name, data["configuration"])
    if not isinstance(data.get("metrics"), dict) or not isinstance(data.get("conditions"), dict):
        raise ValidationError(f"{name} lacks `metrics` or `conditions` (objects)")
    if not data["metrics"]:
        raise ValidationError(f"{name} has no metrics: it would check nothing")
    if not isinstance(data.get("config_name", ""), str):
        raise ValidationError(f"{name}: `config_name` must be a string")
    for key, ref in data["metrics"].items():
        _check_metric(name, key, ref)
    return data


_CONFIGURATION_FIELDS: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "conditions": dict,
    "profile": str,
    "steps": dict,
    "presets": list,
    "chart": str,
    "rendered_capture": bool,
    "experiments": list,
}


def _check_configuration(name: str, conf: Mapping[str, Any]) -> None:
    """Refuse a format-2 ``configuration`` whose fields have the wrong types (one line)."""
    for key, kind in _CONFIGURATION_FIELDS.items():
        if not isinstance(conf.get(key), kind):
            raise ValidationError(f"{name}: `configuration.{key}` is missing or of the wrong type")
    for step, entry in conf["steps"].items():
        if not isinstance(entry, dict) or not isinstance(entry.get("method"), str):
            raise ValidationError(f"{name}: `configuration.steps.{step}` must name its method")
        if not isinstance(entry.get("resolved_options", {}), dict):
            raise ValidationError(f"{name}: `configuration.steps.{step}.resolved_options`")
    for preset in conf["presets"]:
        if not isinstance(preset, dict) or not isinstance(preset.get("name"), str):
            raise ValidationError(f"{name}: each of `configuration.presets` must have a `name`")
    if not all(isinstance(e, str) for e in conf["experiments"]):
        raise ValidationError(f"{name}: `configuration.experiments` must be names")


def _newer_format(got: Any) -> bool:
    """Whether ``got`` names a baseline format newer than this code reads."""
    if not isinstance(got, str) or not got.startswith(_FORMAT_PREFIX):
        return False
    tail = got[len(_FORMAT_PREFIX) :]
    return tail.isdigit() and int(tail) > max(_FORMATS.values())


def baseline_checksum(data: Mapping[str, Any]) -> str:
    """SHA-256 of a baseline's canonical JSON (sorted keys, no spaces), ``checksum`` left out."""
    body = {k: v for k, v in data.items() if k != "checksum"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def seal_baseline(base: Mapping[str, Any], configuration: Mapping[str, Any]) -> dict[str, Any]:
    """A format-2 baseline: ``base`` (:func:`make_baseline`) with its configuration and checksum.

    Parameters
    ----------
    base : mapping
        What :func:`make_baseline` returns.
    configuration : mapping
        JSON description of the run (:func:`validation.regression.describe_configuration`).

    Returns
    -------
    dict
        The baseline, values normalised to JSON, with ``checksum.sha256``
        over everything else (:func:`baseline_checksum`).
    """
    from photoquant.utils import to_json_value

    doc = dict(base)
    doc["format"] = BASELINE_FORMAT_2
    doc["configuration"] = configuration
    doc = json.loads(json.dumps(to_json_value(doc), allow_nan=False))
    doc.pop("checksum", None)
    doc["checksum"] = {"sha256": baseline_checksum(doc)}
    return doc


def load_baseline(path: str | Path) -> dict[str, Any]:
    """Read and validate a baseline file (:func:`validate_baseline`).

    The file is read by :func:`photoquant._json.load_json`: too large, too
    deeply nested, ``NaN`` or not JSON is refused with one line.

    Raises
    ------
    ValidationError
        If the file is missing, unreadable, not JSON, not a baseline, or any
        entry has a wrong type or lacks a key.
    """
    from photoquant.utils import load_json

    p = Path(path)
    if not p.exists():
        raise ValidationError(f"baseline {p} does not exist")
    data = load_json(p, f"baseline {p}", error=ValidationError, max_bytes=_MAX_BASELINE_BYTES)
    return validate_baseline(data, f"baseline {p}")


def check_baseline_applies(
    baseline: Mapping[str, Any], conditions: Mapping[str, Any], *, name: str = "baseline"
) -> None:
    """Refuse, before any run, a baseline made under other conditions.

    ``conditions`` is :meth:`validation.config.ValidationConfig.conditions`
    of the run about to start (normalised to JSON values here). The same
    comparison :func:`check_results` makes on the finished run's results.
    """
    from photoquant.utils import to_json_value

    cond = json.loads(json.dumps(to_json_value(dict(conditions))))
    ref = baseline["conditions"]
    if cond != ref:
        diff = sorted(k for k in set(cond) | set(ref) if cond.get(k) != ref.get(k))
        raise ValidationError(
            f"{name} was made for configuration {baseline.get('config_name')!r} and differs "
            f"from this run in {_condition_names(diff)}"
        )


def _condition_names(names: list[str]) -> str:
    """The conditions' names on one line (a name a baseline file gives with a line
    break or another unprintable character is shown quoted, escaped)."""
    return ", ".join(k if k.isprintable() else repr(k) for k in names)


PEER_ROWS = {"hugin": "photoquant.peers.hugin"}
"""The metric-name parts that are a peer program's rows (Table 1's Hugin column), with the
module that says whether the program is installed: without it, the rows are not run."""


def _expected(key: str, results: Mapping[str, Any], baseline: Mapping[str, Any]) -> bool:
    """Whether the run should have produced ``key``.

    Not when its experiment was not selected, was skipped for a missing
    optional dependency, belongs to a preset that was not run, or is a row of
    a peer program this machine does not have (:data:`PEER_ROWS`); an
    experiment that *failed* is expected (its metrics count as missing).
    """
    import importlib

    from pqsim.synth_camera.presets import CAMERA_PRESETS

    parts = key.split(".")
    if parts[0] not in results.get("experiments_run", []):
        return False
    for peer in set(parts[1:]) & set(PEER_ROWS):
        if not importlib.import_module(PEER_ROWS[peer]).available():
            return False
    skipped = (results.get("experiments", {}).get(parts[0]) or {}).get("skipped")
    if skipped and not str(skipped).startswith("failed"):
        return False
    described = (baseline.get("configuration") or {}).get("presets") or []
    labels = {p.get("name") for p in described if isinstance(p, dict)}
    if len(parts) > 1 and (parts[1] in CAMERA_PRESETS or parts[1] in labels):
        return parts[1] in results.get("presets", [])
    return True


def check_results(
    results: Mapping[str, Any], baseline: Mapping[str, Any], *, name: str = "baseline"
) -> CheckResult:
    """Compare a run's ``results.json`` dict with a baseline.

    Raises
    ------
    ValidationError
        When the baseline was made under other conditions (image size,
        repeats, exposures, sweeps, ...): its tolerances would not apply.
    """
    cond = _conditions(results)
    if cond != baseline["conditions"]:
        diff = sorted(
            k
            for k in set(cond) | set(baseline["conditions"])
            if cond.get(k) != baseline["conditions"].get(k)
        )
        raise ValidationError(
            f"{name} was made for configuration {baseline.get('config_name')!r} and differs "
            f"from this run ({results['config']['name']!r}) in {_condition_names(diff)}"
        )
    out = CheckResult(baseline=name)
    metrics = results["metrics"]
    for key, ref in baseline["metrics"].items():
        if key not in metrics:
            if _expected(key, results, baseline):
                out.regressions.append(
                    Finding(
                        key,
                        "missing",
                        None,
                        ref["value"],
                        ref["tolerance"],
                        ref["better"],
                        ref.get("description", ""),
                    )
                )
            else:
                out.not_run += 1
            continue
        out.compared += 1
        value, base, tol, better = metrics[key], ref["value"], ref["tolerance"], ref["better"]
        desc = ref.get("description", "")
        if value is None or base is None:
            if value is None and base is not None and not ref.get("allow_none", False):
                out.regressions.append(Finding(key, "missing", None, base, tol, better, desc))
            elif value is not None and base is None:
                out.improvements.append(Finding(key, "improvement", value, None, tol, better, desc))
            continue
        delta = value - base
        if not math.isfinite(delta):
            out.regressions.append(Finding(key, "regression", value, base, tol, better, desc))
            continue
        worse = (
            delta > tol
            if better == "lower"
            else -delta > tol
            if better == "higher"
            else abs(delta) > tol
        )
        better_by = (
            -delta > tol if better == "lower" else delta > tol if better == "higher" else False
        )
        if worse:
            out.regressions.append(Finding(key, "regression", value, base, tol, better, desc))
        elif better_by:
            out.improvements.append(Finding(key, "improvement", value, base, tol, better, desc))
    out.new = sum(
        1
        for k, info in results.get("metric_info", {}).items()
        if info.get("check", True) and k not in baseline["metrics"]
    )
    return out


# ---------------------------------------------------------------------------- command


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m validation.baseline``: run several seeds and write a baseline file."""
    from photoquant.io import write_text_atomic
    from validation.config import get_config
    from validation.experiments import run_validation
    from validation.report import results_json

    parser = argparse.ArgumentParser(
        prog="python -m validation.baseline",
        description="Run the validation with several seeds and store a regression baseline "
        "(values of the first seed, tolerances from the spread over all).",
    )
    parser.add_argument("--config", default="quick", help="quick (default), full or tiny")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(8)))
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_BASELINE)
    parser.add_argument("--runs-dir", type=Path, help="also keep each run's results.json here")
    args = parser.parse_args(argv)
    cfg = get_config(args.config)
    runs = []
    for s in args.seeds:
        t0 = time.perf_counter()
        run = run_validation(cfg, s, progress=lambda _m: None)
        text = results_json(run)
        runs.append(json.loads(text))
        if args.runs_dir:
            args.runs_dir.mkdir(parents=True, exist_ok=True)
            write_text_atomic(args.runs_dir / f"results_seed{s}.json", text)
        print(f"seed {s}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    base = make_baseline(runs)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.output, json.dumps(base, indent=1, allow_nan=False) + "\n")
    print(f"baseline with {len(base['metrics'])} metrics written to {args.output}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
