"""Experiment 10 — the paper's profile beside photoquant's, and an ablation of every deviation.

Each preset's capture set is calibrated three ways, with the same frames and
the same seed:

1. ``profile="paper"`` — the paper's choices wherever its text defines them
   (:data:`photoquant.profiles.PROFILES`: 500 random reference points, the
   hat of eq. 6, the balance from the linearised chart, the vignetting
   residual in value units);
2. the paper's profile with *one* of photoquant's deviations
   (:data:`photoquant.profiles.DEVIATIONS`) switched on, for each deviation;
3. ``profile="photoquant"`` — every deviation on (the default).

Every camera is compared with the ground truth by
:func:`validation.compare.compare_with_truth`: ``g`` rms error (ln, worst
channel, where the hat weight ≥ 5 %), balance error (worst channel), sensor
LUT and vignetting map errors (mean relative) and the corrected test
scene's eq. 8 error (mean), beside the scene's physics noise floor. The
table says what each deviation buys on its own; a deviation whose effect
is within the run-to-run noise shows as such.

The comparison scores estimates, not stated uncertainties, so the
paper-profile calibrations here leave their biases unstated
(``uncorrected_bias="ignored"`` on the steps whose paper options state them,
:func:`unstated`): the same estimates (the statement only adds a
reference fit's difference to the stated uncertainty,
``tests/photoquant/test_uncorrected_bias.py``, and on a whole calibration
``tests/validation/test_ablation.py``), without a second fit of the
response and of the vignetting in each of its paper-profile calibrations:
about 4 s of the quick job on 2 cores (2026-12-07).

References
----------
.. [PQ] The photoquantity paper, §5-6.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_pct
from validation.experiments.shared import PIPELINE_QUANTITIES, Shared, pipeline_scores

__all__ = ["run", "TITLE", "QUANTITIES", "unstated", "variants"]

TITLE = "Paper profile, photoquant profile and ablation"

QUANTITIES = PIPELINE_QUANTITIES
"""Metric key, column label and unit of each quantity compared with the truth."""


def unstated(profile: str = "paper") -> dict[str, dict[str, str]]:
    """Step specs turning off every bias statement of ``profile``'s options.

    Examples
    --------
    >>> sorted(unstated())
    ['balance', 'merge', 'response', 'vignetting']
    >>> unstated("photoquant")
    {}
    """
    from photoquant.profiles import profile_steps

    return {
        step: {"uncorrected_bias": "ignored"}
        for step, (_, options) in profile_steps(profile).items()
        if options.get("uncorrected_bias", "ignored") != "ignored"
    }


def variants() -> list[tuple[str, str, dict[str, Any]]]:
    """``(key, label, calibrate keyword arguments)`` of every calibration compared.

    The paper's profile and its one-deviation variants with their biases
    unstated (:func:`unstated`: the module notes say why).
    """
    from photoquant.profiles import DEVIATIONS

    paper = unstated("paper")
    out: list[tuple[str, str, dict[str, Any]]] = [
        ("paper", "paper profile", {"profile": "paper", **paper})
    ]
    for i, dev in enumerate(DEVIATIONS):
        specs = {"profile": "paper", **paper}
        specs[dev.step] = specs.get(dev.step, {}) | dict(dev.options)
        out.append((f"paper+{i}", f"paper + {dev.name}", specs))
    out.append(("photoquant", "photoquant profile", {"profile": "photoquant"}))
    return out


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Calibrate each preset with the paper's profile, each deviation alone and photoquant's."""
    from photoquant.errors import PhotoquantError
    from photoquant.profiles import DEVIATIONS
    from validation._memory import return_free_memory
    from validation.compare import compare_with_truth, read_scene

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("ablation", TITLE, "§5-6; photoquant.profiles")
    res.paper = {"deviations": {d.name: d.why for d in DEVIATIONS}}
    for preset in config.presets:
        cal = shared.calibration(preset)
        floor = None
        # the test scene's frames and manifest read once: every variant corrects them
        manifest, scene = read_scene(cal.manifest)
        for key, label, kwargs in variants():
            shared.say(f"  {preset}: {label}")
            try:
                # the set read once for every variant (calibrate_manifest's inputs), held
                # for the call only: the next preset's replaces it
                model = shared.calibration_inputs(preset).calibrate(
                    seed=cal.calibrate_seed, **kwargs
                )
                rep = compare_with_truth(manifest, model, cal.truth, scene=scene)
                del model  # not held while the next variant calibrates
            except PhotoquantError as exc:
                res.row(f"{preset}: {label}", f"refused: {exc}", detail=False)
                for q, _, unit in QUANTITIES:
                    res.metric(f"{preset}.{key}.{q}", None, unit=unit, check=False)
                continue
            scores = pipeline_scores(rep)
            floor = rep["scene"]["noise_floor_mean"]
            del rep  # its maps are not held while the next variant calibrates
            return_free_memory()  # the freed working set too (0.07 GB off the peak, no time)
            for q, name, unit in QUANTITIES:
                res.metric(
                    f"{preset}.{key}.{q}",
                    scores[q],
                    unit=unit,
                    check=False,
                    description=f"{name} against the truth, {label}",
                )
            res.row(
                f"{preset}: {label}",
                " / ".join(
                    f"{scores[q]:.4f}" if unit == "ln" else fmt_pct(scores[q], 3)
                    for q, _, unit in QUANTITIES
                ),
                "–",
                "g rms / balance / LUT / vignetting / scene",
            )
        del scene  # not held while the next preset's frames are read
        if floor is not None:
            res.metric(
                f"{preset}.scene_noise_floor",
                floor,
                unit="fraction",
                check=False,
                description="physics noise floor of the test scene's e_mean",
            )
            res.row(f"{preset}: test scene noise floor", fmt_pct(floor, 3), "–", "physics")
    res.notes.append(
        "Columns: g rms error (ln, worst channel), balance error (worst channel), sensor LUT and "
        "vignetting map e_mean, test-scene eq. 8 e_mean. 'paper + X' is the paper's profile with "
        "only deviation X of photoquant's switched on. The metrics are reported, not "
        "baseline-checked: the photoquant profile's own are checked by the other experiments."
    )
    for dev in DEVIATIONS:
        res.notes.append(f"{dev.name} ({dev.step}): {dev.why}.")
    return res
