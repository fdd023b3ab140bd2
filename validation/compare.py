"""Compare a calibrated camera with the ground truth of a synthetic capture set.

``photoquant compare MANIFEST --camera CAMERA`` runs :func:`compare_with_truth`:
the capture set written by ``pqsim capture`` (rendered or analytic) names its
ground truth (manifest key ``truth``), and every quantity the calibrator
recovered is compared with it:

* the response ``g`` per channel (rms and largest error in ln units where the
  hat weight is at least 5 %, after removing the gauge);
* the colour balance, as the per-channel scale of the corrected test scene
  against its true photoquantity balanced on the white chart's true colour
  (green-referenced): a calibrated camera makes the white chart neutral;
* the sensor LUT ``u`` and the vignetting map ``v`` (eq. 8 per pixel, no scale
  fitted), with the PRNU the LUT corrects and ``m1…m6`` against the truth;
* the corrected test scene (eq. 8 after one global scale fit), beside the
  noise floor the camera's physics predicts (:mod:`validation.noise_model`);
* the ColorChecker, when the set has one (``pqsim capture`` writes it):
  eq. 8 over the 24 patch means against the rendered truth and their
  correlation, both balanced on the white patch, and the correlation with
  the chart maker's CIE RGB values under D65 (Table 1 of the paper).

The same comparison ends ``photoquant demo``.

References
----------
.. [PQ] The photoquantity paper: eq. 8 (relative
   error), §6.2–6.4, Table 1.
"""

from __future__ import annotations

import dataclasses
import weakref
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.correction import correct
from photoquant.errors import InputError
from photoquant.io import extra_frameset, extra_path, load_manifest, load_stack
from photoquant.model import CameraModel
from photoquant.weighting import weighting_hat_Debevec1997
from validation.experiments.chart import WHITE_PATCH, patch_means
from validation.metrics import (
    channel_scale_ratios,
    correlation,
    map_relative_error,
    relative_error_eq8,
    response_error,
    uncertainty_coverage,
)
from validation.noise_model import (
    predicted_log_error,
    predicted_log_error_with_glare,
    predicted_relative_error,
)
from validation.truth_model import white_reference

__all__ = [
    "channel_scale_variance",
    "compare_with_truth",
    "read_scene",
    "stated_uncertainty_coverage",
    "gauge_removed_sigma",
    "format_comparison",
    "comparison_json",
    "comparison_figures",
    "write_comparison_figures",
]


def read_scene(manifest: Any, *, allow_outside: bool = False) -> tuple[Any, Any]:
    """A capture set's manifest (loaded when given a path) and its test scene's frames.

    The frames are read as :func:`photoquant.correction.correct_manifest` reads
    them (``load_stack(manifest.scene, manifest)``), for a caller that corrects
    them with several cameras or scores them more than once (pass them to
    :func:`compare_with_truth` as ``scene``).

    Raises
    ------
    InputError
        If the manifest has no ``scene`` frames.
    """
    from photoquant.io import CaptureManifest

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if manifest.scene is None:
        raise InputError(f"{manifest.path} has no `scene` frames to correct")
    return manifest, load_stack(manifest.scene, manifest)


def stated_uncertainty_coverage(
    result: Any, truth_l: np.ndarray, stack: Any, model: CameraModel
) -> dict[str, float] | None:
    """How a correction's stated uncertainty covers the truth
    (:func:`validation.metrics.uncertainty_coverage`, one gauge per channel removed,
    against :func:`gauge_removed_sigma`). ``None`` where the correction states no
    uncertainty."""
    stated = gauge_removed_sigma(result, stack, model)
    if stated is None:
        return None
    return uncertainty_coverage(result.photoquantity, truth_l, stated)


def gauge_removed_sigma(result: Any, stack: Any, model: CameraModel) -> np.ndarray | None:
    """The stated standard uncertainty of ``ln l̂`` less its channel's mean over the
    scene: what is left to compare with the truth once one gauge per channel is
    removed (:func:`validation.metrics.normalised_errors`); ``None`` where the
    correction states none.

    The balance's part is one constant per channel, which the gauge removes with
    it: it is left out. The response's part, as the correction states it, is
    relative to the white chart (the balance reads ``g`` there); the gauge takes
    the scene's own mean away instead, so it is stated relative to that
    (:meth:`~photoquant.ResponseModel.covariance_relative_to` the merge's mean
    loadings over the scene, :func:`photoquant.merge.uncertainty.response_error_of_merge_Debevec1997`).
    Where the response's error is small, the two agree; where it is large and
    smooth (a stated uncorrected bias), the chart's reference would state the
    scene's common offset, which the gauge does not see. The other parts are
    taken as stated (their common part over the scene is a small share of them).
    """
    from photoquant.merge.uncertainty import (
        log_variance_response_Debevec1997,
        response_error_of_merge_Debevec1997,
    )

    stated = result.log_sigma
    if stated is None:
        return None
    var = stated.astype(np.float64) ** 2
    if result.log_sigma_balance is not None:
        var = var - result.log_sigma_balance.astype(np.float64) ** 2
    if result.log_sigma_response is not None and model.merge.method == "Debevec 1997":
        response = model.balanced_response()
        options = model.merge.options
        loadings, rest = response_error_of_merge_Debevec1997(stack, response, options)
        if np.all(np.isfinite(loadings)) and np.all(np.isfinite(rest)):
            scene = response.covariance_relative_to(loadings, rest, "the scene's mean")
            var = (
                var
                - result.log_sigma_response.astype(np.float64) ** 2
                + log_variance_response_Debevec1997(stack, scene, options)
            )
    return np.sqrt(np.maximum(var, 0.0))


def channel_scale_variance(stack: Any, model: CameraModel, mask: np.ndarray) -> np.ndarray | None:
    """The stated variance of each channel's scale on a corrected scene against the
    reference channel's (``ln`` of :func:`validation.metrics.channel_scale_ratios`), ``(C,)``.

    The scale is a mean over the scene's pixels (``~mask``), so the calibration's
    errors that are correlated from pixel to pixel stay in it: the response's
    (:func:`photoquant.merge.uncertainty.response_error_of_merge_Debevec1997`: the
    merge's loadings on ``g``'s error averaged over the scene, with the camera's
    covariance, relative to the white chart) and the vignetting's (the scene's
    mean of ``ln v`` less the chart centre's where the balance read the chart
    after ``÷ u·v``, :meth:`~photoquant.vignetting.base.VignettingModel.log_mean_variance`),
    in the channel and in the reference channel, and the balance's chart noise:
    each where the camera states it. The sensor LUT's error, independent from
    pixel to pixel, averages out. ``None`` where the balance states no uncertainty.
    """
    from photoquant.merge.uncertainty import response_error_of_merge_Debevec1997

    response = model.balanced_response()
    balance = model.balance.log_variance
    if balance is None:
        return None
    var = np.zeros(balance.size)
    if response.covariance_factor is not None and model.merge.method == "Debevec 1997":
        loadings, rest = response_error_of_merge_Debevec1997(stack, response, model.merge.options)
        var = var + np.sum(loadings**2, axis=1) + rest
    centre = None
    if model.balance.chart_roi is not None and model.balance.chart_stage == "uniformised":
        x0, y0, x1, y1 = model.balance.chart_roi
        centre = (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    weights = (~np.asarray(mask, dtype=bool)).astype(np.float64)
    # the response's error is in the loadings above: the map's part inherited from it
    # is not added again (VignettingModel.excluding_response_error)
    vignetting = model.vignetting.excluding_response_error().log_mean_variance(
        stack.image_shape, weights, centre
    )
    if vignetting is not None:
        var = var + vignetting
    ref = 1 if var.size > 1 else 0
    return np.where(np.arange(var.size) == ref, 0.0, var + var[ref] + balance)


def _colour_checker(manifest: Any, model: CameraModel, truth: Any, allow_outside: bool) -> dict:
    """Correct the ColorChecker frames; compare the patch means with the truth."""
    cc = truth.captures["colorchecker"]
    info = manifest.extra["colorchecker"]
    if not isinstance(info, dict):
        raise InputError(f"manifest {manifest.path}: `colorchecker` must be an object")
    rois = _patch_rois(info.get("patch_rois"), cc.l.shape[:2], manifest.path)
    stack = load_stack(
        extra_frameset(manifest, "colorchecker", allow_outside=allow_outside), manifest
    )
    res = correct(stack, model)
    # both balanced on the white patch (Table 1): the camera's balance makes the
    # calibration chart neutral, not this chart's white under this light
    measured = patch_means(res.photoquantity, rois)
    measured = measured / measured[WHITE_PATCH]
    true_l = patch_means(cc.l, rois)
    true_l = true_l / true_l[WHITE_PATCH]
    _, stats, _ = relative_error_eq8(true_l[:, None, :], measured[:, None, :])
    out: dict[str, Any] = {"error": stats, "r_camera": correlation(measured, true_l)}
    ref = _nested(truth.meta, "colorchecker", "reference_D65", "CIE RGB")
    if ref is not None:
        ref = np.asarray(ref, dtype=object)
        if ref.shape != measured.shape or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in ref.ravel()
        ):
            raise InputError(
                f"the truth's `meta.colorchecker.reference_D65.CIE RGB` must be "
                f"{measured.shape[0]} x {measured.shape[1]} numbers"
            )
        out["r_cie_rgb"] = correlation(measured, ref.astype(np.float64))
    return out


def _nested(meta: Any, *keys: str) -> Any:
    """``meta[k0][k1]...``, or None where a level is missing or not an object."""
    for key in keys:
        if not isinstance(meta, dict):
            return None
        meta = meta.get(key)
    return meta


def _patch_rois(value: Any, shape: tuple[int, ...], where: Any) -> np.ndarray:
    """The 24 patch boxes ``(x0, y0, x1, y1)``, checked to lie inside an image of ``shape``."""
    h, w = shape
    bad = InputError(
        f"manifest {where}: `colorchecker.patch_rois` must be 24 boxes [x0, y0, x1, y1] of "
        f"integers with 0 <= x0 < x1 <= {w}, 0 <= y0 < y1 <= {h}"
    )
    if not isinstance(value, list) or len(value) != 24:
        raise bad
    for box in value:
        if (
            not isinstance(box, list | tuple)
            or len(box) != 4
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in box)
        ):
            raise bad
        x0, y0, x1, y1 = box
        if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
            raise bad
    return np.asarray(value, dtype=np.int64)


def _require_captures(truth: Any, names: tuple[str, ...], where: Any) -> None:
    """Refuse a truth set that lacks a capture the comparison needs."""
    captures = getattr(truth, "captures", None)
    if not isinstance(captures, dict):
        raise InputError(f"the truth of {where} has no captures")
    missing = [n for n in names if n not in captures]
    if missing:
        have = ", ".join(sorted(map(str, captures))) or "none"
        raise InputError(
            f"the truth of {where} lacks the capture(s) {', '.join(missing)} (it has: {have})"
        )


def _white_chart_truth(manifest: Any, truth: Any) -> np.ndarray:
    """The white chart's true photoquantity: median of view 0's truth over the white ROI."""
    n_ch = truth.camera.n_channels
    if manifest.white_roi is None or "view0" not in truth.captures:
        return np.ones(n_ch)
    x0, y0, x1, y1 = manifest.white_roi
    roi = truth.captures["view0"].l[y0:y1, x0:x1].reshape(-1, n_ch)
    return np.median(roi, axis=0)


_FLOORS: weakref.WeakKeyDictionary[Any, dict[bool, np.ndarray]] = weakref.WeakKeyDictionary()
"""The scene floors computed for a truth (a :class:`pqsim.synth_camera.truth.TruthSet`),
kept while it lives: every calibration compared with one truth has the same floor."""


def scene_noise_floor(truth: Any, removes_glare: bool) -> np.ndarray:
    """The test scene's expected eq. 8 error per pixel from the camera's noise alone.

    :func:`validation.noise_model.predicted_log_error` (with glare removed from the
    merge where the camera model removes it,
    :func:`~validation.noise_model.predicted_log_error_with_glare`) drawn by
    :func:`~validation.noise_model.predicted_relative_error` (seed 0). It depends on the
    truth alone: computed once per truth object and reused (read-only) by every
    comparison with it (the ablation and the leaderboard compare many calibrations with
    one truth).
    """
    cached = _FLOORS.setdefault(truth, {})
    if removes_glare not in cached:
        cam, scene = truth.camera, truth.captures["scene"]
        noise = predicted_log_error_with_glare if removes_glare else predicted_log_error
        bias, var = noise(cam, scene.l, scene.exposure_s, scene.n_repeats)
        floor = predicted_relative_error(scene.l, var, np.random.default_rng(0), log_bias=bias)
        floor.setflags(write=False)
        cached[removes_glare] = floor
    return cached[removes_glare]


def compare_with_truth(
    manifest: str | Path | Any,
    model: CameraModel,
    truth: Any = None,
    *,
    allow_outside: bool = False,
    uncertainty: bool = False,
    scene: Any = None,
) -> dict[str, Any]:
    """Compare a calibrated camera and its corrections with a capture set's ground truth.

    Parameters
    ----------
    manifest : str, Path or CaptureManifest
        The capture set's manifest (``photoquant.captures/1``) with ``scene``
        frames; unless ``truth`` is given, its ``truth`` key names the truth.
    model : CameraModel
        The camera calibrated from that set (or from another set of the same
        synthetic camera).
    truth : TruthSet, optional
        :func:`pqsim.synth_camera.truth.load_truth`'s result; read from the
        manifest's ``truth`` entry when not given.
    allow_outside : bool
        Allow the manifest's files (and its truth) outside its folder.
    uncertainty : bool
        Also correct the scene with its stated uncertainty and score it against
        the truth (``uncertainty``, :func:`stated_uncertainty_coverage`).
    scene : ExposureStack, optional
        The manifest's ``scene`` frames as :func:`read_scene` reads them; read
        from the files when not given. A caller that compares many cameras
        with one capture set reads them once: the correction and every score
        are the same.

    Returns
    -------
    dict
        ``response`` (per channel ``rms``/``max``), ``balance`` (``factors``,
        ``channel_error``), ``lut`` (``error``, ``prnu_floor``), ``vignetting``
        (``error``, ``params``, ``true_params``), ``scene`` (``error``,
        ``noise_floor_mean``, ``flagged``, ``photoquantity``) and, when the set
        has a ColorChecker, ``colorchecker`` (``error``, ``r_camera``,
        ``r_cie_rgb``); with ``uncertainty``, ``uncertainty`` (``z_spread``,
        ``within_68``, ``within_95``, ``n``; ``None`` where the camera states
        none). Errors are :class:`validation.metrics.ErrorStats`.

    Raises
    ------
    InputError
        If the manifest has no ``scene`` or no ``truth``, or the truth does not
        match the camera (channels, image size).
    """
    from photoquant.io import CaptureManifest
    from pqsim.synth_camera.truth import load_truth

    if not isinstance(model, CameraModel):
        raise InputError(
            f"`model` must be a CameraModel (photoquant.model.load_camera), got "
            f"{type(model).__name__}"
        )
    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if truth is None:
        truth = load_truth(extra_path(manifest, "truth", allow_outside=allow_outside))
    _require_captures(truth, ("scene",), manifest.path)
    cam = truth.camera
    if tuple(cam.channels) != tuple(model.channels):
        raise InputError(
            f"the truth's channels {tuple(cam.channels)} differ from the camera's "
            f"{tuple(model.channels)}"
        )
    if tuple(cam.sensor_lut.shape[:2]) != tuple(model.image_shape):
        raise InputError(
            f"the truth's image size {cam.sensor_lut.shape[:2]} differs from the camera's "
            f"{tuple(model.image_shape)}"
        )
    out: dict[str, Any] = {"response": [], "balance": {}, "lut": {}, "vignetting": {}}
    for ch in range(cam.n_channels):
        w = weighting_hat_Debevec1997(model.response.levels, 0, model.response.saturation_level[ch])
        rms, worst = response_error(
            model.response.log_inverse_response[ch],
            cam.inverse_response_ln(model.response.levels, ch),
            np.where(w >= 0.05, w, 0.0),
        )
        out["response"].append({"rms": rms, "max": worst})
    if scene is None:
        manifest, scene = read_scene(manifest)
    res = correct(scene, model, uncertainty="auto" if uncertainty else False)
    true_scene = truth.captures["scene"]
    # A calibrated camera makes the white chart neutral: it measures l_λ / W_λ,
    # W the chart's true photoquantity (neutral for pqsim's analytic chart, the
    # paper's colour under the lamp for a rendered set). Compare with that.
    white = _white_chart_truth(manifest, truth)
    scene_l = white_reference(true_scene.l, white / white[min(1, white.size - 1)])
    ratios = channel_scale_ratios(scene_l, res.photoquantity, res.mask)
    out["balance"] = {
        "factors": model.balance.factors.tolist(),
        "channel_error": (ratios - 1).tolist(),
        "white_chart_truth": white.tolist(),
    }
    lut_err = map_relative_error(cam.sensor_lut, model.sensor_lut.lut)
    out["lut"] = {"error": lut_err, "prnu_floor": float(np.mean(np.abs(cam.sensor_lut - 1)))}
    out["maps"] = {
        "sensor_lut": (np.asarray(model.sensor_lut.lut, float) - cam.sensor_lut) / cam.sensor_lut,
        "vignetting": (np.asarray(model.vignetting_map(), float) - cam.vignetting) / cam.vignetting,
    }
    out["vignetting"] = {
        "error": map_relative_error(cam.vignetting, model.vignetting_map()),
        "method": model.vignetting.method,
        "params": getattr(model.vignetting, "params", None),
        "true_params": None if cam.vignetting_params is None else np.asarray(cam.vignetting_params),
    }
    if uncertainty:
        out["uncertainty"] = stated_uncertainty_coverage(res, scene_l, scene, model)
    e, stats, _ = relative_error_eq8(scene_l, res.photoquantity, res.mask)
    out["maps"]["scene"] = e
    # with veiling glare that the camera model removes, the floor of the glare-free scene
    # is held to the noise of the light the sensor received (veil included)
    removes_glare = model.glare is not None and not model.glare.is_identity
    floor = scene_noise_floor(truth, removes_glare)
    ok = np.isfinite(e) & np.isfinite(floor)
    out["scene"] = {
        "error": stats,
        "noise_floor_mean": float(floor[ok].mean()),
        "flagged": float(res.mask.any(axis=-1).mean()),
        "photoquantity": res.photoquantity,
    }
    if "colorchecker" in truth.captures and "colorchecker" in manifest.extra:
        out["colorchecker"] = _colour_checker(manifest, model, truth, allow_outside)
    return out


def format_comparison(rep: dict[str, Any], model: CameraModel, title: str) -> str:
    """The comparison as a text table (the demo's and ``photoquant compare``'s output)."""
    ch = model.channels
    lines = [
        "",
        title,
        "",
        "quantity                      recovered vs truth",
        "----------------------------  ---------------------------------------------",
    ]
    for name, r in zip(ch, rep["response"], strict=True):
        lines.append(
            f"response g_{name} (ln units)        rms {r['rms']:.4f}, max {r['max']:.4f} "
            "(gauge removed)"
        )
    bal = ", ".join(
        f"{n} {a:.4f} ({100 * e:+.2f} %)"
        for n, a, e in zip(
            ch, rep["balance"]["factors"], rep["balance"]["channel_error"], strict=True
        )
    )
    lines.append(f"colour balance a               {bal}")
    lut = rep["lut"]
    lines.append(
        f"sensor LUT u                   mean error {100 * lut['error'].e_mean:.3f} % "
        f"(PRNU it corrects: {100 * lut['prnu_floor']:.2f} %), max {100 * lut['error'].e_max:.2f} %"
    )
    vig = rep["vignetting"]
    lines.append(
        f"vignetting map v               e_mean {100 * vig['error'].e_mean:.3f} %, "
        f"e_max {100 * vig['error'].e_max:.3f} % (paper: 1.6 %, 9 %)"
    )
    if vig["params"] is not None and vig["true_params"] is not None:
        for name, p, q in zip(ch, vig["params"], vig["true_params"], strict=True):
            lines.append(
                f"  m1..m6 {name}: "
                + " ".join(f"{v:+.3f}" for v in p)
                + "   truth "
                + " ".join(f"{v:+.3f}" for v in q)
            )
    sc = rep["scene"]
    lines.append(
        f"test scene photoquantity (eq.8) e_mean {100 * sc['error'].e_mean:.3f} %, "
        f"e_max {100 * sc['error'].e_max:.2f} %; noise floor {100 * sc['noise_floor_mean']:.3f} %; "
        f"flagged {100 * sc['flagged']:.2f} %"
    )
    if "uncertainty" in rep:
        cov = rep["uncertainty"]
        lines.append(
            "stated uncertainty (test scene) "
            + (
                "not stated by the camera"
                if cov is None
                else f"z spread {cov['z_spread']:.2f} (1: honest); within the nominal 68 % / "
                f"95 %: {100 * cov['within_68']:.1f} / {100 * cov['within_95']:.1f} %"
            )
        )
    if "colorchecker" in rep:
        cc = rep["colorchecker"]
        cie = f", r vs CIE RGB (D65) {cc['r_cie_rgb']:.4f}" if "r_cie_rgb" in cc else ""
        lines.append(
            f"ColorChecker patches (eq.8)    e_mean {100 * cc['error'].e_mean:.3f} %, "
            f"e_max {100 * cc['error'].e_max:.2f} %; r vs truth {cc['r_camera']:.5f}{cie}"
        )
    return "\n".join(lines)


def comparison_json(rep: dict[str, Any]) -> dict[str, Any]:
    """JSON-ready numbers of a comparison (the corrected image and error maps left out)."""

    def clean(value: Any) -> Any:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return clean(dataclasses.asdict(value))
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if k not in ("photoquantity", "maps")}
        if isinstance(value, list | tuple):
            return [clean(v) for v in value]
        if isinstance(value, np.ndarray):
            return value.tolist()
        if isinstance(value, np.generic):
            return value.item()
        return value

    return clean(rep)


def comparison_figures(rep: dict[str, Any], channels: tuple[str, ...]) -> list[Any]:
    """Figures of a comparison: per-channel error maps of ``v`` and ``u``, the scene's eq. 8 map.

    Returns :class:`validation.experiments.base.FigureSpec` objects for
    :func:`validation.figures.draw_figure`.
    """
    from validation.experiments.base import FigureSpec

    maps = rep["maps"]
    figs = []
    for key, label, what in (
        ("vignetting", "vignetting v", "vignetting_error"),
        ("sensor_lut", "sensor LUT u", "sensor_lut_error"),
    ):
        err = 100 * np.asarray(maps[key], dtype=float)
        lim = float(np.nanmax(np.abs(err))) or 1.0
        panels = [
            {
                "title": f"{name}: recovered − true, e_mean {np.nanmean(np.abs(err[..., c])):.3f} %",
                "image": err[..., c],
                "cmap": "RdBu_r",
                "vmin": -lim,
                "vmax": lim,
                "unit": "% of true",
            }
            for c, name in enumerate(channels)
        ]
        figs.append(
            FigureSpec(what, "maps", f"{label}: relative error per pixel", "", {"panels": panels})
        )
    e = 100 * np.asarray(maps["scene"], dtype=float)  # (H, W): eq. 8 joins the channels
    panels = [
        {
            "title": f"eq. 8 error per pixel, e_mean {np.nanmean(e):.2f} %",
            "image": np.log10(np.maximum(e, 1e-3)),
            "cmap": "magma",
            "vmin": -2.0,
            "vmax": 2.0,
            "unit": "log10(error in %)",
        }
    ]
    figs.append(
        FigureSpec(
            "scene_error",
            "maps",
            "test scene: eq. 8 relative error",
            "",
            {"panels": panels, "ncols": 1},
        )
    )
    return figs


def write_comparison_figures(
    rep: dict[str, Any], channels: tuple[str, ...], folder: str | Path, *, overwrite: bool = False
) -> list[Path]:
    """Draw :func:`comparison_figures` as PNG files into a new ``folder`` (written atomically)."""
    from photoquant.io.atomic import atomic_directory
    from photoquant.io.outputs import figures_folder_problem
    from validation.figures import draw_figure

    specs = comparison_figures(rep, channels)
    target = Path(folder)
    with atomic_directory(target, overwrite=overwrite, replaceable=figures_folder_problem) as tmp:
        for spec in specs:
            draw_figure(spec, tmp / f"{spec.name}.png")
    return [target / f"{spec.name}.png" for spec in specs]
