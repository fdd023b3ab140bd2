"""Experiment 9 — calibration from a Mitsuba-rendered capture set (light-transport truth).

The other experiments calibrate from the analytic numpy scenes of
:mod:`pqsim.analytic`, whose photoquantities are closed-form. Here each camera
preset captures the scenes of :mod:`pqsim.scenes` rendered spectrally by
Mitsuba 3 (:func:`pqsim.rendered_capture.write_rendered_capture_set`: the
calibration desk with its white paper from ``V`` views cut out of one wide
render, the optics-free irradiance scene, the high-contrast test scene and the
ColorChecker, through the camera's spectral sensitivities), photoquant
calibrates from the written files, and every recovered quantity is compared
with the truth by :func:`validation.compare.compare_with_truth`: response,
balance (against the truth balanced on the paper's true colour), sensor LUT,
vignetting, the corrected test scene beside its physics noise floor, and the
ColorChecker's patches with their correlation to the chart maker's CIE RGB.

The renders carry Monte-Carlo noise (about 1 % per pixel on the views at the
default 64 samples) that is part of the truth, and their noise depends on the
Mitsuba variant (llvm or scalar): the metrics are reported, not checked
against a baseline. The experiment runs in ``--full`` and with
``--rendered-capture``; it needs Mitsuba 3 (``pip install '.[render]'``).

References
----------
.. [PQ] The photoquantity paper: §5.1–5.5
   (calibration scenes), §6.1–6.4 (results).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_pct
from validation.experiments.shared import Shared

__all__ = ["run", "TITLE"]

TITLE = "Calibration from a Mitsuba-rendered capture set (§5, §6)"


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Render, capture, calibrate and compare each preset with its light-transport truth."""
    res = ExperimentResult("rendered", TITLE, "§5.1–5.5, §6")
    if not config.rendered_capture:
        res.skipped = "not in this configuration (--full or --rendered-capture runs it)"
        return res
    from pqsim.render import default_cache_dir, mitsuba_available

    if not mitsuba_available():
        res.skipped = "needs Mitsuba 3: pip install 'photoquant[render]'"
        return res
    from photoquant.calibration import calibrate_manifest
    from pqsim.rendered_capture import write_rendered_capture_set
    from pqsim.synth_camera.truth import load_truth
    from validation.compare import compare_with_truth, comparison_figures

    shared = shared or Shared(config, seed, workdir)
    h, w = config.shape
    cache = config.render_cache or default_cache_dir()
    variants = set()
    for preset in config.presets:
        shared.say(f"  rendered capture set of {preset} ({w}x{h}) ...")
        t0 = time.perf_counter()
        manifest = write_rendered_capture_set(
            Path(workdir) / f"rendered-{preset}",
            config.preset_source(preset),
            resolution=config.shape,
            exposure_s=np.asarray(config.exposure_s),
            n_repeats=config.n_repeats,
            n_views=config.n_views,
            seed=shared.stream("rendered", preset),
            cache_dir=cache,
            progress=False,
            overwrite=True,
            compress_frames=False,
        )
        t_capture = time.perf_counter() - t0
        t0 = time.perf_counter()
        model = calibrate_manifest(manifest)
        t_calibrate = time.perf_counter() - t0
        truth = load_truth(manifest.parent / "truth")
        variants.add(truth.meta.get("mitsuba_variant"))
        rep = compare_with_truth(manifest, model, truth)
        _record(res, preset, model, rep, t_capture, t_calibrate)
        vignetting_maps = comparison_figures(rep, model.channels)[0]
        res.figures.append(
            dataclasses.replace(
                vignetting_maps,
                name=f"rendered_vignetting_{preset}",
                title=f"{preset}, rendered capture set: {vignetting_maps.title}",
                caption=(
                    f"{preset}: recovered − true vignetting per pixel (% of true), calibrated "
                    "from the Mitsuba-rendered views (one wide render cut into V views)."
                ),
            )
        )
    res.notes += [
        f"Rendered with Mitsuba 3 ({', '.join(sorted(str(v) for v in variants))}), "
        f"{w}x{h}, K = {len(config.exposure_s)}, N = {config.n_repeats}, V = {config.n_views}, "
        "64 samples per pixel; the views are cut out of one wide 2x2-supersampled render, "
        "so a scene point has the same rendered radiance in every view. Renders are cached "
        f"in {cache}.",
        "The truth is what reached the sensor: the renders, Monte-Carlo noise included. "
        "The balance and the test scene are compared with the truth balanced on the white "
        "paper's true colour (a calibrated camera makes the paper neutral). The sensor LUT's "
        "error includes the irradiance render's own Monte-Carlo noise (0.1–0.3 % at 64 spp).",
        "These metrics depend on the Mitsuba variant's noise realisation and are not checked "
        "against a baseline.",
    ]
    return res


def _record(res: ExperimentResult, preset: str, model, rep: dict, t_capture, t_calibrate) -> None:
    names = list(model.channels)
    rms = [r["rms"] for r in rep["response"]]
    bal = np.abs(np.asarray(rep["balance"]["channel_error"], dtype=float))
    lut, vig, sc = rep["lut"]["error"], rep["vignetting"]["error"], rep["scene"]
    cc = rep.get("colorchecker")
    # (key, value, unit, better, description); reported, not checked (see the module notes)
    metrics = [
        (
            "response_rms_max",
            max(rms),
            "ln",
            "lower",
            "largest per-channel rms error of g (ln units, gauge removed)",
        ),
        (
            "balance_abs_error_max",
            float(bal.max()),
            "fraction",
            "lower",
            "largest |channel scale / green − 1| on the corrected test scene",
        ),
        ("sensor_lut_e_mean", lut.e_mean, "fraction", "lower", "mean |u_est − u| / u"),
        ("vignetting_e_mean", vig.e_mean, "fraction", "lower", "mean |v_est − v| / v"),
        ("vignetting_e_max", vig.e_max, "fraction", "lower", "max |v_est − v| / v"),
        (
            "scene_e_mean",
            sc["error"].e_mean,
            "fraction",
            "lower",
            "eq. 8 mean error of the corrected test scene",
        ),
        (
            "scene_noise_floor",
            sc["noise_floor_mean"],
            "fraction",
            "lower",
            "the camera physics' prediction of that error",
        ),
        ("capture_s", t_capture, "s", "lower", "render (or cache) + synthetic camera + writing"),
        ("calibrate_s", t_calibrate, "s", "lower", "photoquant calibrate on the written files"),
    ]
    if cc is not None:
        metrics += [
            (
                "colorchecker_e_mean",
                cc["error"].e_mean,
                "fraction",
                "lower",
                "eq. 8 mean error of the 24 patch means",
            ),
            (
                "colorchecker_r_cie_rgb",
                cc.get("r_cie_rgb"),
                "",
                "higher",
                "r of the balanced patches with CIE RGB (D65)",
            ),
        ]
    for key, value, unit, better, description in metrics:
        res.metric(
            f"{preset}.{key}", value, unit=unit, better=better, check=False, description=description
        )
    res.row(
        f"{preset}: g rms (ln) {'/'.join(names)}; balance error",
        " / ".join(f"{v:.4f}" for v in rms) + f"; ≤ {fmt_pct(float(bal.max()))}",
        "–",
        "rendered capture set",
    )
    res.row(
        f"{preset}: LUT e_mean; vignetting e_mean / e_max",
        f"{fmt_pct(lut.e_mean, 3)}; {fmt_pct(vig.e_mean, 3)} / {fmt_pct(vig.e_max)}",
        "–; 1.6 % / 9 %",
        f"PRNU corrected {fmt_pct(rep['lut']['prnu_floor'])}",
    )
    res.row(
        f"{preset}: test scene eq. 8 e_mean / e_max",
        f"{fmt_pct(sc['error'].e_mean)} / {fmt_pct(sc['error'].e_max)}",
        "–",
        f"noise floor {fmt_pct(sc['noise_floor_mean'])}",
    )
    if cc is not None:
        res.row(
            f"{preset}: ColorChecker patches e_mean; r vs CIE RGB",
            f"{fmt_pct(cc['error'].e_mean)}; {cc.get('r_cie_rgb', float('nan')):.4f}",
            "–; 0.84–0.90 (Table 1)",
            "patch means vs the render",
        )
    res.row(
        f"{preset}: time capture / calibrate",
        f"{t_capture:.1f} s / {t_calibrate:.1f} s",
        "< 5 min",
        "",
        detail=True,
    )
