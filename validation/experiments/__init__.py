"""The validation experiments and the run that chains them.

Each experiment is a module with ``run(config, seed, workdir, *, shared=None)
-> ExperimentResult`` (see :mod:`validation.experiments.base`); they are
listed, in the paper's order, in :data:`EXPERIMENTS`.
:func:`run_validation` runs a selection of them on one
:class:`~validation.experiments.shared.Shared` state (so that each camera
preset is simulated and calibrated once) and gathers every metric.

| key | what | paper |
| --- | --- | --- |
| ``response`` | recovered vs true ``g`` | Fig. 3 |
| ``balance`` | colour balance factors | §5.3 |
| ``sensor_lut`` | sensor LUT ``u`` | §5.4 |
| ``vignetting`` | map error, ``m1…m6``, sweeps | Fig. 9 |
| ``noise`` | ``N = 4`` vs truth, ``N = 1`` vs ``N = 10``, ``1/√N`` | §6.3, Fig. 8, app. A |
| ``table1`` | correlation with ground truth | Table 1 |
| ``fig7`` | linear regression | Fig. 7 |
| ``timings`` | step times | §6.1 |
| ``rendered`` | calibration from a Mitsuba-rendered capture set (``--full``) | §5, §6 |
| ``ablation`` | the paper's profile, photoquant's, each deviation alone | §5, §6 |
| ``leaderboard`` | every registered method ranked against the truth | §6 (beyond) |
| ``robustness`` | each real-camera disturbance alone and all together (``--full``) | §3.2 (beyond) |
| ``robustness_pairs`` | every pair of the sensor and output disturbances (when named) | §3.2 (beyond) |

Experiments in :data:`OPT_IN` run by default only when their configuration
flag is on (``robustness``: :attr:`ValidationConfig.robustness`, set by
``--full``); naming them in ``experiments`` runs them on any configuration.
"""

from __future__ import annotations

import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from typing import Any

from validation.config import ValidationConfig, ValidationError
from validation.experiments.base import ExperimentResult

__all__ = ["EXPERIMENTS", "ValidationRun", "run_validation", "package_versions", "RESULTS_FORMAT"]

RESULTS_FORMAT = "photoquant.validation/1"

EXPERIMENTS: dict[str, str] = {
    "response": "validation.experiments.response",
    "balance": "validation.experiments.balance",
    "sensor_lut": "validation.experiments.sensor_lut",
    "vignetting": "validation.experiments.vignetting",
    "noise": "validation.experiments.noise",
    "uncertainty": "validation.experiments.uncertainty",
    "table1": "validation.experiments.table1",
    "fig7": "validation.experiments.fig7",
    "timings": "validation.experiments.timings",
    "rendered": "validation.experiments.rendered",
    "ablation": "validation.experiments.ablation",
    "leaderboard": "validation.experiments.leaderboard",
    "robustness": "validation.experiments.robustness",
    "robustness_pairs": "validation.experiments.robustness_pairs",
}
"""Experiment key → module, in the order of the report (the paper's §6)."""

OPT_IN: dict[str, str] = {"robustness": "robustness", "robustness_pairs": "robustness_pairs"}
"""Experiment key → the :class:`ValidationConfig` flag that includes it in a default run
(a flag the configuration does not have: only when named)."""

REPORTED_ONLY: frozenset[str] = frozenset({"uncertainty"})
"""Experiments whose metrics are reported, never checked by ``--check``: a baseline recorded
before them need not have them."""


@dataclass
class ValidationRun:
    """Everything one run produced."""

    config: ValidationConfig
    seed: int
    experiments: dict[str, ExperimentResult]
    seeds: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0

    @property
    def metrics(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for res in self.experiments.values():
            out.update(res.metrics)
        return dict(sorted(out.items()))

    def to_dict(self) -> dict[str, Any]:
        """The content of ``results.json``."""
        info = {}
        for res in self.experiments.values():
            info.update({k: v.as_dict() for k, v in res.info.items()})
        return {
            "format": RESULTS_FORMAT,
            "config": self.config.as_dict(),
            "seed": self.seed,
            "seeds": dict(sorted(self.seeds.items())),
            "experiments_run": list(self.experiments),
            "presets": list(self.config.presets),
            "metrics": self.metrics,
            "metric_info": dict(sorted(info.items())),
            "experiments": {k: v.to_dict() for k, v in self.experiments.items()},
            "versions": package_versions(),
            "platform": {
                "python": sys.version.split()[0],
                "machine": platform.machine(),
                "system": platform.system(),
                "processor": platform.processor(),
            },
            "elapsed_s": self.elapsed_s,
        }


def package_versions() -> dict[str, str | None]:
    """Versions of photoquant and of the libraries the results depend on (None: missing)."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {}
    for dist in (
        "photoquant",
        "numpy",
        "scipy",
        "opencv-python-headless",
        "OpenEXR",
        "matplotlib",
        "colour-science",
    ):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = None
    import photoquant

    out["photoquant (source)"] = photoquant.__version__
    return out


def _select(names: Sequence[str] | None, config: ValidationConfig | None = None) -> list[str]:
    if names is None:
        return [
            n
            for n in EXPERIMENTS
            if n not in OPT_IN or (config is not None and getattr(config, OPT_IN[n], False))
        ]
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ValidationError(f"unknown experiment(s) {unknown}; valid: {list(EXPERIMENTS)}")
    return [n for n in EXPERIMENTS if n in set(names)]


def run_validation(
    config: ValidationConfig,
    seed: int = 0,
    *,
    experiments: Sequence[str] | None = None,
    workdir: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> ValidationRun:
    """Run the selected experiments (all by default) and gather their results.

    Parameters
    ----------
    config : ValidationConfig
        Settings (:data:`validation.config.QUICK` is the default job).
    seed : int
        Master seed; the same seed gives the same metrics (timings aside).
    experiments : sequence of str, optional
        Keys of :data:`EXPERIMENTS` to run.
    workdir : path, optional
        Where the capture sets are written (kept); a temporary folder,
        removed at the end, by default.
    progress : callable, optional
        Receives step messages (standard error by default).

    Returns
    -------
    ValidationRun
    """
    from photoquant.errors import PhotoquantError
    from photoquant.io.atomic import make_scratch_directory, remove_scratch_directory
    from validation.experiments.shared import Shared

    names = _select(experiments, config)
    keep = workdir is not None
    root = Path(workdir) if keep else make_scratch_directory("photoquant-validate-")
    shared = Shared(config, seed, root, progress)
    t_start = time.perf_counter()
    results: dict[str, ExperimentResult] = {}
    try:
        for i, name in enumerate(names, 1):
            module = import_module(EXPERIMENTS[name])
            shared.say(f"validate: [{i}/{len(names)}] {module.TITLE} ...")
            t0 = time.perf_counter()
            try:
                res = module.run(config, seed, root, shared=shared)
            except PhotoquantError as exc:
                res = ExperimentResult(name, module.TITLE, "")
                res.skipped = f"failed: {exc}"
                shared.say(f"validate: {name} failed: {exc}")
            res.elapsed_s = time.perf_counter() - t0
            results[name] = res
    finally:
        if not keep:
            remove_scratch_directory(root)
    return ValidationRun(
        config=config,
        seed=int(seed),
        experiments=results,
        seeds=dict(shared.seeds),
        elapsed_s=time.perf_counter() - t_start,
    )
