"""Experiment 6 — Table 1 of [PQ]: correlation of output values with ground truth.

For each camera preset (CCD, CMOS) and lighting — outdoor (CIE D65) and
indoor (CIE A, a halogen lamp) — the ColorChecker of
:mod:`validation.experiments.chart` (``config.chart``: ``"analytic"``, exact
spectral integrals on a flat chart, or ``"rendered"``, Mitsuba 3's spectral
render of :func:`pqsim.scenes.colour_checker_scene`), captured by the numpy
synthetic camera, is measured three ways:

* **uncorrected**: one LDR frame as the camera outputs it (20 ms, §6.3),
  the mean pixel value of each patch;
* **corrected (this method)**: the calibrated camera's photoquantity from the
  ``K`` calibration exposures with ``N`` repeats
  (:func:`photoquant.correction.correct`), colour-balanced on the chart's white
  patch (§5.3 — the paper's white chart lit by the scene's light; the
  calibration scene's chart is neutral in camera photoquantity, i.e. lit by
  an equal-energy light), patch means;
* **Hugin** (the paper's third row): the same capture set calibrated with
  Hugin's photometric calibration where Hugin has one — its EMoR response
  (``"Hugin EMoR"``: ``vig_optimize`` on pairs of one pixel in two exposures
  of view 0, one curve for all channels as in Hugin) and its radial
  vignetting (``"Hugin"``: ``vig_optimize``'s ``Vb Vc Vd Vx Vy`` from the
  views' correspondences), no sensor LUT (Hugin has no per-pixel model) —
  with photoquant's merge of the same ``K × N`` chart frames through that
  response (Hugin's own merge needs remapped images; the merge is not what
  the row compares), balanced on the white patch like the corrected row
  (:func:`hugin_measurements`). Without ``vig_optimize`` on ``PATH`` the row
  says so (``apt-get install hugin-tools``).

Each is compared, over the 24 patches × 3 channels, with two ground truths:
the true camera photoquantity (exact ``∫ r_λ E ρ``, or the rendered
patch means, balanced on the white patch like the corrected row) and, as in the paper, the chart maker's CIE
RGB values under D65 (for the indoor scene too: the maker gives D65 values
only). The table entry is Pearson's correlation coefficient; the
truth-based error is eq. 8's mean over the patches against the camera
photoquantity after one global scale fit.

References
----------
.. [PQ] The photoquantity paper: §6.3
   "Linearization and colour-correction", §6.4, Table 1.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_pct
from validation.experiments.shared import Shared, have_colour_science
from validation.metrics import correlation

__all__ = ["run", "chart_measurements", "hugin_measurements", "PAPER", "TITLE", "COLUMNS"]

TITLE = "Table 1: correlation with ground truth"

CACHE_KEYS = ("chart", "chart-pipeline", "pipeline-model", "chart-hdr")
"""The :attr:`~validation.experiments.shared.Shared.cache` entries this experiment reads."""

CHART_HDR_KEPT_BYTES = 32 * 2**20
"""The largest chart HDR capture (its frames) kept for the next correction of it
(:func:`chart_hdr_stack`); a larger one is simulated again each time."""

COLUMNS = (("ccd", "outdoor"), ("ccd", "indoor"), ("cmos", "outdoor"), ("cmos", "indoor"))
"""The paper's columns: CCD outdoor, CCD indoor, CMOS outdoor, CMOS indoor."""

PAPER = {
    "uncorrected": [0.85, 0.63, 0.84, 0.67],
    "corrected": [0.87, 0.84, 0.9, 0.86],
    "hugin": [0.84, 0.76, 0.9, 0.75],
    "columns": ["CCD outdoor", "CCD indoor", "CMOS outdoor", "CMOS indoor"],
}

HUGIN_STEPS = {"response": "Hugin EMoR", "vignetting": "Hugin", "sensor_lut": "None"}
"""The Hugin row's calibration: Hugin's response and vignetting, no sensor LUT."""

NO_HUGIN = (
    "The paper's third row (Hugin) needs Hugin's command-line tools (vig_optimize): "
    "apt-get install hugin-tools."
)


def chart_measurements(
    config: ValidationConfig, shared: Shared, preset: str, label: str, illuminant: str
) -> dict[str, Any]:
    """Capture the chart with ``preset`` under ``illuminant``; patch values (memoised).

    Returns
    -------
    dict
        ``"chart"`` (ChartScene), ``"ldr"`` (24, 3) mean DN of the uncorrected
        frame, ``"ldr_clipped"`` (24, 3) bool (a patch pixel at the clipping
        level), ``"hdr"`` (24, 3) corrected photoquantity balanced on the white
        patch, ``"hdr_unbalanced"`` (24, 3), ``"white_balance"`` (3,),
        ``"truth_camera"`` (24, 3) true photoquantity balanced on the white
        patch, ``"truth_cie"`` (24, 3) CIE RGB under D65, ``"correct_s"``.
    """
    key = ("chart", preset, label)
    if key in shared.cache:
        return shared.cache[key]
    from validation.experiments.chart import patch_means

    cal = shared.calibration(preset)
    chart = shared.chart(illuminant, preset)
    camera, model = cal.camera, cal.model
    ldr_cap = camera.capture(
        chart.l, [config.ldr_exposure_s], 1, rng=shared.stream("chart_ldr", preset, label)
    )
    frame = ldr_cap.frames[0, 0].astype(np.float64)
    sat = np.asarray(camera.saturation_dn, dtype=np.float64)
    ldr = patch_means(frame, chart.boxes)
    clipped = patch_means((frame >= sat).astype(np.float64), chart.boxes) > 0
    stack, hdr_raw, balance, correct_s = _corrected_chart(
        config, shared, preset, label, camera, model, chart
    )
    out = {
        "chart": chart,
        "ldr": ldr,
        "ldr_clipped": clipped,
        "hdr": hdr_raw * balance,
        "hdr_unbalanced": hdr_raw,
        "white_balance": balance,
        "truth_camera": chart.patch_l / chart.patch_l[chart.white_index],
        "truth_cie": np.asarray(chart.cie_rgb),
        "correct_s": correct_s,
        "correct_image_shape": stack.image_shape,
        "correct_frames": stack.n_repeats * stack.n_exposures,
    }
    shared.cache[key] = out
    return out


def _corrected_chart(
    config: ValidationConfig,
    shared: Shared,
    preset: str,
    label: str,
    camera: Any,
    model: Any,
    chart: Any,
) -> tuple[Any, np.ndarray, np.ndarray, float]:
    """The chart's HDR capture (seed stream ``chart_hdr``) corrected with ``model``.

    Returns the stack, the patch means (24, 3), the white patch's balance
    factors and the correction's wall time: the corrected and the Hugin rows
    score the same frames the same way.
    """
    import time

    from photoquant.balance import colour_balance
    from photoquant.correction import correct
    from validation.experiments.chart import patch_means

    stack = chart_hdr_stack(config, shared, preset, label, camera, chart)
    t0 = time.perf_counter()
    corr = correct(stack, model)
    correct_s = time.perf_counter() - t0
    hdr_raw = patch_means(corr.photoquantity, chart.boxes)
    white = chart.boxes[chart.white_index]
    balance = colour_balance(corr.photoquantity, white.tolist(), mask=corr.mask)
    return stack, hdr_raw, balance, correct_s


def chart_hdr_stack(
    config: ValidationConfig, shared: Shared, preset: str, label: str, camera: Any, chart: Any
) -> Any:
    """The chart's HDR capture with ``preset``'s camera (seed stream ``chart_hdr``) as a stack.

    Every camera model scored on the chart corrects these same frames (Table 1's
    rows, Fig. 7, each leaderboard entry): a capture small enough
    (:data:`CHART_HDR_KEPT_BYTES`) is simulated once per preset and label and
    kept in ``shared.cache`` (``"chart-hdr"``) with what its corrections memoise
    (its means and clipping masks); the same seed gives the same frames, so the
    scores are those of a capture simulated for each.
    """
    key = ("chart-hdr", preset, label)
    if key in shared.cache:
        return shared.cache[key]
    hdr_cap = camera.capture(
        chart.l,
        np.asarray(config.exposure_s),
        config.chart_repeats,
        rng=shared.stream("chart_hdr", preset, label),
    )
    stack = hdr_cap.to_stack()
    if stack.frames.nbytes <= CHART_HDR_KEPT_BYTES:
        shared.cache[key] = stack
    return stack


def pipeline_rows(config: ValidationConfig) -> list[tuple[str, str, dict[str, Any]]]:
    """The rows beside "corrected": ``(key, label, calibrate keywords)``, one per pipeline.

    Each profile of :data:`photoquant.profiles.PROFILES` other than the run's
    own (the "corrected" row's, ``config.calibrate_kwargs["profile"]`` or the
    default) gets a row calibrated with that profile alone; the Hugin row
    (:data:`HUGIN_STEPS`) follows when Hugin's ``vig_optimize`` is installed.
    """
    from photoquant.peers import hugin
    from photoquant.profiles import DEFAULT_PROFILE, PROFILES

    run_profile = str(config.calibrate_kwargs.get("profile", DEFAULT_PROFILE)).lower()
    rows: list[tuple[str, str, dict[str, Any]]] = [
        (f"profile_{name}", f"corrected ({name} profile)", {"profile": name})
        for name in PROFILES
        if name.lower() != run_profile
    ]
    if hugin.available():
        rows.append(("hugin", "Hugin", dict(HUGIN_STEPS)))
    return rows


def pipeline_measurements(
    config: ValidationConfig,
    shared: Shared,
    preset: str,
    label: str,
    illuminant: str,
    row: str,
    steps: dict[str, Any],
) -> dict[str, Any]:
    """The chart of :func:`chart_measurements` corrected with another pipeline's camera (memoised).

    The preset's capture set (the one the corrected row's camera comes from)
    is calibrated with ``calibrate(**steps)`` (once per preset and ``row``);
    the chart's HDR frames are the corrected row's (the same seed stream), so
    the rows differ only by the calibration. Returns ``"hdr"`` (24, 3)
    balanced on the white patch, ``"model"``, ``"calibrate_s"`` and
    ``"correct_s"``.
    """
    import time

    key = ("chart-pipeline", row, preset, label)
    if key in shared.cache:
        return shared.cache[key]
    cal = shared.calibration(preset)
    model_key = ("pipeline-model", row, preset)
    if model_key not in shared.cache:
        inputs = shared.calibration_inputs(preset)
        t0 = time.perf_counter()
        # a pipeline without a sensor LUT (Hugin) does not read the irradiance scene
        if str(steps.get("sensor_lut", "")) == "None":
            inputs = dataclasses.replace(inputs, irradiance=None)
        result = inputs.calibrate(seed=cal.calibrate_seed, **steps)
        shared.cache[model_key] = (result, time.perf_counter() - t0)
    model, calibrate_s = shared.cache[model_key]
    chart = shared.chart(illuminant, preset)
    _, hdr_raw, balance, correct_s = _corrected_chart(
        config, shared, preset, label, cal.camera, model, chart
    )
    out = {
        "hdr": hdr_raw * balance,
        "model": model,
        "calibrate_s": calibrate_s,
        "correct_s": correct_s,
    }
    shared.cache[key] = out
    return out


def hugin_measurements(
    config: ValidationConfig, shared: Shared, preset: str, label: str, illuminant: str
) -> dict[str, Any]:
    """The chart corrected with a Hugin-calibrated camera (:data:`HUGIN_STEPS`, memoised)."""
    return pipeline_measurements(
        config, shared, preset, label, illuminant, "hugin", dict(HUGIN_STEPS)
    )


def _chart_note(config: ValidationConfig, shared: Shared) -> str:
    sens = ", ".join(f"{p}: {shared.sensitivities(p)}" for p in config.presets)
    if config.chart == "rendered":
        renders = {
            (label, p): shared.chart(ill, p).render
            for label, ill in config.illuminants
            for p in config.presets
        }
        variants = sorted({r["variant"] for r in renders.values()})
        return (
            "The ColorChecker is rendered by Mitsuba 3 (pqsim.scenes.colour_checker_scene: "
            "40 mm patches on a black board under a uniform sky, BabelColor average "
            f"reflectances) through the camera's spectral sensitivities ({sens}), "
            f"{config.chart_spp} spp, variant {', '.join(variants)}, render seed 0; its "
            "camera-photoquantity truth is the render's mean over each patch region, and "
            "the numpy synthetic camera captures the rendered image."
        )
    return (
        "The ColorChecker is an analytic flat chart, not a render: each patch's photoquantity "
        f"is the exact integral of the camera's spectral sensitivities ({sens}), the "
        "illuminant and the patch reflectance (BabelColor average), captured by the numpy "
        "synthetic camera."
    )


def _eq8_patches(reference: np.ndarray, estimate: np.ndarray) -> float:
    from validation.metrics import relative_error_eq8

    _, stats, _ = relative_error_eq8(reference[:, None, :], estimate[:, None, :])
    return stats.e_mean


def chart_experiment(
    name: str, title: str, where: str, paper: dict, config: ValidationConfig
) -> tuple[ExperimentResult, dict, list[tuple[str, str]]]:
    """The result of a ColorChecker experiment, its lighting and its (preset, lighting) columns.

    The result is marked skipped when colour-science (the spectral data) is missing.
    """
    res = ExperimentResult(name, title, where)
    res.paper = paper
    lighting = dict(config.illuminants)
    if not have_colour_science():
        res.skipped = "needs colour-science for the spectral data: pip install colour-science"
        return res, lighting, []
    columns = [(p, lab) for p, lab in COLUMNS if p in config.presets and lab in lighting]
    return res, lighting, columns


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Correlations of the uncorrected and corrected chart values with both ground truths."""
    shared = shared or Shared(config, seed, workdir)
    res, lighting, columns = chart_experiment("table1", TITLE, "§6.3, §6.4, Table 1", PAPER, config)
    if res.skipped:
        return res
    from photoquant.peers import hugin

    have_hugin = hugin.available()
    extra = pipeline_rows(config)
    rows = ("uncorrected", "corrected", *(key for key, _, _ in extra))
    names = {"uncorrected": "uncorrected", "corrected": "corrected"} | {
        key: name for key, name, _ in extra
    }
    table: dict[tuple[str, str], dict[str, float]] = {}
    times: dict[str, list[str]] = {}
    for preset, label in columns:
        m = chart_measurements(config, shared, preset, label, lighting[label])
        cell: dict[str, float] = {}
        measured = [("uncorrected", m["ldr"]), ("corrected", m["hdr"])]
        for key, _, steps in extra:
            pm = pipeline_measurements(config, shared, preset, label, lighting[label], key, steps)
            measured.append((key, pm["hdr"]))
            times.setdefault(key, []).append(
                f"{preset.upper()} calibration {pm['calibrate_s']:.1f} s"
            )
        for row, values in measured:
            for gt in ("camera", "cie"):
                cell[f"{row}.r_{gt}"] = res.metric(
                    f"{preset}.{label}.{row}.r_{gt}",
                    correlation(m[f"truth_{gt}"], values),
                    better="higher",
                    description=f"correlation of {names[row]} patch values with the "
                    + ("true camera photoquantity" if gt == "camera" else "CIE RGB (D65)"),
                )
            cell[f"{row}.e_mean"] = res.metric(
                f"{preset}.{label}.{row}.e_mean",
                _eq8_patches(m["truth_camera"], values),
                unit="fraction",
                description=f"eq. 8 mean over the patches of {names[row]} vs the camera "
                "photoquantity",
            )
        table[(preset, label)] = cell
    heads = "  ".join(f"{p.upper()}-{lab}" for p, lab in columns)
    paper_idx = [COLUMNS.index(c) for c in columns]
    res.row("columns", heads, "(same)", "")
    for gt, gt_name in (("cie", "CIE RGB (D65)"), ("camera", "camera photoquantity")):
        for row in rows:
            res.row(
                f"r, {names[row]} vs {gt_name}",
                "  ".join(f"{table[c][f'{row}.r_{gt}']:.4f}" for c in columns),
                "  ".join(f"{PAPER[row][i]:.2f}" for i in paper_idx)
                if gt == "cie" and row in PAPER
                else "–",
                (
                    "eq. 8 e_mean: "
                    + " ".join(fmt_pct(table[c][f"{row}.e_mean"], 1) for c in columns)
                )
                if gt == "camera"
                else "",
            )
        if not have_hugin:
            res.row(
                f"r, Hugin vs {gt_name}",
                "not installed",
                "  ".join(f"{PAPER['hugin'][i]:.2f}" for i in paper_idx) if gt == "cie" else "–",
                "needs vig_optimize (apt-get install hugin-tools)",
            )
    hugin_note = (
        "The Hugin row: the capture set calibrated with Hugin's EMoR response (one curve for "
        "all channels, as Hugin) and Hugin's radial vignetting, both fitted by Hugin's "
        "vig_optimize from point pairs the adapter writes (photoquant.peers.hugin), no sensor "
        "LUT; the chart's frames merged through that response by photoquant's merge and "
        "balanced on the white patch like the corrected row"
        + (f" ({'; '.join(sorted(set(times['hugin'])))})." if times.get("hugin") else ".")
        if have_hugin
        else NO_HUGIN
    )
    profile_notes = [
        f"The '{name}' row: the same capture set calibrated with photoquant's "
        f"'{key.removeprefix('profile_')}' profile (photoquant.profiles; "
        f"{'; '.join(sorted(set(times.get(key, []))))}), its chart corrected and balanced "
        "like the corrected row."
        for key, name, _ in extra
        if key.startswith("profile_")
    ]
    res.notes += [
        hugin_note,
        *profile_notes,
        _chart_note(config, shared),
        "The corrected values are balanced on the chart's white patch (the paper's white chart "
        "lit by the scene's light, §5.3); the camera-photoquantity truth is balanced the same "
        "way. The CIE RGB truth is under D65 for both lightings, as the chart maker's values.",
        "colour-science ships measured spectral sensitivities of CMOS cameras only; the CCD "
        "and CMOS presets differ in their response, noise and vignetting "
        "(pqsim.synth_camera.presets).",
    ]
    return res
