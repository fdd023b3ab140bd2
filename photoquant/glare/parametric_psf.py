"""Glare spread function from a point-source capture: a parametric (Moffat) PSF fitted per channel.

The glare capture is a bracketed HDR capture of a small bright source on a
dark background, as in the glare-spread-function measurements of [TAHL07]_
and the stray-light calibration of [BJA07]_. Merged and divided by ``u`` it
is ``y = (1 − f) x + f K ⊛ x`` (:mod:`photoquant.glare.base`), with ``x``
the source alone. The source's *core* (the connected pixels above ``core_threshold`` of the
peak that hold it, grown by one pixel) is measured directly, ``x ≈ y / (1 − f)`` there
(the glare landing on the core is ``≈ f · A · K(0)`` of it, which biases
``f`` low by that fraction: 7·10⁻⁵ for a source of ``A`` ≈ 50 pixels with
``f`` = 1.5 %, ``w`` = 40 px; 0.2 % with ``f`` = 2 %, ``w`` = 10 px), so the
source's own size and shape need not be known. Away from the core, ``y = f / (1 − f) · K ⊛ y_core``:
the tail is the measured core spread by the kernel.

The fit compares that prediction with the tail in log-spaced annuli about the
source's centroid: each annulus' mean over the same pixels (at most
``max_per_annulus`` of them, evenly strided), and the residual
``ln(predicted) − ln(observed)`` per annulus, so each octave of radius
weighs alike whatever the tail's many decades. The amplitude ``f / (1 − f)``
is profiled out in closed form (the mean log ratio) over a grid of widths, and
the best grid point is refined by :func:`scipy.optimize.least_squares` in
``(ln A, ln w)``; the fit's covariance ``s² (JᵀJ)⁻¹`` gives the
uncertainties in the report. Annuli where fewer than ``min_valid_fraction``
of the pixels have a valid exposure (the far tail sinking into the dark) are
left out: a mean over the pixels that noise lifted above the dark level would
be biased up. Within an annulus, values more than 8 robust standard
deviations (1.4826 · MAD) from its median are left out: hot and stuck
pixels are no glare (the tail varies by ~±15 % across an annulus, well
inside that band). A constant background ``b ≥ 0`` is fitted beside the tail
(``fit_background``): the dark current's mean ``D·t`` electrons reads, at
every exposure alike, as the constant photoquantity ``D / scale``, and stray
ambient light on the dark background is nearly constant too; left out, it
reads as a heavier tail (with the ccd preset's 20 e⁻/s, +1.3 % on ``f``).
Annuli whose pixels' median *best-exposed* value (the highest unsaturated
mean over the exposures, :attr:`~photoquant.glare.GlareData.best_level`)
is below ``min_level`` of the range are left out too: near the dark floor
a merged value is biased up (values at the dark threshold drop out of the
merge, rounding is a large part of the signal). Measured on pqsim's ccd
with the source dimmed to ``l = 30`` (the far tail at 1-2 DN of 255 in the
longest exposure): the annulus means +18 % at 2 DN, +3.5 % at 4 DN, under
0.5 % from 10 DN; the fitted ``f`` 6 % low and the background 3× too high,
then ``f`` within 0.3 % and ``w`` within 0.3 % with the default 3 % floor
(8 DN), and the brighter source's fit unchanged.

References
----------
.. [TAHL07] E.-V. Talvala, A. Adams, M. Horowitz, M. Levoy, "Veiling glare in
   high dynamic range imaging", ACM Trans. Graph. 26(3), 37 (SIGGRAPH 2007).
.. [BJA07] B. Bitlis, P. A. Jansson, J. P. Allebach, "Parametric point spread
   function modeling and reduction of stray light effects in digital still
   cameras", Proc. SPIE 6498, Computational Imaging V, 2007.
.. [MR07] J. J. McCann, A. Rizzi, "Veiling glare: the dynamic range limit of
   HDR images", Proc. SPIE 6492, 2007.
.. [Mof69] A. F. J. Moffat, Astron. Astrophys. 3, 455–461, 1969.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt, label

from photoquant._checks import check_array, check_int, check_positive
from photoquant.errors import CalibrationError, InputError
from photoquant.glare.base import (
    GLARE_METHODS,
    MAX_GLARE_FRACTION,
    GlareData,
    GlareModel,
)
from photoquant.methods import Method, StepFit

__all__ = [
    "ParametricPSFOptions",
    "GlareFit",
    "fit_glare_ParametricPSF",
    "characterise_glare_ParametricPSF",
]


@dataclass(frozen=True)
class ParametricPSFOptions:
    """Options of the ``"Parametric PSF"`` glare fit.

    Attributes
    ----------
    beta : float
        Tail exponent of the Moffat kernel, held fixed (1.5: an ``r⁻³`` tail).
    core_threshold : float
        Pixels above this fraction of the peak are the source's core.
    exclude_px : float
        Tail pixels closer than this to the core are left out (the source's
        edge blur).
    n_annuli : int
        Log-spaced annuli from the core's edge to the farthest valid pixel.
    max_per_annulus : int
        Pixels per annulus at most (evenly strided): bounds the fit's cost.
    min_valid_fraction : float
        Annuli with fewer valid pixels than this fraction are left out.
    fit_background : bool
        Fit a constant background ``b ≥ 0`` beside the tail (module notes).
    min_level : float
        Annuli whose pixels' median best-exposed value
        (:attr:`~photoquant.glare.GlareData.best_level`, a fraction of the
        range) is below this are left out, where the data give it (module
        notes).
    """

    beta: float = 1.5
    core_threshold: float = 1e-2
    exclude_px: float = 2.0
    n_annuli: int = 32
    max_per_annulus: int = 200
    min_valid_fraction: float = 0.9
    fit_background: bool = True
    min_level: float = 0.03

    def __post_init__(self) -> None:
        b = check_positive(self.beta, "beta")
        if not 1.0 < b <= 20.0:
            raise InputError(f"`beta` must lie in (1, 20], got {self.beta}")
        check_positive(self.core_threshold, "core_threshold", maximum=0.5)
        check_positive(self.exclude_px, "exclude_px", allow_zero=True)
        check_int(self.n_annuli, "n_annuli", 4)
        check_int(self.max_per_annulus, "max_per_annulus", 8)
        v = check_positive(self.min_valid_fraction, "min_valid_fraction", maximum=1.0)
        if v <= 0:
            raise InputError(f"`min_valid_fraction` must be positive, got {v}")
        check_positive(self.min_level, "min_level", allow_zero=True, maximum=0.5)
        if not isinstance(self.fit_background, bool):
            raise InputError(f"`fit_background` must be true or false, got {self.fit_background!r}")


@dataclass(frozen=True)
class GlareFit:
    """The fitted glare spread of each channel, with the fit's quality.

    Attributes
    ----------
    fraction, width_px : ndarray, shape (C,)
        ``f_λ`` and ``w_λ``.
    fraction_std, width_std : ndarray, shape (C,)
        Their standard errors from the fit's covariance.
    rms_log_residual : ndarray, shape (C,)
        Root mean square of ``ln(predicted / observed)`` over the annuli.
    n_annuli : ndarray, shape (C,) of int
        Annuli used.
    radius_range_px : ndarray, shape (C, 2)
        Radii of the innermost and outermost annulus used.
    core_pixels : ndarray, shape (C,) of int
        Pixels in the source's core.
    background : ndarray, shape (C,)
        The fitted constant background (0 without ``fit_background``).
    """

    fraction: np.ndarray
    width_px: np.ndarray
    fraction_std: np.ndarray
    width_std: np.ndarray
    rms_log_residual: np.ndarray
    n_annuli: np.ndarray
    radius_range_px: np.ndarray
    core_pixels: np.ndarray
    background: np.ndarray

    def report(self) -> dict[str, Any]:
        return {
            "fraction": self.fraction.tolist(),
            "width_px": self.width_px.tolist(),
            "fraction_std": self.fraction_std.tolist(),
            "width_std": self.width_std.tolist(),
            "rms_log_residual": self.rms_log_residual.tolist(),
            "n_annuli": self.n_annuli.tolist(),
            "radius_range_px": self.radius_range_px.tolist(),
            "core_pixels": self.core_pixels.tolist(),
            "background": self.background.tolist(),
        }


def find_source(
    y: np.ndarray, valid: np.ndarray, saturated: np.ndarray, core_threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """The glare capture's source: the brightest compact region, not any bright or clipped pixel.

    A sensor's hot and stuck pixels are as bright as a small source in a
    capture that is dark elsewhere, and a stuck pixel reads saturated in
    every exposure. Single pixels are not a source: the image is median
    filtered over 3×3 (an isolated pixel leaves no trace, a source of a few
    pixels across keeps its level), and a saturated pixel with no saturated
    neighbour is a defect (a source too bright for the exposures clips as a
    patch). The core is the connected region at the filtered peak of values
    at least ``core_threshold`` of it and ten times the image's median (a
    bright glare tail or dark offset is not the source). Returns
    the core ``(H, W)`` and the saturated pixels that are not the source's
    (defects, to be left out).
    """
    from scipy.ndimage import median_filter

    patches, _ = label(saturated, structure=np.ones((3, 3)))
    sizes = np.bincount(patches.ravel())
    lone = saturated & (sizes[patches] == 1)
    clipped = saturated & ~lone
    level = np.where(valid, y, 0.0)
    top = float(np.max(level)) if valid.any() else 0.0
    # a pixel clipped in every exposure is at least as bright as anything measured
    level = np.where(clipped, max(top, 1.0), np.where(lone, 0.0, level))
    smooth = median_filter(level, size=3, mode="nearest")
    peak = float(np.max(smooth))
    if not peak > 0:  # nothing wider than a pixel: the brightest value is all there is
        smooth, peak = level, top
    row, col = np.unravel_index(np.argmax(smooth), y.shape)  # where the source is
    floor = 10.0 * float(np.median(level[valid])) if valid.any() else 0.0
    threshold = max(core_threshold * peak, floor) if floor < peak else core_threshold * peak
    labels, _ = label((level >= threshold) & (valid | clipped))
    near = labels[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2]
    near = near[near > 0]
    core = labels == (np.bincount(near).argmax() if near.size else labels[row, col])
    return core, lone | (clipped & ~binary_dilation(core, iterations=2))


def _channel_fit(
    y: np.ndarray,
    saturated: np.ndarray,
    best_level: np.ndarray | None,
    opts: ParametricPSFOptions,
    ch: int,
) -> tuple[float, float, float, float, float, int, float, float, int, float]:
    valid = np.isfinite(y) & (y > 0)
    if not valid.any():
        raise CalibrationError(f"glare capture, channel {ch}: no pixel has a valid exposure")
    core, defects = find_source(y, valid, saturated, opts.core_threshold)
    in_source = saturated & ~defects & binary_dilation(core)
    if in_source.any():
        raise CalibrationError(
            f"glare capture, channel {ch}: {int(in_source.sum())} pixel(s) of the source are "
            "saturated in every exposure; add shorter exposures (or dim the source)"
        )
    valid &= ~defects  # clipped pixels that are not the source's: no glare
    core = binary_dilation(core) & valid
    source = np.where(core, y, 0.0)
    yy, xx = np.nonzero(core)
    weights = source[yy, xx]
    cx = float(np.sum(xx * weights) / np.sum(weights))
    cy = float(np.sum(yy * weights) / np.sum(weights))
    h, w = y.shape
    gy, gx = np.mgrid[0:h, 0:w]
    radius = np.hypot(gx - cx, gy - cy)
    far = distance_transform_edt(~core) > opts.exclude_px
    if not far.any():
        raise CalibrationError(f"glare capture, channel {ch}: the source fills the frame")
    r_lo = max(float(radius[far].min()), 0.5)
    r_hi = float(radius[far & valid].max()) if (far & valid).any() else r_lo
    if not r_hi > r_lo * 1.5:
        raise CalibrationError(
            f"glare capture, channel {ch}: the glare tail is dark everywhere beyond the source "
            "(lengthen the longest exposure)"
        )
    edges = np.geomspace(r_lo, r_hi * (1 + 1e-9), int(opts.n_annuli) + 1)
    ring = np.digitize(radius, edges) - 1  # annulus index, -1 / n outside
    samples: list[np.ndarray] = []
    mids: list[float] = []
    observed: list[float] = []
    for j in range(int(opts.n_annuli)):
        members = np.flatnonzero((ring == j).ravel() & far.ravel())
        if members.size == 0:
            continue
        ok = valid.ravel()[members]
        if ok.mean() < opts.min_valid_fraction:
            continue
        members = members[ok]
        if best_level is not None and np.median(best_level.ravel()[members]) < opts.min_level:
            continue  # too near the dark floor to be merged without bias (module notes)
        # hot and stuck pixels are no glare: drop values beyond 8 robust sigmas
        values = y.ravel()[members]
        med = np.median(values)
        mad = 1.4826 * np.median(np.abs(values - med))
        if mad > 0:
            members = members[np.abs(values - med) <= 8.0 * mad]
        stride = max(1, int(np.ceil(members.size / opts.max_per_annulus)))
        members = members[::stride]
        samples.append(members)
        mids.append(float(np.sqrt(edges[j] * edges[j + 1])))
        observed.append(float(np.mean(y.ravel()[members])))
    if len(samples) < 4:
        raise CalibrationError(
            f"glare capture, channel {ch}: only {len(samples)} annuli of the tail have valid "
            f"exposures at {100 * opts.min_level:g} % of the range or more (need 4): lengthen "
            "the longest exposure or brighten the source"
        )
    idx = np.concatenate(samples)
    owner = np.concatenate([np.full(s.size, k) for k, s in enumerate(samples)])
    counts = np.bincount(owner)
    py, px = np.divmod(idx, w)
    d2 = (px[:, None] - xx[None, :]) ** 2 + (py[:, None] - yy[None, :]) ** 2
    d2 = d2.astype(np.float64)
    log_obs = np.log(np.asarray(observed))
    beta = float(opts.beta)

    def unit_profile(width: float) -> np.ndarray:
        """Annulus means of ``K_w ⊛ y_core`` (amplitude 1)."""
        k = (beta - 1.0) / (np.pi * width**2) * (1.0 + d2 / width**2) ** (-beta)
        per_pixel = k @ weights
        return np.bincount(owner, per_pixel) / counts

    obs = np.asarray(observed)

    def residual(theta: np.ndarray) -> np.ndarray:
        tail = np.exp(theta[0]) * unit_profile(float(np.exp(theta[1])))
        background = theta[2] * obs[-1] if opts.fit_background else 0.0
        return np.log(tail + background) - log_obs

    widths = np.geomspace(1.0, 4.0 * max(h, w), 48)
    best = None
    for width in widths:
        lp = np.log(unit_profile(float(width)))
        amp = float(np.mean(log_obs - lp))
        cost = float(np.sum((amp + lp - log_obs) ** 2))
        if best is None or cost < best[0]:
            best = (cost, amp, float(np.log(width)))
    assert best is not None
    # (ln A, ln w, b / faintest annulus); b >= 0: dark signal and ambient light only add
    lo = np.array([np.log(1e-8), np.log(1.0), 0.0])
    hi = np.array(
        [np.log(MAX_GLARE_FRACTION / (1 - MAX_GLARE_FRACTION)), np.log(40.0 * max(h, w)), 1.0]
    )
    x0 = np.clip(np.array([best[1], best[2], 1e-3]), lo + 1e-9, hi - 1e-9)
    from scipy.optimize import least_squares  # here only: 70 ms to import

    sol = least_squares(residual, x0, bounds=(lo, hi), x_scale=1.0)
    res = sol.fun
    n_par = 3 if opts.fit_background else 2
    dof = max(res.size - n_par, 1)
    s2 = float(res @ res) / dof
    try:
        jac = sol.jac[:, :n_par]
        cov = np.linalg.inv(jac.T @ jac) * s2
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), np.nan)
    amplitude = float(np.exp(sol.x[0]))
    width_px = float(np.exp(sol.x[1]))
    fraction = amplitude / (1.0 + amplitude)
    if sol.x[0] >= hi[0] - 1e-6:
        raise CalibrationError(
            f"glare capture, channel {ch}: the tail is too bright for a glare spread of the "
            f"source (the fitted fraction reached its bound, {MAX_GLARE_FRACTION:g} of the "
            "light): check that the source is the only light in the capture and that the "
            "response is right near its clip"
        )
    # d f / d ln A = A / (1 + A)²,  d w / d ln w = w
    f_std = float(np.sqrt(max(cov[0, 0], 0.0)) * amplitude / (1.0 + amplitude) ** 2)
    w_std = float(np.sqrt(max(cov[1, 1], 0.0)) * width_px)
    rms = float(np.sqrt(np.mean(res**2)))
    background = float(sol.x[2] * obs[-1]) if opts.fit_background else 0.0
    return (
        fraction,
        width_px,
        f_std,
        w_std,
        rms,
        len(samples),
        mids[0],
        mids[-1],
        int(core.sum()),
        background,
    )


def fit_glare_ParametricPSF(
    image: Any,
    all_saturated: Any = None,
    *,
    beta: float = 1.5,
    core_threshold: float = 1e-2,
    exclude_px: float = 2.0,
    n_annuli: int = 32,
    max_per_annulus: int = 200,
    min_valid_fraction: float = 0.9,
    fit_background: bool = True,
    best_level: Any = None,
    min_level: float = 0.03,
) -> GlareFit:
    """Fit a Moffat glare spread ``(f_λ, w_λ)`` per channel to a point-source capture.

    Parameters
    ----------
    image : array_like, shape (H, W, C)
        The merged glare capture divided by ``u`` (linear); NaN where no
        exposure was valid.
    all_saturated : array_like, shape (H, W, C) of bool, optional
        Pixels saturated in every exposure: a saturated source is refused.
    best_level : array_like, shape (H, W, C), optional
        Each pixel's best-exposed value as a fraction of the range
        (:func:`photoquant.glare.best_exposed_level`); with it, annuli below
        ``min_level`` are left out.
    beta, core_threshold, exclude_px, n_annuli, max_per_annulus, min_valid_fraction, \
fit_background, min_level
        See :class:`ParametricPSFOptions`.

    Returns
    -------
    GlareFit

    Raises
    ------
    CalibrationError
        A saturated source, no valid tail (too short a longest exposure), a
        source filling the frame.
    """
    opts = ParametricPSFOptions(
        beta=beta,
        core_threshold=core_threshold,
        exclude_px=exclude_px,
        n_annuli=n_annuli,
        max_per_annulus=max_per_annulus,
        min_valid_fraction=min_valid_fraction,
        fit_background=fit_background,
        min_level=min_level,
    )
    y = check_array(image, "image", ndim=3, kind="f").astype(np.float64)
    sat = (
        np.zeros(y.shape, dtype=bool)
        if all_saturated is None
        else check_array(all_saturated, "all_saturated", shape=y.shape, kind="b")
    )
    best = (
        None
        if best_level is None
        else check_array(best_level, "best_level", shape=y.shape, kind="iuf").astype(np.float64)
    )
    rows = [
        _channel_fit(y[..., c], sat[..., c], None if best is None else best[..., c], opts, c)
        for c in range(y.shape[2])
    ]
    cols = list(zip(*rows, strict=True))
    return GlareFit(
        fraction=np.array(cols[0]),
        width_px=np.array(cols[1]),
        fraction_std=np.array(cols[2]),
        width_std=np.array(cols[3]),
        rms_log_residual=np.array(cols[4]),
        n_annuli=np.array(cols[5], dtype=np.int64),
        radius_range_px=np.stack([np.array(cols[6]), np.array(cols[7])], axis=1),
        core_pixels=np.array(cols[8], dtype=np.int64),
        background=np.array(cols[9]),
    )


def characterise_glare_ParametricPSF(
    data: GlareData, options: ParametricPSFOptions | None = None
) -> StepFit[GlareModel]:
    """The ``"glare"`` step from a point-source capture (module notes; [TAHL07]_, [BJA07]_)."""
    opts = options or ParametricPSFOptions()
    fit = fit_glare_ParametricPSF(
        data.image,
        data.all_saturated,
        beta=opts.beta,
        core_threshold=opts.core_threshold,
        exclude_px=opts.exclude_px,
        n_annuli=opts.n_annuli,
        max_per_annulus=opts.max_per_annulus,
        min_valid_fraction=opts.min_valid_fraction,
        fit_background=opts.fit_background,
        best_level=data.best_level,
        min_level=opts.min_level,
    )
    model = GlareModel(
        "Parametric PSF",
        fit.fraction,
        fit.width_px,
        opts.beta,
        {"fraction_std": fit.fraction_std.tolist(), "width_std": fit.width_std.tolist()},
    )
    return StepFit(model, fit.report())


GLARE_METHODS.add(
    Method(
        "glare",
        "Parametric PSF",
        characterise_glare_ParametricPSF,
        options=ParametricPSFOptions,
        model=GlareModel,
        reference="Moffat PSF fitted to a point-source capture: Talvala et al. 2007; "
        "Bitlis, Jansson & Allebach 2007",
    ),
    replace=True,
)
