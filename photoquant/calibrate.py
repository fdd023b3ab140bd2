"""Off-line calibration (§5 of the paper): response, balance, sensor LUT, vignetting.

:func:`calibrate` composes the steps, each a plain function of its own module:

1. response ``g_λ`` from the exposures of view 0 (:mod:`photoquant.response`),
2. HDR merge of every view and of the irradiance scene (:mod:`photoquant.merge`),
3. sensor LUT ``u`` from the irradiance scene (:mod:`photoquant.flatfield`),
4. vignetting ``m1…m6`` from correspondences across the views
   (:mod:`photoquant.vignetting`, :mod:`photoquant.correspondences`),
5. colour balance ``a_λ`` from the white chart (:mod:`photoquant.balance`).

Order of the balance
--------------------
The paper estimates the balance (§5.3) from the linearised white chart,
before ``u`` and ``v`` are known. Neither ``u`` (normalised per channel) nor
``v`` (its equation is homogeneous per channel) depends on the balance, so by
default (``balance_stage="uniformised"``) photoquant estimates it last, from
the chart divided by ``u·v``: the corrected chart is then exactly neutral even
where the channels' vignetting differs at the chart. ``"linearised"`` is the
paper's order, for reproduction.

Steps whose input is missing are left at identity and say so in
``model.report["notes"]``: without an irradiance scene ``u = 1``; with fewer
than two views ``v = 1``; without a white chart ``a = 1``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np

from photoquant import __version__
from photoquant._checks import validate_method
from photoquant.balance import colour_balance, white_chart_colour
from photoquant.correspondences import (
    find_correspondences_homography,
    sample_image,
    tracks_to_observations,
)
from photoquant.errors import CalibrationError, InputError
from photoquant.flatfield import sensor_lut_IrradianceScene
from photoquant.merge import MERGE_METHODS, MergeResult, merge_stack
from photoquant.model import CameraModel
from photoquant.response import DEFAULT_SMOOTHNESS, recover_response
from photoquant.stack import ExposureStack
from photoquant.vignetting import IDENTITY_VIGNETTING, fit_vignetting, vignetting_map

__all__ = ["calibrate", "calibrate_manifest"]

Progress = Callable[[str], None]


def _check_views(views: Sequence[ExposureStack], irradiance: ExposureStack | None) -> None:
    if isinstance(views, ExposureStack):
        raise InputError(
            "`views` must be a sequence of ExposureStack (wrap a single view in a list)"
        )
    if len(views) == 0:
        raise InputError("`views` is empty: calibration needs at least one view")
    ref = views[0]
    for i, view in enumerate([*views, *([irradiance] if irradiance is not None else [])]):
        name = f"views[{i}]" if i < len(views) else "irradiance"
        if not isinstance(view, ExposureStack):
            raise InputError(f"`{name}` must be an ExposureStack, got {type(view).__name__}")
        if view.image_shape != ref.image_shape or view.n_channels != ref.n_channels:
            raise InputError(
                f"`{name}` has images {view.image_shape} with {view.n_channels} channels, "
                f"views[0] has {ref.image_shape} with {ref.n_channels}"
            )
        if view.bit_depth != ref.bit_depth:
            raise InputError(
                f"`{name}` has bit depth {view.bit_depth}, views[0] has {ref.bit_depth}"
            )


def calibrate(
    views: Sequence[ExposureStack],
    *,
    irradiance: ExposureStack | None = None,
    white_roi: Sequence[int] | None = None,
    correspondences: Sequence[np.ndarray] | None = None,
    response_method: str = "Debevec 1997",
    smoothness: float = DEFAULT_SMOOTHNESS,
    n_samples: int = 2000,
    weighting: str = "hat",
    merge_weighting: str = "hat-quantisation",
    merge_method: str = "Debevec 1997",
    vignetting_method: str = "Extended Goldman-Chen",
    vignetting_normalise: Literal["track", "none"] = "track",
    sample_radius: int = 1,
    balance_stage: Literal["uniformised", "linearised"] = "uniformised",
    seed: int = 0,
    progress: Progress | None = None,
) -> CameraModel:
    """Calibrate a camera from capture stacks (§5 of the paper).

    Parameters
    ----------
    views : sequence of ExposureStack
        The calibration scene seen from ``V`` view directions (camera rotated
        about its centre of projection). ``views[0]`` also gives the response
        and holds the white chart.
    irradiance : ExposureStack, optional
        The optics-free, uniformly lit sensor (§5.4); ``u = 1`` without it.
    white_roi : sequence of 4 int, optional
        White chart box ``[x0, y0, x1, y1]`` in ``views[0]`` (end exclusive).
    correspondences : sequence of ndarray, optional
        Tracks, each ``(n, 3)`` rows ``[view, x, y]`` in pixels. Found
        automatically (feature matching + homography) when not given and
        ``V ≥ 2``.
    response_method, smoothness, n_samples, weighting
        Response recovery (§5.2): method name, β of eq. 7, pixels sampled,
        weighting function (the paper's hat by default).
    merge_weighting : str
        Weighting of the HDR merges (eq. 6), stored in the model for the
        correction. ``"hat-quantisation"`` (default) is the paper's hat reduced
        where one DN is a coarse step in log exposure
        (:func:`photoquant.weighting.weighting_hat_quantisation`); ``"hat"``
        is the paper's exactly.
    merge_method : str
        HDR merge method, a key of :data:`photoquant.merge.MERGE_METHODS`,
        stored in the model for the correction.
    vignetting_method, vignetting_normalise, sample_radius
        Vignetting fit (§5.5): method, residual normalisation, and the
        half-size of the window averaged at each correspondence.
    balance_stage : {"uniformised", "linearised"}
        Where the white chart is read (see the module notes).
    seed : int
        Seed of the response's sample selection (results are deterministic).
    progress : callable, optional
        Called with a short message as each step starts.

    Returns
    -------
    CameraModel
    """
    _check_views(views, irradiance)
    if balance_stage not in ("uniformised", "linearised"):
        raise InputError(
            f"`balance_stage` must be 'uniformised' or 'linearised', got {balance_stage!r}"
        )
    merge_method = validate_method(merge_method, MERGE_METHODS, "merge")
    say = progress or (lambda _msg: None)
    ref = views[0]
    height, width = ref.image_shape
    n_ch = ref.n_channels
    timings: dict[str, float] = {}
    notes: list[str] = []
    report: dict[str, Any] = {"timings_s": timings, "notes": notes}

    # 1. response -----------------------------------------------------------
    say("response")
    t0 = time.perf_counter()
    resp = recover_response(
        ref,
        method=response_method,
        smoothness=smoothness,
        n_samples=n_samples,
        weighting=weighting,
        rng=np.random.default_rng(seed),
    )
    timings["response"] = time.perf_counter() - t0
    report["response"] = {
        "method": response_method,
        "n_samples": resp.n_samples,
        "n_equations": resp.n_equations,
        "residual_rms": resp.residual_rms,
        "monotone_constrained": resp.monotone_constrained,
        "saturation_level": resp.saturation_level,
        "valid_min": resp.valid_min,
    }
    levels, g, sat = resp.levels, resp.log_inverse_response, resp.saturation_level

    def merge(stack: ExposureStack) -> MergeResult:
        return merge_stack(
            stack,
            levels,
            g,
            sat,
            min_level=resp.valid_min,
            weighting=merge_weighting,
            method=merge_method,
        )

    # 2. merge the views ------------------------------------------------------
    say(f"merge {len(views)} view(s)")
    t0 = time.perf_counter()
    merged = [merge(view) for view in views]
    timings["merge_per_view"] = (time.perf_counter() - t0) / len(views)
    report["merge"] = {
        "flagged_fraction_view0": float(merged[0].mask.mean()),
        "all_saturated_view0": int(merged[0].all_saturated.sum()),
        "all_dark_view0": int(merged[0].all_dark.sum()),
    }

    # 3. sensor LUT -----------------------------------------------------------
    t0 = time.perf_counter()
    if irradiance is not None:
        say("sensor LUT")
        irr = merge(irradiance)
        lut_result = sensor_lut_IrradianceScene(irr.photoquantity(), irr.mask)
        lut = lut_result.lut
        report["sensor_lut"] = {
            "n_flagged": lut_result.n_flagged,
            "prnu_std": lut_result.prnu_std,
        }
    else:
        lut = np.ones((height, width, n_ch), dtype=np.float32)
        notes.append("no irradiance scene: sensor LUT left at 1 (identity)")
    timings["sensor_lut"] = time.perf_counter() - t0

    # 4. vignetting -----------------------------------------------------------
    t0 = time.perf_counter()
    uniform = [m.photoquantity() / lut for m in merged]
    if len(views) >= 2:
        say("vignetting")
        if correspondences is None or len(correspondences) == 0:
            found = find_correspondences_homography(uniform)
            tracks = list(found.tracks)
            source = "automatic (SIFT + RANSAC homography)"
        else:
            tracks = [np.asarray(tr, dtype=np.float64) for tr in correspondences]
            source = "given"
        view_idx, xy, track_idx = tracks_to_observations(tracks)
        if view_idx.size and (view_idx.min() < 0 or view_idx.max() >= len(views)):
            raise InputError(
                f"a correspondence names view {int(view_idx.max())}, there are {len(views)} views"
            )
        values = np.full((view_idx.size, n_ch), np.nan)
        for v in range(len(views)):
            sel = view_idx == v
            if np.any(sel):
                values[sel] = sample_image(uniform[v], xy[sel], radius=sample_radius)
        fit = fit_vignetting(
            values,
            xy,
            view_idx,
            track_idx,
            (height, width),
            method=vignetting_method,
            normalise=vignetting_normalise,
        )
        if not np.all(fit.converged):
            raise CalibrationError(f"the vignetting fit cannot be trusted: {fit.message}")
        vig_params = fit.params
        report["vignetting"] = {
            "method": vignetting_method,
            "correspondence_source": source,
            "n_tracks_given": len(tracks),
            "n_tracks": fit.n_tracks,
            "n_pairs": fit.n_pairs,
            "n_observations": fit.n_observations,
            "residual_rms": fit.residual_rms,
            "message": fit.message,
        }
    else:
        vig_params = np.tile(IDENTITY_VIGNETTING, (n_ch, 1))
        notes.append("one view only: vignetting left at 1 (identity)")
    timings["vignetting"] = time.perf_counter() - t0

    # 5. colour balance -------------------------------------------------------
    t0 = time.perf_counter()
    if white_roi is not None:
        say("colour balance")
        linear = merged[0].photoquantity()
        if balance_stage == "uniformised":
            linear = linear / (lut * vignetting_map(vig_params, (height, width)))
        balance = colour_balance(linear, white_roi, mask=merged[0].mask)
        report["balance"] = {
            "stage": balance_stage,
            "white_colour": white_chart_colour(linear, white_roi, merged[0].mask),
        }
    else:
        balance = np.ones(n_ch)
        notes.append("no white chart: colour balance left at 1 (identity)")
    timings["balance"] = time.perf_counter() - t0

    parameters = {
        "photoquant_version": __version__,
        "response_method": response_method,
        "smoothness": float(smoothness),
        "n_samples": int(n_samples),
        "weighting": weighting,
        "merge_weighting": merge_weighting,
        "merge_method": merge_method,
        "vignetting_method": vignetting_method,
        "vignetting_normalise": vignetting_normalise,
        "sample_radius": int(sample_radius),
        "balance_stage": balance_stage,
        "seed": int(seed),
        "n_views": len(views),
        "white_roi": None if white_roi is None else [int(v) for v in white_roi],
    }
    return CameraModel(
        image_shape=(height, width),
        channels=ref.channels,
        bit_depth=ref.bit_depth,
        response_levels=levels,
        log_inverse_response=g,
        saturation_level=sat,
        balance=balance,
        sensor_lut=lut,
        vignetting_params=vig_params,
        response_valid_min=resp.valid_min,
        parameters=parameters,
        report=report,
    )


def calibrate_manifest(
    manifest,
    *,
    allow_outside: bool = False,
    progress_bars: bool = False,
    **kwargs: Any,
) -> CameraModel:
    """Calibrate from a capture manifest (a path or a loaded ``CaptureManifest``).

    Uses ``views``, ``irradiance``, ``white_roi`` and ``correspondences`` of
    the manifest; ``kwargs`` go to :func:`calibrate`.
    """
    from photoquant.io.manifest import CaptureManifest, load_manifest, load_stack

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    views = [load_stack(v, manifest, progress=progress_bars) for v in manifest.views]
    irradiance = (
        load_stack(manifest.irradiance, manifest, progress=progress_bars)
        if manifest.irradiance is not None
        else None
    )
    corr = list(manifest.correspondences) if manifest.correspondences else None
    return calibrate(
        views,
        irradiance=irradiance,
        white_roi=manifest.white_roi,
        correspondences=corr,
        **kwargs,
    )
