"""Experiment 1 — response functions (Fig. 3 of [PQ]): recovered vs true ``g_λ``.

For each camera preset the calibrated log inverse response
``g_λ = ln f_λ⁻¹`` (eq. 7) is compared with the simulator's true one, level by
level, after removing the gauge: ``g`` is recovered up to an additive
constant per channel (the photoquantity's scale, fixed later by the colour
balance), fitted as the weighted mean difference. Levels count with the
paper's hat weight (eq. 6), those below 5 % of its peak and below the lowest
level the response was measured at are left out
(:func:`validation.metrics.response_error`). An error ``δ`` in ``g`` is a
relative error ``δ`` of every photoquantity merged from that level.

The paper shows the curves of its CCD (Fig. 3) without a number: there is no
ground truth for a real camera.

References
----------
.. [PQ] The photoquantity paper: eq. 6, 7;
   §6.1 "Response functions", Fig. 3.
.. [DM97] P. E. Debevec, J. Malik, "Recovering high dynamic range radiance
   maps from photographs", SIGGRAPH 1997, doi:10.1145/258734.258884.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, FigureSpec, fmt_pct
from validation.experiments.shared import Shared

__all__ = ["run", "response_weights", "gauge_offsets", "TITLE"]

TITLE = "Response functions g (Fig. 3)"


def response_weights(model, channel: int) -> np.ndarray:
    """The levels' weights for the comparison: the hat ≥ 5 % of its peak, above ``valid_min``."""
    from photoquant.weighting import weighting_hat_Debevec1997

    levels = model.response.levels
    w = weighting_hat_Debevec1997(levels, 0, model.response.saturation_level[channel])
    w = np.where(w >= 0.05, w, 0.0)
    if model.response.valid_min is not None:
        w = np.where(levels >= model.response.valid_min[channel], w, 0.0)
    return w


def gauge_offsets(model, camera_truth) -> np.ndarray:
    """Per channel the constant ``c_λ`` with ``g_est + c_λ ≈ g_true`` (weighted mean difference)."""
    out = np.empty(len(model.channels))
    for ch in range(out.size):
        w = response_weights(model, ch)
        g_true = camera_truth.inverse_response_ln(model.response.levels, ch)
        d = g_true - model.response.log_inverse_response[ch]
        ok = (w > 0) & np.isfinite(d)
        out[ch] = np.sum(w[ok] * d[ok]) / np.sum(w[ok])
    return out


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Compare each preset's recovered response with the truth; figure of the curves."""
    from validation.metrics import response_error

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("response", TITLE, "§6.1, eq. 7, Fig. 3")
    res.paper = {"note": "Fig. 3 shows the curves of a real CCD; no error is given"}
    curves = {}
    for preset in config.presets:
        cal = shared.calibration(preset)
        model, cam = cal.model, cal.truth.camera
        levels = model.response.levels
        offsets = gauge_offsets(model, cam)
        rms_all, max_all = [], []
        est, true, valid = [], [], []
        for ch, name in enumerate(model.channels):
            w = response_weights(model, ch)
            g_true = cam.inverse_response_ln(levels, ch)
            rms, worst = response_error(model.response.log_inverse_response[ch], g_true, w)
            res.metric(
                f"{preset}.g_rms.{name}",
                rms,
                unit="ln",
                description=f"RMS of g_{name} − g_true after the gauge, hat-weighted",
            )
            res.metric(
                f"{preset}.g_max.{name}",
                worst,
                unit="ln",
                description=f"max |g_{name} − g_true| after the gauge",
            )
            rms_all.append(rms)
            max_all.append(worst)
            est.append(model.response.log_inverse_response[ch] + offsets[ch])
            true.append(np.where(np.isfinite(g_true), g_true, np.nan))
            valid.append(w > 0)
        sat_ok = np.array_equal(np.asarray(model.response.saturation_level), cam.saturation_dn)
        res.metric(
            f"{preset}.saturation_levels_wrong",
            int(np.sum(np.asarray(model.response.saturation_level) != cam.saturation_dn)),
            description="channels whose detected clipping level differs from the truth",
        )
        ch_names = "/".join(model.channels)
        res.row(
            f"{preset}: g rms error {ch_names} (ln, gauge removed)",
            " / ".join(f"{v:.4f}" for v in rms_all),
            "– (Fig. 3: curves only)",
            "≙ " + " / ".join(fmt_pct(v) for v in rms_all) + " in l",
        )
        res.row(
            f"{preset}: g max error {ch_names} (ln)",
            " / ".join(f"{v:.4f}" for v in max_all),
            "–",
            "clipping levels "
            + ("= truth" if sat_ok else "≠ truth")
            + f" ({', '.join(str(int(s)) for s in model.response.saturation_level)})",
        )
        curves[preset] = {
            "levels": levels,
            "channels": list(model.channels),
            "g_est": np.array(est),
            "g_true": np.array(true),
            "valid": np.array(valid),
        }
    res.figures.append(
        FigureSpec(
            "fig3_response",
            "response",
            "Response functions: recovered (solid) vs true (dashed) g = ln f⁻¹",
            "Recovered g_λ (gauge fitted to the truth) and the true g_λ per channel; below, "
            "the difference on the levels that count (hat weight ≥ 5 %). Cf. Fig. 3 of the paper.",
            {"presets": curves},
        )
    )
    res.notes.append(
        "g is defined up to one additive constant per channel (the colour balance fixes the "
        "channels' relative scale, §5.3); the constant is fitted as the hat-weighted mean "
        "difference before the RMS is taken."
    )
    return res
