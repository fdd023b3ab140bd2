"""Deterministic benchmark inputs from the synthetic camera, and accuracy against its truth."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from pqsim.analytic import scene_test_hdr
from pqsim.synth_camera.presets import camera_from_preset

__all__ = ["HDRStack", "hdr_stack", "true_log_inverse_response", "log_error_pct"]


@dataclass(frozen=True, eq=False)
class HDRStack:
    """A simulated stack and what it truly measures.

    ``frames`` (N, K, H, W, C) integers; ``exposure_s`` (K,); ``exposure``
    the true ``u·v·l`` per pixel (the photoquantity a merge recovers, up to
    one scale per channel); ``measurable`` where some exposure of the pixel
    lies strictly inside the sensor's range (the pixels every merge is
    scored on); ``camera`` the :class:`pqsim.synth_camera.SyntheticCamera`.
    """

    frames: np.ndarray
    exposure_s: np.ndarray
    exposure: np.ndarray
    measurable: np.ndarray
    camera: Any
    scene: np.ndarray

    @property
    def bit_depth(self) -> int:
        return int(self.camera.bit_depth)


@functools.lru_cache(maxsize=4)
def hdr_stack(
    height: int,
    width: int,
    exposures: int,
    repeats: int = 1,
    seed: int = 0,
    preset: str = "ccd",
    t_range: tuple[float, float] = (2.5e-4, 0.64),
    bit_depth: int = 8,
) -> HDRStack:
    """The HDR test scene (lamp, deep shadow) through a camera preset, seeded (cached)."""
    cam = camera_from_preset(preset, bit_depth=bit_depth)
    t = np.geomspace(t_range[0], t_range[1], exposures)
    scene = scene_test_hdr((height, width))
    cap = cam.capture(scene, t, repeats, rng=seed)
    truth = cap.truth.camera
    exposure = truth.sensor_lut * truth.vignetting * scene
    c_max = cam.c_max
    inside = (cap.frames.min(axis=0) > 0) & (cap.frames.max(axis=0) < c_max)
    measurable = inside.any(axis=0) & (exposure > 0)
    for a in (cap.frames, exposure, measurable):
        a.setflags(write=False)
    return HDRStack(cap.frames, cap.exposure_s, exposure, measurable, cam, scene)


def true_log_inverse_response(data: HDRStack) -> tuple[np.ndarray, np.ndarray]:
    """``(levels, g)``: the camera's true ``g_λ`` on every integer level, made finite.

    ``g(0) = −∞`` and ``g`` above a channel's saturation value is undefined;
    both are filled from the nearest defined levels (every merge gives those
    values no or hardly any weight), so that every implementation gets the
    same finite table.
    """
    truth = data.camera.truth((1, 1))
    levels = np.arange(data.camera.c_max + 1, dtype=np.float64)
    g = np.stack([truth.inverse_response_ln(levels, ch) for ch in range(truth.n_channels)])
    for row in g:
        ok = np.isfinite(row)
        idx = np.flatnonzero(ok)
        row[~ok] = np.interp(levels[~ok], levels[idx], row[idx])
        if not ok[0] and idx.size >= 2:  # linear extrapolation below the first defined level
            slope = (row[idx[1]] - row[idx[0]]) / (levels[idx[1]] - levels[idx[0]])
            row[: idx[0]] = row[idx[0]] - slope * (levels[idx[0]] - levels[: idx[0]])
    return levels, g


def camera_model(data: HDRStack, saturation: np.ndarray, *, valid_min: float = 2.0) -> Any:
    """A :class:`photoquant.CameraModel` holding the synthetic camera's true parameters.

    The true ``g`` (balance included: it is in the pixel values), the true
    PRNU ``u`` and vignetting ``v`` (the extended Goldman-Chen parameters of
    the preset), identity balance; the pipeline's merge (hat-quantisation).
    """
    from photoquant.balance import BalanceModel
    from photoquant.defects import DefectMap
    from photoquant.merge import MergeModel
    from photoquant.model import CameraModel
    from photoquant.response.model import ResponseModel
    from photoquant.sensor_lut import SensorLUTModel
    from photoquant.vignetting import ExtendedGoldmanChenVignetting

    levels, g = true_log_inverse_response(data)
    n_ch = g.shape[0]
    truth = data.camera.truth(data.frames.shape[2:4])
    shape = (*data.frames.shape[2:4], n_ch)
    response = ResponseModel(
        "Debevec 1997", levels, g, saturation, valid_min=np.full(n_ch, valid_min)
    )
    return CameraModel(
        image_shape=tuple(data.frames.shape[2:4]),
        channels=tuple(data.camera.channels),
        bit_depth=data.bit_depth,
        response=response,
        merge=MergeModel("Debevec 1997", {"weighting": "hat-quantisation"}),
        balance=BalanceModel.identity(n_ch),
        sensor_lut=SensorLUTModel("Irradiance Scene", truth.sensor_lut.astype(np.float32)),
        vignetting=ExtendedGoldmanChenVignetting(
            "Extended Goldman-Chen", np.asarray(data.camera.vignetting_params, dtype=float)
        ),
        # the preset's sensor has no hot or stuck pixel: the map a calibration stores
        defects=DefectMap(hot=np.zeros(shape, dtype=bool), stuck=np.zeros(shape, dtype=bool)),
    )


def log_error_pct(
    estimate: np.ndarray, data: HDRStack, truth: np.ndarray | None = None
) -> dict[str, float]:
    """Median and RMS relative error (%) of a linear estimate of ``u·v·l`` on the measurable pixels.

    ``truth`` replaces ``u·v·l`` (e.g. the scene's ``l`` for a corrected image).

    Per channel the unknown global scale is removed (the median of
    ``ln estimate − ln truth``); a measurable pixel the estimate leaves
    non-finite or non-positive counts in ``invalid_pct`` and not in the RMS.
    """
    est = np.asarray(estimate, dtype=np.float64)
    errs, invalid, total = [], 0, 0
    for ch in range(est.shape[-1]):
        m = data.measurable[..., ch]
        e = est[..., ch][m]
        ok = np.isfinite(e) & (e > 0)
        invalid += int(np.count_nonzero(~ok))
        total += int(m.sum())
        true = data.exposure if truth is None else truth
        d = np.log(e[ok]) - np.log(true[..., ch][m][ok])
        d -= np.median(d)
        errs.append(d)
    rel = np.abs(np.expm1(np.concatenate(errs)))
    return {
        "median_err_pct": float(100.0 * np.median(rel)),
        "rms_err_pct": float(100.0 * np.sqrt(np.mean(rel**2))),
        "invalid_pct": 100.0 * invalid / max(total, 1),
    }
