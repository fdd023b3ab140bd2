"""Experiment 2 — colour balance factors (§5.3 of [PQ]) vs truth.

The calibrated camera outputs *white-balanced* photoquantity: the white chart
of the calibration scene comes out neutral. The balance factors ``a_λ``
themselves are not comparable with the simulator's in-camera balance
directly, because each recovered ``g_λ`` carries its own gauge constant
(§5.2): what must hold is ``g_λ + ln a_λ = g_true,λ + K`` with one ``K`` for
all channels. With ``c_λ`` the fitted gauge of channel λ
(:func:`validation.experiments.response.gauge_offsets`), the factor the truth
implies is ``a*_λ = exp(c_λ − c_G)`` (green is the reference, ``a_G = 1``);
the error is ``a_λ / a*_λ − 1``.

End to end, the HDR test scene is corrected and each channel's median ratio
to the true photoquantity is compared with green's
(:func:`validation.metrics.channel_scale_ratios`): a balanced camera gives 1.

The factors' stated standard uncertainty (the white chart's noise,
:func:`photoquant.balance.balance_log_variance`) is shown beside their
error: the error against the truth-implied factor also holds the recovered
response's error between the chart's level and the gauge's mean over the
levels, which that part does not state. The test scene's channel scale has
its own stated uncertainty (:func:`validation.compare.channel_scale_variance`):
the chart's noise, and the response's and the vignetting's errors relative to
the chart, averaged over the scene, in the channel and in green.

The paper gives no accuracy for the balance (only its time, 1 ms).

References
----------
.. [PQ] The photoquantity paper: §5.3, §6.1
   "Colour balancing".
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult
from validation.experiments.response import gauge_offsets
from validation.experiments.shared import Shared

__all__ = ["run", "TITLE"]

TITLE = "Colour balance factors (§5.3)"


def _signed_pct(values) -> str:
    return " / ".join(f"{100 * v:+.2f} %" for v in values)


def _scene_scale_row(
    res: ExperimentResult,
    preset: str,
    shared: Shared,
    model: Any,
    ratios: np.ndarray,
    names: list[str],
    others: list[int],
) -> None:
    """The test scene's channel scales: their stated uncertainty and error / stated."""
    from validation.compare import channel_scale_variance, read_scene

    corr = shared.scene_correction(preset)
    _, scene = read_scene(shared.calibration(preset).manifest)
    variance = channel_scale_variance(scene, model, corr.mask)
    if variance is None:
        return
    _stated_std_rows(
        res,
        f"{preset}.scene_scale_log_std",
        "stated standard uncertainty of the test scene's {name}/G scale",
        f"{preset}: stated uncertainty of the test scene's scale {{channels}}",
        np.sqrt(variance),
        np.log(ratios),
        names,
        others,
    )


def _stated_std_rows(
    res: ExperimentResult,
    key: str,
    description: str,
    label: str,
    std: np.ndarray,
    log_error: np.ndarray,
    names: list[str],
    others: list[int],
) -> None:
    """A stated standard uncertainty per channel (metrics ``key.<channel>``, reported only)
    and its detail row (``label`` with ``{channels}``) beside the error in units of it
    (``–`` where none is stated)."""
    for ch in others:
        res.metric(
            f"{key}.{names[ch]}",
            float(std[ch]),
            unit="ln",
            better="both",
            check=False,
            description=description.format(name=names[ch]),
        )
    res.row(
        label.format(channels="/".join(names[ch] for ch in others)),
        " / ".join(f"{100 * std[ch]:.3f} %" for ch in others),
        "–",
        "error / stated: "
        + " / ".join(f"{log_error[ch] / std[ch]:+.1f}" if std[ch] > 0 else "–" for ch in others),
        detail=True,
    )


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Compare the recovered balance with the truth, directly and on the corrected test scene."""
    from validation.metrics import channel_scale_ratios

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("balance", TITLE, "§5.3, §6.1")
    res.paper = {"note": "no accuracy given (time 1 ms)"}
    for preset in config.presets:
        cal = shared.calibration(preset)
        model, cam = cal.model, cal.truth.camera
        names = list(model.channels)
        ref = 1 if len(names) > 1 else 0
        a = np.asarray(model.balance.factors, dtype=np.float64)
        c = gauge_offsets(model, cam)
        a_star = np.exp(c - c[ref])
        err = a / a_star - 1
        scene = cal.truth.captures["scene"]
        corr = shared.scene_correction(preset)
        ratios = channel_scale_ratios(scene.l, corr.photoquantity, corr.mask)
        for ch, name in enumerate(names):
            res.metric(
                f"{preset}.factor.{name}",
                a[ch],
                better="both",
                check=False,
                description=f"recovered a_{name}",
            )
            res.metric(
                f"{preset}.factor_truth.{name}",
                a_star[ch],
                better="both",
                check=False,
                description=f"a_{name} implied by the truth and the recovered gauge",
            )
            if ch != ref:
                res.metric(
                    f"{preset}.factor_abs_error.{name}",
                    abs(err[ch]),
                    unit="fraction",
                    description=f"|a_{name} / a*_{name} − 1|",
                )
                res.metric(
                    f"{preset}.scene_abs_error.{name}",
                    abs(ratios[ch] - 1),
                    unit="fraction",
                    description=f"|median(l̂/l)_{name} / median(l̂/l)_G − 1| on the test scene",
                )
        others = [ch for ch in range(len(names)) if ch != ref]
        lbl = "/".join(names[ch] for ch in others)
        res.row(
            f"{preset}: factors a {'/'.join(names)}",
            " / ".join(f"{v:.4f}" for v in a),
            "– (1 ms)",
            "truth-implied " + " / ".join(f"{v:.4f}" for v in a_star),
        )
        res.row(
            f"{preset}: factor error {lbl}",
            _signed_pct(err[others]),
            "–",
            f"test scene channel error {lbl}: {_signed_pct(ratios[others] - 1)}",
        )
        variance = model.balance.log_variance
        if variance is not None:
            _stated_std_rows(
                res,
                f"{preset}.factor_log_std",
                "stated standard uncertainty of ln a_{name} (chart noise)",
                f"{preset}: stated uncertainty of ln a {{channels}} (the chart's noise)",
                np.sqrt(np.asarray(variance, dtype=np.float64)),
                np.log1p(err),
                names,
                others,
            )
        _scene_scale_row(res, preset, shared, model, ratios, names, others)
        res.notes.append(
            f"{preset}: in-camera balance of the simulator a = "
            + " / ".join(f"{v:g}" for v in cam.balance)
            + "; the method's factors undo it together with each channel's gauge."
        )
    return res
