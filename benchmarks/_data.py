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
) -> HDRStack:
    """The HDR test scene (lamp, deep shadow) through a camera preset, seeded (cached)."""
    cam = camera_from_preset(preset)
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


def log_error_pct(estimate: np.ndarray, data: HDRStack) -> dict[str, float]:
    """Median and RMS relative error (%) of a linear estimate of ``u·v·l`` on the measurable pixels.

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
        d = np.log(e[ok]) - np.log(data.exposure[..., ch][m][ok])
        d -= np.median(d)
        errs.append(d)
    rel = np.abs(np.expm1(np.concatenate(errs)))
    return {
        "median_err_pct": float(100.0 * np.median(rel)),
        "rms_err_pct": float(100.0 * np.sqrt(np.mean(rel**2))),
        "invalid_pct": 100.0 * invalid / max(total, 1),
    }
