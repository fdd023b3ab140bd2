"""The benchmark case API: a case builds its data once, times each implementation interleaved.

A :class:`Case` is one row of the benchmark table: a name, a
``setup`` that builds the inputs deterministically (seeded synthetic camera)
and returns a context object, one callable per implementation (ours and the
peers, each ``fn(ctx) -> output``) and an ``accuracy`` function
``accuracy(ctx, impl_name, output) -> {metric: value}`` that scores each
implementation's output against the truth the setup knows. The runner
(:mod:`benchmarks.run`) times the implementations **in one process,
interleaved** (repeat 1 of every implementation, then repeat 2, ...), so
that a machine's slow moments hit every implementation alike, each repeat
starting one implementation further on (*rotated*), so that what an
implementation leaves behind (caches it filled, a heap it released back to
the system) does not always fall on the same successor, and reports
min and median per implementation, the ratio ``ours / peer`` of both, and
each one's accuracy (computed once, on the first run's output).

A module ``benchmarks/bench_*.py`` contributes rows by defining
``cases(config: Config) -> list[Case]``; :func:`discover` collects them.

Example::

    def cases(config: Config) -> list[Case]:
        def setup(cfg: Config) -> dict:
            ...  # build the stack with pqsim, seed cfg.seed
            return {"stack": stack, "truth": truth}

        return [
            Case(
                name="merge-hat",
                title="HDR merge (hat)",
                setup=setup,
                implementations={"photoquant": ours, "OpenCV": peer},
                accuracy=lambda ctx, impl, out: {"rel_err_pct": ...},
            )
        ]

A case on the *user's path* (``user_path=True``) times what a user runs:
the public API with its defaults (``pq.calibrate``, ``pq.calibrate_manifest``,
``pq.correct``) or a whole command as a subprocess, from the inputs a user
has (frames, files). Those are the headline rows; the other cases (kernels,
single steps, data already in memory) are the breakdown beside them, and
the runner writes the two tables in that order.

An implementation may return :class:`Measured` to report metrics measured
by itself (e.g. peak memory from a subprocess) beside its output; a case
with ``timed=False`` is run once per implementation and reports only those
metrics (and ``wall_s``).
"""

from __future__ import annotations

import gc
import importlib
import pkgutil
import statistics
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Case", "Config", "Measured", "CaseResult", "ImplResult", "run_case", "discover"]


@dataclass(frozen=True)
class Config:
    """What every case's setup may read.

    Attributes
    ----------
    width, height : int
        Image size of the timing rows (the issue's 1024×768 by default).
    exposures : int
        ``K`` of the timing rows (8).
    repeats : int
        Timed repeats per implementation (interleaved).
    seed : int
        Seed of every random draw (the synthetic camera's noise, samples).
    quick : bool
        A smoke-size run: cases should shrink anything expensive they do
        beyond ``width × height`` (e.g. the 50 Mpixel memory rows).
    """

    width: int = 1024
    height: int = 768
    exposures: int = 8
    repeats: int = 7
    seed: int = 0
    quick: bool = False

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.height, self.width


@dataclass(frozen=True)
class Measured:
    """An implementation's output with metrics it measured itself (e.g. ``peak_extra_bytes``)."""

    output: Any
    metrics: Mapping[str, float] = field(default_factory=dict)


Implementation = Callable[[Any], Any]
Accuracy = Callable[[Any, str, Any], Mapping[str, float]]


@dataclass(frozen=True)
class Case:
    """One benchmark row.

    Attributes
    ----------
    name : str
        Short identifier (``--only`` selects by it), e.g. ``"merge-hat"``.
    title : str
        The row's label in the Markdown table.
    setup : callable
        ``setup(config) -> ctx``; deterministic in ``config.seed``; not timed.
    implementations : mapping of str to callable
        ``fn(ctx) -> output`` (or :class:`Measured`); the first is *ours*
        unless ``ours`` names another. Names are labels ("photoquant",
        "OpenCV", "colour-hdri", "floor: u8→f32 reduce", ...).
    accuracy : callable, optional
        ``accuracy(ctx, impl_name, output) -> {metric: value}``, against the
        truth; ``{}`` for an implementation it does not score (a floor).
    ours : str, optional
        Which implementation the ratios are taken of (the first by default).
    unit : {"ms", "per_s"}
        How the Markdown shows times: milliseconds, or runs per second
        (e.g. "stacks/s").
    per_s_label : str
        The unit's label for ``"per_s"`` (``"stacks/s"``).
    timed : bool
        False: run each implementation once and report its metrics only.
    notes : str
        A line printed under the row (what the row compares).
    user_path : bool
        A headline row: the public API with its defaults, or a command as a
        subprocess, timed from what a user has (module docstring). False: a
        breakdown row (a kernel, a step, data already in memory).
    """

    name: str
    title: str
    setup: Callable[[Config], Any]
    implementations: Mapping[str, Implementation]
    accuracy: Accuracy | None = None
    ours: str | None = None
    unit: str = "ms"
    per_s_label: str = "runs/s"
    timed: bool = True
    notes: str = ""
    user_path: bool = False

    @property
    def ours_name(self) -> str:
        return self.ours or next(iter(self.implementations))


@dataclass
class ImplResult:
    """One implementation's timings (seconds), accuracy and own metrics."""

    name: str
    times_s: list[float] = field(default_factory=list)
    accuracy: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    error: str | None = None

    @property
    def min_s(self) -> float:
        return min(self.times_s) if self.times_s else float("nan")

    @property
    def median_s(self) -> float:
        return statistics.median(self.times_s) if self.times_s else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "min_s": self.min_s,
            "median_s": self.median_s,
            "times_s": self.times_s,
            "accuracy": self.accuracy,
            "metrics": self.metrics,
            "error": self.error,
        }


@dataclass
class CaseResult:
    """A case's results: per implementation, and the ratios ours / peer."""

    case: Case
    results: dict[str, ImplResult]
    setup_s: float

    def ratios(self) -> dict[str, dict[str, float]]:
        """``{peer: {"min": ours.min / peer.min, "median": ...}}`` (time ratios: < 1 is faster).

        An untimed case's ratios are those of the ``wall_s`` its implementations
        measured themselves (one run: min = median).
        """
        ours = self.results[self.case.ours_name]
        out = {}
        for name, res in self.results.items():
            if name == ours.name:
                continue
            if not self.case.timed:
                a, b = ours.metrics.get("wall_s"), res.metrics.get("wall_s")
                if a is not None and b:
                    out[name] = {"min": a / b, "median": a / b}
                continue
            if not res.times_s or not ours.times_s:
                continue
            out[name] = {"min": ours.min_s / res.min_s, "median": ours.median_s / res.median_s}
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.case.name,
            "title": self.case.title,
            "ours": self.case.ours_name,
            "unit": self.case.unit,
            "notes": self.case.notes,
            "user_path": self.case.user_path,
            "setup_s": self.setup_s,
            "implementations": [r.to_dict() for r in self.results.values()],
            "ratios_ours_over_peer": self.ratios(),
        }


def _call(fn: Implementation, ctx: Any) -> tuple[float, Any]:
    gc.collect()
    t0 = time.perf_counter()
    out = fn(ctx)
    return time.perf_counter() - t0, out


def run_case(case: Case, config: Config, log: Callable[[str], None] | None = None) -> CaseResult:
    """Set ``case`` up, time its implementations interleaved, score their accuracy."""
    t0 = time.perf_counter()
    ctx = case.setup(config)
    setup_s = time.perf_counter() - t0
    results = {name: ImplResult(name) for name in case.implementations}
    repeats = max(1, config.repeats) if case.timed else 1
    order = list(case.implementations)
    for rep in range(repeats):
        shift = rep % len(order)
        for name in order[shift:] + order[:shift]:
            fn = case.implementations[name]
            res = results[name]
            if res.error is not None:
                continue
            try:
                sec, out = _call(fn, ctx)
            except Exception as exc:  # one implementation's failure is its row, not the run's
                lines = str(exc).strip().splitlines() or [""]
                res.error = f"{type(exc).__name__}: {lines[-1]}"
                if log is not None:
                    log(f"  {case.name}: {name} failed: {res.error}")
                continue
            if isinstance(out, Measured):
                if rep == 0:
                    res.metrics.update({k: float(v) for k, v in out.metrics.items()})
                out = out.output
            res.times_s.append(sec)
            if rep == 0 and case.accuracy is not None:
                res.accuracy = {k: float(v) for k, v in case.accuracy(ctx, name, out).items()}
            del out
        if log is not None:
            log(f"  {case.name}: repeat {rep + 1}/{repeats}")
    return CaseResult(case, results, setup_s)


def discover(config: Config) -> list[Case]:
    """Every case of every ``benchmarks.bench_*`` module that defines ``cases(config)``."""
    import benchmarks

    found: list[Case] = []
    for info in sorted(pkgutil.iter_modules(benchmarks.__path__), key=lambda m: m.name):
        if not info.name.startswith("bench_"):
            continue
        module = importlib.import_module(f"benchmarks.{info.name}")
        make = getattr(module, "cases", None)
        if callable(make):
            found.extend(make(config))
    names = [c.name for c in found]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"benchmark case names must be unique, repeated: {dupes}")
    return found
