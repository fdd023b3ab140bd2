"""Vignetting: a non-parametric flat-field map from a uniformly lit target.

A target of uniform radiance seen through the optics (a diffuser over the
lens, an integrating sphere, an evenly lit white wall filling the view) gives,
after linearisation and sensor uniformisation, ``c_p = v_p · l`` with one
``l`` for every pixel: the image *is* the vignetting up to a scale and noise.
This is classic flat-fielding [How06]_ (there with the sensor's gain in the
same frame; here ``u`` is already divided out) and the approach of TUM's
``vignetteCalib`` [Eng16]_, which however estimates the flat field from a
target with known geometry rather than from an evenly lit one.

The map is the flat-field image smoothed by a *local linear* Gaussian
regression (at each pixel, the weighted least-squares plane through the
valid pixels nearby, weights a Gaussian of std ``σ``; [Fan96]_). Unlike a plain
Gaussian blur it has no first-order bias at the image border, where the
window is one-sided, and it fills flagged (NaN) pixels from their
neighbours. Outliers (hot pixels, specks on the target) are removed robustly:
pixels whose residual from a first fit deviates from the median residual of
their 7 × 7 neighbourhood by more than ``reject`` robust standard deviations
(1.4826 × the median absolute deviation) are dropped and the fit repeated. Larger defects (dust donuts of the optics) are
kept: they are real attenuation, which a flat field is meant to divide out.
Each channel is then divided by its value at the image centre (or its
maximum), so that ``v = 1`` there like the parametric models.

No model is assumed, so any smooth fall-off is captured (cos⁴, a decentred or
elliptical lens, a different fall-off per channel); the price is a capture of
a uniform target, structure finer than ``σ`` being smoothed away (a sharp
mechanical cut-off is rounded over about ``σ``), and non-uniformity of the
illumination, which is taken for vignetting.

Public objects
--------------
- :func:`smooth_flat_field`
- :class:`FlatFieldVignetting`, :class:`FlatFieldOptions`
- :func:`characterise_vignetting_FlatField` (method ``"Flat Field"``)

References
----------
.. [How06] S. B. Howell, *Handbook of CCD Astronomy*, 2nd ed., Cambridge
   University Press, 2006, §4.3 "Flat fields". doi:10.1017/CBO9780511807909
.. [Eng16] J. Engel, V. Usenko and D. Cremers, "A photometrically calibrated
   benchmark for monocular visual odometry", arXiv:1607.02555, 2016
   (``mono_dataset_code``: ``vignetteCalib``).
.. [Fan96] J. Fan and I. Gijbels, *Local Polynomial Modelling and Its
   Applications*, Chapman & Hall, 1996. doi:10.1201/9780203748725
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter, median_filter

from photoquant._checks import check_array, check_positive
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import Method, StepFit
from photoquant.vignetting.base import VIGNETTING_METHODS, VignettingData, VignettingModel
from photoquant.vignetting.extended_goldman_chen import _check_image_shape

__all__ = [
    "smooth_flat_field",
    "FlatFieldVignetting",
    "FlatFieldOptions",
    "characterise_vignetting_FlatField",
]

METHOD_NAME = "Flat Field"
_IMAGE_KEY = "flat_field"
_MAD_TO_STD = 1.4826  # std of a normal distribution per median absolute deviation
# Least fraction of a full window's Gaussian weight that must be valid at a pixel
# (a corner pixel of a complete image has 1/4): less is a hole to be refused.
_MIN_WEIGHT = 0.05
# Relative deviations below this are never outliers: near the border the local
# median of the residuals leaves up to 6e-4 of the smoothing bias (measured: a
# 48 × 64 image, v = 1 − 0.3 r² + …, sigma 1.6 px; 3e-4 for cos⁴ down to 0.5).
_REL_FLOOR = 2e-3
_MEDIAN_SIZE = 7


@dataclass(frozen=True)
class _Smoothed:
    value: np.ndarray  # (H, W): the local-linear estimate
    noise_gain: np.ndarray  # (H, W): sqrt(Σ w_i²) of the equivalent kernel
    weight: np.ndarray  # (H, W): valid Gaussian weight, 1 inside a complete image


def _local_linear(data: np.ndarray, valid: np.ndarray, sigma: float) -> _Smoothed:
    """Gaussian-weighted local linear regression of ``data`` over ``valid`` pixels.

    Per pixel, the weighted least-squares plane through its neighbours: the
    3 × 3 normal equations ``A c = b`` in the centred basis ``φ = (1, x_i − x,
    y_i − y)`` are solved by their adjugate (``A`` is symmetric), pixel by
    pixel in closed form.
    """
    h, w = data.shape
    m = valid.astype(np.float64)
    d = np.where(valid, data, 0.0)
    # coordinates in units of sigma, centred on the image, for conditioning
    x = ((np.arange(w, dtype=np.float64) - (w - 1) / 2) / sigma)[None, :]
    y = ((np.arange(h, dtype=np.float64) - (h - 1) / 2) / sigma)[:, None]

    def g(a: np.ndarray) -> np.ndarray:
        return gaussian_filter(a, sigma, mode="constant", cval=0.0)

    def g2(a: np.ndarray) -> np.ndarray:
        # Σ g_i² a_i: g² is a Gaussian of std σ/√2 scaled by 1 / (4π σ²)
        return gaussian_filter(a, sigma / np.sqrt(2.0), mode="constant", cval=0.0) / (
            4.0 * np.pi * sigma * sigma
        )

    def centred(filt: Any) -> tuple[np.ndarray, ...]:
        """The moments Σ k_i m_i φ φᵀ with φ = (1, x_i − x, y_i − y): s0, cx, cy, cxx, cxy, cyy."""
        s0, sx, sy = filt(m), filt(m * x), filt(m * y)
        sxx, sxy, syy = filt(m * x * x), filt(m * x * y), filt(m * y * y)
        cx = sx - x * s0
        cy = sy - y * s0
        cxx = sxx - 2 * x * sx + x * x * s0
        cyy = syy - 2 * y * sy + y * y * s0
        cxy = sxy - x * sy - y * sx + x * y * s0
        return s0, cx, cy, cxx, cxy, cyy

    a00, a01, a02, a11, a12, a22 = centred(g)
    weight = a00
    # first row of the adjugate of the symmetric A, and its determinant
    c0 = a11 * a22 - a12 * a12
    c1 = a02 * a12 - a01 * a22
    c2 = a01 * a12 - a02 * a11
    det = a00 * c0 + a01 * c1 + a02 * c2
    # no plane where the window is (nearly) empty or its pixels lie on a line (A singular);
    # there A = I, as for a pixel without data
    ok = (weight >= _MIN_WEIGHT) & (det > 0)
    c0, c1, c2 = np.where(ok, c0, 1.0), np.where(ok, c1, 0.0), np.where(ok, c2, 0.0)
    det = np.where(ok, det, 1.0)
    t0, tx, ty = g(d), g(d * x), g(d * y)
    coef0 = (c0 * t0 + c1 * (tx - x * t0) + c2 * (ty - y * t0)) / det
    # equivalent kernel w = e1ᵀ A⁻¹ φ g: Σ w² = e1ᵀ A⁻¹ B A⁻¹ e1, B = Σ g² m φ φᵀ,
    # with A⁻¹ e1 = (c0, c1, c2) / det
    b00, b01, b02, b11, b12, b22 = centred(g2)
    gain2 = (
        b00 * c0 * c0
        + b11 * c1 * c1
        + b22 * c2 * c2
        + 2.0 * (b01 * c0 * c1 + b02 * c0 * c2 + b12 * c1 * c2)
    ) / (det * det)
    value = np.where(ok, coef0, np.nan)
    return _Smoothed(value, np.sqrt(np.maximum(gain2, 0.0)), weight)


def smooth_flat_field(
    flat: Any,
    sigma_px: float,
    *,
    reject: float = 4.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smooth a flat-field image robustly by local linear Gaussian regression.

    Parameters
    ----------
    flat : array_like, shape (H, W, C)
        Linear values of a uniformly lit target; NaN (or non-positive) values
        are flagged pixels.
    sigma_px : float
        Standard deviation of the Gaussian weights, in pixels.
    reject : float
        Outlier threshold (0: no rejection). The relative residuals of a first
        fit minus their median over each 7 × 7 neighbourhood are free of the
        smooth parts (the smoothing bias, the pull of an outlier on its
        neighbours); a pixel is dropped when that exceeds ``reject`` robust
        standard deviations of it (and 0.2 %, above what the border leaves of
        the smoothing bias), and the fit is repeated without it. The median
        ignores defects of up to 24 pixels (fewer than half the window).

    Returns
    -------
    smooth : ndarray, shape (H, W, C)
        The smoothed image (same units as ``flat``); NaN where fewer than 5 %
        of a full window's weight is valid.
    relative_noise : ndarray, shape (C,)
        Robust standard deviation of the relative residuals of the kept pixels.
    map_noise : ndarray, shape (H, W, C)
        First-order relative standard uncertainty of ``smooth``:
        ``relative_noise · sqrt(Σ w_i²)`` with ``w`` the equivalent kernel
        (``≈ 1 / (2 √π σ)`` inside the image, larger at the border).

    Examples
    --------
    >>> flat = np.ones((20, 30, 1)); flat[5, 7] = np.nan; flat[9, 9] = 5.0
    >>> smooth, noise, _ = smooth_flat_field(flat, 3.0)
    >>> bool(np.allclose(smooth, 1.0)), noise.tolist()
    (True, [0.0])
    """
    flat = check_array(flat, "flat_field", ndim=3, kind="iuf").astype(np.float64)
    sigma_px = check_positive(sigma_px, "sigma_px")
    reject = check_positive(reject, "reject", allow_zero=True)
    smooth = np.empty_like(flat)
    map_noise = np.empty_like(flat)
    noise = np.empty(flat.shape[2])
    for ch in range(flat.shape[2]):
        data = flat[..., ch]
        valid = np.isfinite(data) & (data > 0)
        fit = _local_linear(data, valid, sigma_px)
        if reject > 0:
            # residuals of the first fit hold the smoothing bias and the pull of the
            # outliers on their neighbours, both smooth on the scale of sigma: the
            # local median of the residuals removes them, the outliers stand out
            first = np.where(valid, data / fit.value - 1.0, 0.0)
            first = np.where(np.isfinite(first), first, 0.0)
            rel = first - median_filter(first, size=_MEDIAN_SIZE, mode="nearest")
            spread = _MAD_TO_STD * np.median(np.abs(rel[valid] - np.median(rel[valid])))
            outlier = valid & (np.abs(rel) > max(reject * spread, _REL_FLOOR))
            if np.any(outlier):
                valid = valid & ~outlier
                fit = _local_linear(data, valid, sigma_px)
        rel = data / fit.value - 1.0
        keep = valid & np.isfinite(rel)
        noise[ch] = _MAD_TO_STD * np.median(np.abs(rel[keep] - np.median(rel[keep])))
        smooth[..., ch] = fit.value
        map_noise[..., ch] = noise[ch] * fit.noise_gain
    return smooth, noise, map_noise


@dataclass(frozen=True, eq=False)
class FlatFieldVignetting(VignettingModel):
    """A vignetting map stored as an image (from a flat field), 1 at its reference.

    Parameters
    ----------
    method : str
        The method that made it.
    image : ndarray, shape (H, W, C)
        ``v`` on the pixel grid; finite and positive. Saved in the camera
        folder as ``flat_field.exr`` (float32).
    normalised_at : {"centre", "max"}
        Where ``v = 1``: at the image centre or at the maximum, per channel.
    """

    method: str
    image: np.ndarray
    normalised_at: str = "centre"

    def __post_init__(self) -> None:
        image = check_array(self.image, "flat-field vignetting image", ndim=3, kind="f")
        if not np.all(np.isfinite(image)) or np.any(image <= 0):
            raise InputError("the flat-field vignetting image must be finite and positive")
        if self.normalised_at not in ("centre", "max"):
            raise InputError(
                f"`normalised_at` must be 'centre' or 'max', got {self.normalised_at!r}"
            )
        object.__setattr__(self, "image", image.astype(np.float64))

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        h, w = _check_image_shape(image_shape)
        if self.image.shape[:2] != (h, w):
            raise InputError(
                f"the flat-field vignetting map is {self.image.shape[1]}x{self.image.shape[0]}, "
                f"the image is {w}x{h}: a flat field applies only to its own image size"
            )
        return self.image.copy()

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return (
            {
                "model": METHOD_NAME,
                "normalised_at": self.normalised_at,
                "image_shape": list(self.image.shape[:2]),
            },
            {_IMAGE_KEY: self.image},
        )

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> FlatFieldVignetting:
        if _IMAGE_KEY not in images:
            raise InputError(f"the flat-field vignetting needs its image {_IMAGE_KEY!r}")
        image = np.asarray(images[_IMAGE_KEY], dtype=np.float64)
        shape = params.get("image_shape")
        if shape is not None and list(image.shape[:2]) != list(shape):
            raise InputError(
                f"the flat-field vignetting image has shape {list(image.shape[:2])}, "
                f"its parameters say {shape}"
            )
        return cls(method, image, str(params.get("normalised_at", "centre")))


@dataclass(frozen=True)
class FlatFieldOptions:
    """Options of the ``"Flat Field"`` vignetting method.

    Attributes
    ----------
    sigma : float
        Standard deviation of the smoothing Gaussian as a fraction of the image
        diagonal (default 0.02: 4 px on 160 × 120, 25.6 px on 1024 × 768). The
        map's noise falls as ``1/σ``; its bias is ``≈ σ²/2 ∇²v`` (local linear).
    normalise_at : {"centre", "max"}
        Divide each channel by its value at the image centre (default) or by
        its maximum.
    reject : float
        Outlier threshold in robust standard deviations of the residuals minus
        their local median (0: none; see :func:`smooth_flat_field`).
    min_valid_fraction : float
        Least fraction of valid (finite, positive) pixels per channel.
    max_uncertainty : float
        Largest accepted mean relative first-order uncertainty of the map.
    """

    sigma: float = 0.02
    normalise_at: str = "centre"
    reject: float = 4.0
    min_valid_fraction: float = 0.5
    max_uncertainty: float = 0.02

    def __post_init__(self) -> None:
        check_positive(self.sigma, "sigma")
        if self.sigma > 1:
            raise InputError(f"`sigma` is a fraction of the diagonal in (0, 1], got {self.sigma!r}")
        if self.normalise_at not in ("centre", "max"):
            raise InputError(f"`normalise_at` must be 'centre' or 'max', got {self.normalise_at!r}")
        check_positive(self.reject, "reject", allow_zero=True)
        check_positive(self.min_valid_fraction, "min_valid_fraction")
        if self.min_valid_fraction > 1:
            raise InputError(
                f"`min_valid_fraction` must be in (0, 1], got {self.min_valid_fraction!r}"
            )
        check_positive(self.max_uncertainty, "max_uncertainty")


def _centre_value(smooth: np.ndarray) -> np.ndarray:
    """Bilinear value at the image centre, pixel index ((W − 1)/2, (H − 1)/2), per channel."""
    h, w = smooth.shape[:2]
    ys = [(h - 1) // 2, h // 2]
    xs = [(w - 1) // 2, w // 2]
    return np.mean(smooth[np.ix_(ys, xs)], axis=(0, 1))


def characterise_vignetting_FlatField(
    data: VignettingData, options: FlatFieldOptions | None = None
) -> StepFit[FlatFieldVignetting]:
    """The ``"vignetting"`` step from a flat field: smoothed, normalised image.

    Parameters
    ----------
    data : VignettingData
        ``data.flat_field`` (``exp(merge) / u`` of a uniformly lit target seen
        through the optics, ``(H, W, C)``) is the input; the views and tracks
        are not used.
    options : FlatFieldOptions, optional

    Returns
    -------
    StepFit
        The :class:`FlatFieldVignetting` and a report (valid fraction, relative
        noise of the flat field, map uncertainty, message).

    Raises
    ------
    CalibrationError
        No flat field, too few valid pixels, a flagged region wider than the
        smoothing window, a non-positive map or a map uncertainty above
        ``max_uncertainty``.
    InputError
        A flat field whose shape or channels differ from the views'.
    """
    opts = options or FlatFieldOptions()
    if data.flat_field is None:
        raise CalibrationError(
            "the 'Flat Field' vignetting method needs a flat field (a capture of a uniformly "
            "lit target through the optics, e.g. a diffuser or an integrating sphere); none "
            "was given"
        )
    h, w = _check_image_shape(data.image_shape)
    flat = check_array(data.flat_field, "flat_field", ndim=3, kind="iuf").astype(np.float64)
    n_ch = data.uniform_views[0].shape[-1] if data.uniform_views else flat.shape[2]
    if flat.shape != (h, w, n_ch):
        raise InputError(
            f"`flat_field` must have shape {(h, w, n_ch)} like the views, got {flat.shape}"
        )
    valid = np.isfinite(flat) & (flat > 0)
    fraction = valid.mean(axis=(0, 1))
    if np.any(fraction < opts.min_valid_fraction):
        ch = int(np.argmin(fraction))
        raise CalibrationError(
            f"the flat field has only {fraction[ch]:.1%} valid pixels in channel {ch} "
            f"(at least {opts.min_valid_fraction:.0%} needed): it is mostly saturated, dark "
            "or flagged"
        )
    sigma_px = opts.sigma * float(np.hypot(h, w))
    smooth, noise, map_noise = smooth_flat_field(flat, sigma_px, reject=opts.reject)
    if not np.all(np.isfinite(smooth)):
        raise CalibrationError(
            "the flat field has a flagged region wider than the smoothing window "
            f"(sigma {sigma_px:.1f} px): the map cannot be filled there; increase `sigma` "
            "or recapture the flat field"
        )
    if np.any(smooth <= 0):
        raise CalibrationError("the smoothed flat field is not positive over the image")
    ref = _centre_value(smooth) if opts.normalise_at == "centre" else smooth.max(axis=(0, 1))
    image = smooth / ref
    uncertainty = map_noise.mean(axis=(0, 1))
    message = (
        f"flat field smoothed with sigma {sigma_px:.1f} px, normalised at the "
        f"{opts.normalise_at}; valid pixels "
        + ", ".join(f"{f:.1%}" for f in fraction)
        + "; relative noise of the flat field "
        + ", ".join(f"{n:.2%}" for n in noise)
        + "; relative map uncertainty (1 sigma, image mean) "
        + ", ".join(f"{u:.3%}" for u in uncertainty)
    )
    if np.any(uncertainty > opts.max_uncertainty):
        raise CalibrationError(
            f"the flat-field map cannot be trusted: its uncertainty exceeds "
            f"{opts.max_uncertainty:.1%} ({message}); average more frames or increase `sigma`"
        )
    report = {
        "sigma_px": sigma_px,
        "valid_fraction": fraction,
        "relative_noise": noise,
        "map_uncertainty": uncertainty,
        "message": message,
    }
    return StepFit(FlatFieldVignetting(METHOD_NAME, image, opts.normalise_at), report)


VIGNETTING_METHODS.add(
    Method(
        "vignetting",
        METHOD_NAME,
        characterise_vignetting_FlatField,
        options=FlatFieldOptions,
        model=FlatFieldVignetting,
        reference="flat-fielding (Howell 2006, §4.3); TUM vignetteCalib (Engel et al. 2016)",
        needs=frozenset({"flat_field"}),
    ),
    replace=True,
)
