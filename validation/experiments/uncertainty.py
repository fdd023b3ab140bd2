"""The stated uncertainty against the truth: is a photoquantity as far off as it says?

``photoquant correct`` states, beside every photoquantity, the standard
uncertainty of ``ln l``: the frames' noise, the calibration's statistical
errors (the response, the sensor LUT, the vignetting), where the scene's
times were refined, theirs, and where a profile keeps a method with a known
bias (the paper's), that bias measured against the default method on the
same data (:attr:`photoquant.Correction.log_sigma`). On the
simulator the truth shows how far each corrected value actually is. The
capture set's HDR test scene is corrected with the calibrated camera and

    z = (ln l̂ − ln l − ŝ_λ) / σ

is formed per pixel and channel, ``ŝ_λ`` the inverse-variance weighted mean
of ``ln l̂ − ln l`` of channel ``λ`` (the photoquantity is measured up to one
scale per channel: the gauge, one number fitted to tens of thousands). ``σ``
is the stated uncertainty of what the gauge leaves
(:func:`validation.compare.gauge_removed_sigma`): the balance's part, one
constant per channel, is left out, and the response's part is taken relative
to the scene's own mean instead of the white chart's. Where
the stated uncertainty is the actual one, ``z`` is a standard normal
variate: its spread is 1, and the central interval of nominal level ``p``
(``|z| < Φ⁻¹((1 + p)/2)``) holds a share ``p`` of the values. Reported per
camera: the spread and the shares within the nominal 68 % and 95 % intervals
of the whole stated uncertainty and of its noise part alone, and a
reliability diagram (the share within each nominal interval against its
level). A spread above 1 measures what the stated uncertainty leaves out:
the response's bias (a ripple of ``g`` with the bracket's exposure step,
which the fit's covariance cannot see, :doc:`/user-guide/correct`), and any
disturbance of the camera the calibration does not model. One is shown
apart: a mean dark current ``D`` electrons a second, where the capture set's
dark frames were not subtracted, is to eq. 1 the light ``D / (u·v)`` added
to every pixel (:meth:`pqsim.synth_camera.truth.CaptureTruth.dark_current_light`):
no bracket of a lit scene tells it from the scene's own, and it biases the
shadows. ``z`` is then also reported against ``l`` plus that light: the
difference between the two spreads is what the unmodelled dark current
adds.

The metrics are reported, not checked against the stored baseline.

References
----------
.. [GUM] JCGM 100:2008, Evaluation of measurement data — Guide to the
   expression of uncertainty in measurement, §6 (coverage intervals).
.. [Gneiting2007] Gneiting, T., Balabdaoui, F., & Raftery, A. E. (2007).
   Probabilistic forecasts, calibration and sharpness. J. R. Stat. Soc. B
   69(2), 243-268 (the reliability of stated intervals).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, FigureSpec, fmt_num, fmt_pct
from validation.experiments.shared import Shared
from validation.metrics import NOMINAL_LEVELS, interval_shares, normalised_errors

__all__ = ["run", "TITLE", "NOMINAL_LEVELS", "normalised_errors", "interval_shares"]

TITLE = "Stated uncertainty against the truth"

CACHE_KEYS = ("uncertainty",)
"""The :attr:`~validation.experiments.shared.Shared.cache` entries this experiment reads."""


def _stated(shared: Shared, preset: str) -> tuple[Any, np.ndarray | None, bool]:
    """The test scene corrected with its stated uncertainty (once per run), the stated
    uncertainty the comparison's gauge leaves (:func:`validation.compare.gauge_removed_sigma`),
    and whether its capture set's dark frames were subtracted."""
    key = ("uncertainty", preset)
    if key not in shared.cache:
        from photoquant.correction import correct
        from validation.compare import gauge_removed_sigma, read_scene

        cal = shared.calibration(preset)
        manifest, scene = read_scene(cal.manifest)
        result = correct(scene, cal.model, uncertainty="auto")
        stated = gauge_removed_sigma(result, scene, cal.model)
        shared.cache[key] = (result, stated, bool(manifest.dark_subtraction))
    return shared.cache[key]  # type: ignore[no-any-return]


def _shares_row(
    res: ExperimentResult, name: str, z: np.ndarray, label: str, against: str, *, detail: bool
) -> list[float]:
    """Metrics ``{name}.z_spread`` / ``.within_68`` / ``.within_95`` and their row; the shares."""
    shares = interval_shares(z)
    spread = float(z.std()) if z.size else None
    i68, i95 = NOMINAL_LEVELS.index(0.68), NOMINAL_LEVELS.index(0.95)
    res.metric(
        f"{name}.z_spread",
        spread,
        better="both",
        check=False,
        description=f"std of (ln l̂ − ln l − ŝ)/σ, {against} (1: honest)",
    )
    res.metric(f"{name}.within_68", shares[i68], better="both", check=False)
    res.metric(f"{name}.within_95", shares[i95], better="both", check=False)
    preset, _, _ = name.partition(".")
    res.row(
        f"{preset}: z spread, within 68 % / 95 % ({label})",
        f"{fmt_num(spread, '.2f')}, {fmt_pct(shares[i68], 1)} / {fmt_pct(shares[i95], 1)}",
        "1, 68 % / 95 %",
        detail=detail,
    )
    return [float(v) for v in shares]


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Per preset: ``z`` of the corrected test scene against its truth, and its shares."""
    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("uncertainty", TITLE, "GUM §6; the correction's stated uncertainty")
    panels = []
    for preset in config.presets:
        cal = shared.calibration(preset)
        result, stated, dark_subtracted = _stated(shared, preset)
        if stated is None:
            res.notes.append(f"{preset}: no uncertainty stated ({'; '.join(result.notes)})")
            continue
        scene = cal.truth.captures["scene"]
        truth = scene.l
        series = []
        for part, sigma in (("stated", stated), ("noise", result.log_sigma_noise)):
            z = normalised_errors(result.photoquantity, truth, sigma)
            label = "stated uncertainty" if part == "stated" else "its noise part alone"
            shares = _shares_row(
                res, f"{preset}.{part}", z, label, f"σ the {label}", detail=part == "noise"
            )
            series.append({"label": f"{label} ({z.size} values)", "y": shares})
        dark_e = scene.camera.noise.dark_current_e_per_s
        glare = scene.camera.glare is not None and not scene.camera.glare.is_identity
        if dark_e > 0 and not dark_subtracted and not glare:
            # the dark current is light to eq. 1 (pqsim CaptureTruth.dark_current_light):
            # measured against l plus it, the spread is what the statement leaves out
            # of the model's own errors; the difference, what the unmodelled dark adds
            z = normalised_errors(result.photoquantity, truth + scene.dark_current_light(), stated)
            label = "against l + the dark current's light"
            against = "σ the stated uncertainty, l plus the dark current's light"
            shares = _shares_row(res, f"{preset}.stated_dark_light", z, label, against, detail=True)
            series.append({"label": f"stated, {label}", "y": shares})
            res.notes.append(
                f"{preset}: the mean dark current ({dark_e:g} e⁻/s, no dark frames subtracted) "
                "adds to every pixel the light D/(u·v) it is equivalent to, which eq. 1 "
                "cannot tell from the scene's; in the shadows it biases ln l̂ beyond the "
                "stated uncertainty (the row against l + that light shows by how much)"
            )
        series.append({"label": "nominal", "y": list(NOMINAL_LEVELS), "style": "k:"})
        parts = [
            name
            for name, value in (
                ("noise", result.log_sigma_noise),
                ("response", result.log_sigma_response),
                ("sensor LUT", result.log_sigma_sensor_lut),
                ("vignetting", result.log_sigma_vignetting),
                ("exposure times", result.log_sigma_exposure),
                ("merge weighting's bias", result.log_sigma_weighting),
                ("balance", result.log_sigma_balance),
            )
            if value is not None
        ]
        res.row(f"{preset}: parts stated", ", ".join(parts), detail=True)
        panels.append(
            {
                "title": f"{preset}",
                "x": list(NOMINAL_LEVELS),
                "xticks": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0],
                "xlabel": "nominal level of the central interval",
                "ylabel": "share of the values inside it",
                "series": series,
            }
        )
    if panels:
        res.figures.append(
            FigureSpec(
                "uncertainty_reliability",
                "sweep",
                "Stated uncertainty: reliability against the truth",
                "The share of the corrected test scene's values whose error against the "
                "truth lies inside the central interval of each nominal level, for the "
                "whole stated uncertainty and its noise part alone; on the dotted "
                "diagonal the stated uncertainty is the actual one, below it it is too "
                "small.",
                {"panels": panels},
            )
        )
    return res
