"""Vignetting: a radial polynomial about a fitted centre (the model of Hugin and lensfun).

Per channel,

.. math::

    v = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6, \\qquad
    r^2 = \\frac{W^2 (x_n - c_x)^2 + H^2 (y_n - c_y)^2}{(W^2 + H^2) / 4},

with normalised pixel-centre coordinates ``x_n = (x + 0.5)/W``,
``y_n = (y + 0.5)/H`` and a centre ``(c_x, c_y)`` that is fitted (``(0.5, 0.5)``
is the image centre). ``r`` is a distance in pixels divided by the half-diagonal:
circular in pixels, ``r = 1`` at the corners of a centred image. This is the
``pa`` vignetting model of lensfun [LF]_ and Hugin's photometric model [Hug]_
(``Va = 1``, ``Vb, Vc, Vd`` the coefficients of ``r², r⁴, r⁶``, ``Vx, Vy`` a
shift of the centre in pixels, ``r`` normalised by the half-diagonal): here
``k = (Vb, Vc, Vd)`` and the centre shift in pixels is
``((c_x − 0.5) W, (c_y − 0.5) H)`` (check Hugin's sign convention before
exchanging values). With ``c = (0.5, 0.5)`` it is the Goldman–Chen 2005 model
(:mod:`photoquant.vignetting.goldman_chen2005`); it is itself the extended
Goldman–Chen model of the paper with its aspect fixed to ``m4 = (W/H)²``.

The fit is the pairwise one of the paper's extended model (§5.5 of [PQ]_):
residuals ``c_is v_js − c_js v_is`` over every pair of views of every point,
weighted by the inverse mean of the track and divided by the RMS of ``v``,
minimised by Levenberg–Marquardt [Mor78]_ from the linear least-squares start
at the image centre.

Public objects
--------------
- :func:`vignetting_RadialPolynomial`
- :class:`RadialPolynomialVignetting`, :class:`RadialPolynomialOptions`
- :func:`characterise_vignetting_RadialPolynomial` (method ``"Radial Polynomial"``)

References
----------
.. [LF] lensfun, "Lens models": vignetting model ``pa`` (Pablo d'Angelo's,
   from Hugin), ``1 + k1 r² + k2 r⁴ + k3 r⁶``; ``libs/lensfun/mod-color.cpp``
   ("for vignetting it uses 1.0 = half diagonal length").
   https://lensfun.github.io/manual/latest/
.. [Hug] Hugin, photometric optimisation (``vig_optimize``), image variables
   ``Va, Vb, Vc, Vd`` (radial vignetting polynomial) and ``Vx, Vy`` (centre
   shift). https://hugin.sourceforge.io/
.. [PQ] The photoquantity paper, §5.5.
.. [Mor78] J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and
   theory", Lecture Notes in Mathematics 630, 1978. doi:10.1007/BFb0067700
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_array
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import Method, StepFit
from photoquant.vignetting._pairs import (
    PairFitOptions,
    PairModel,
    fit_pair_model,
    pair_observations,
    pixel_grid,
    sample_tracks,
)
from photoquant.vignetting.base import (
    VIGNETTING_METHODS,
    VignettingData,
    VignettingModel,
    wants_view_gains,
)
from photoquant.vignetting.extended_goldman_chen import _check_image_shape
from photoquant.vignetting.goldman_chen2005 import (
    _axis_weights,
    _params_from_json,
    _polynomial,
)

__all__ = [
    "RADIAL_POLYNOMIAL_PARAMETER_NAMES",
    "vignetting_RadialPolynomial",
    "RadialPolynomialVignetting",
    "RadialPolynomialOptions",
    "characterise_vignetting_RadialPolynomial",
]

METHOD_NAME = "Radial Polynomial"

RADIAL_POLYNOMIAL_PARAMETER_NAMES: tuple[str, ...] = ("k1", "k2", "k3", "cx", "cy")
"""Coefficients of ``r², r⁴, r⁶`` and the centre in normalised coordinates."""


def vignetting_RadialPolynomial(
    x_n: Any, y_n: Any, params: Any, image_shape: tuple[int, int]
) -> np.ndarray:
    """Evaluate the radial polynomial vignetting model with a centre [LF]_.

    Parameters
    ----------
    x_n, y_n : array_like
        Normalised pixel-centre coordinates.
    params : array_like, shape (..., 5)
        ``(k1, k2, k3, cx, cy)``; leading axes broadcast against the
        coordinates (``(C, 5)`` with ``(H, W, 1)`` coordinates gives ``(H, W, C)``).
    image_shape : (H, W)
        Sets the unit of ``r`` (the half-diagonal).

    Returns
    -------
    ndarray, float64
        ``v = 1 + k1 r² + k2 r⁴ + k3 r⁶``, 1 at the centre ``(cx, cy)``.

    Examples
    --------
    >>> vignetting_RadialPolynomial([0.25, 1.0], [0.5, 1.0], [-0.3, 0, 0, 0.25, 0.5], (4, 4))
    array([1.    , 0.5125])
    """
    h, w = _check_image_shape(image_shape)
    x_n = check_array(x_n, "x_n", kind="iuf").astype(np.float64)
    y_n = check_array(y_n, "y_n", kind="iuf").astype(np.float64)
    p = check_array(params, "params", kind="iuf").astype(np.float64)
    if p.shape[-1:] != (5,):
        raise InputError(f"`params` must have shape (..., 5), got {p.shape}")
    a_x, a_y = _axis_weights((h, w))
    rho = a_x * (x_n - p[..., 3]) ** 2 + a_y * (y_n - p[..., 4]) ** 2
    return _polynomial(rho, p[..., :3])


def _pair_model(image_shape: tuple[int, int]) -> PairModel:
    a_x, a_y = _axis_weights(image_shape)

    def value(p: np.ndarray, x_n: np.ndarray, y_n: np.ndarray) -> np.ndarray:
        rho = a_x * (x_n - p[3]) ** 2 + a_y * (y_n - p[4]) ** 2
        return _polynomial(rho, p[:3])

    def value_and_jacobian(
        p: np.ndarray, x_n: np.ndarray, y_n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        k1, k2, k3, cx, cy = p
        dx, dy = x_n - cx, y_n - cy
        rho = a_x * dx**2 + a_y * dy**2
        dv_drho = k1 + rho * (2.0 * k2 + 3.0 * rho * k3)
        jac = np.stack(
            [rho, rho**2, rho**3, dv_drho * (-2.0 * a_x * dx), dv_drho * (-2.0 * a_y * dy)],
            axis=1,
        )
        return _polynomial(rho, p[:3]), jac

    def linear_start(x_n: np.ndarray, y_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho = a_x * (x_n - 0.5) ** 2 + a_y * (y_n - 0.5) ** 2
        return np.stack([rho, rho**2, rho**3], axis=1), np.array([0.5, 0.5])

    return PairModel(
        METHOD_NAME, RADIAL_POLYNOMIAL_PARAMETER_NAMES, value, value_and_jacobian, linear_start
    )


@dataclass(frozen=True, eq=False)
class RadialPolynomialVignetting(VignettingModel):
    """The radial polynomial about a fitted centre: ``(k1, k2, k3, cx, cy)`` per channel.

    Parameters
    ----------
    method : str
        The method that fitted it.
    params : ndarray, shape (C, 5)
        ``(k1, k2, k3, cx, cy)`` per channel (see :func:`vignetting_RadialPolynomial`).
    """

    method: str
    params: np.ndarray

    def __post_init__(self) -> None:
        p = check_array(self.params, "vignetting params", ndim=2, kind="iuf", finite=True)
        if p.shape[1] != 5:
            raise InputError(
                "the radial polynomial model has 5 parameters per channel "
                f"({', '.join(RADIAL_POLYNOMIAL_PARAMETER_NAMES)}), got shape {p.shape}"
            )
        object.__setattr__(self, "params", p.astype(np.float64))

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        h, w = _check_image_shape(image_shape)
        x_n, y_n = pixel_grid((h, w))
        return vignetting_RadialPolynomial(x_n[..., None], y_n[..., None], self.params, (h, w))

    def centre_shift_px(self, image_shape: tuple[int, int]) -> np.ndarray:
        """The centre minus the image centre in pixels, ``(C, 2)`` (Hugin's ``Vx, Vy`` kind)."""
        h, w = _check_image_shape(image_shape)
        return (self.params[:, 3:5] - 0.5) * np.array([w, h], dtype=np.float64)

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return (
            {
                "model": METHOD_NAME,
                "parameter_names": list(RADIAL_POLYNOMIAL_PARAMETER_NAMES),
                "formula": "v = 1 + k1 r^2 + k2 r^4 + k3 r^6",
                "radius": (
                    "r^2 = (W^2 (x_n - cx)^2 + H^2 (y_n - cy)^2) / ((W^2 + H^2) / 4), "
                    "x_n = (x + 0.5) / W, y_n = (y + 0.5) / H"
                ),
                "params": self.params.tolist(),
            },
            {},
        )

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> RadialPolynomialVignetting:
        del images
        return cls(method, _params_from_json(params.get("params"), 5, "radial polynomial"))


@dataclass(frozen=True)
class RadialPolynomialOptions(PairFitOptions):
    """Options of the ``"Radial Polynomial"`` vignetting fit.

    Attributes
    ----------
    normalise : {"track", "none"}
        Pair residuals divided by their track's mean (default) or in value units.
    scale_invariant : bool
        Divide the residuals by the RMS of ``v`` (default).
    sample_radius : int
        Half-size of the window averaged at each correspondence (0 to 64).
    min_pairs : int
        Fewest usable pairs of observations (default 30).
    min_spread : float
        Fewest fraction of the width and of the height the observations span.
    max_uncertainty : float
        Largest accepted mean relative first-order uncertainty of the map.
    max_nfev : int
        Most evaluations of the residuals per channel.
    """


def characterise_vignetting_RadialPolynomial(
    data: VignettingData, options: RadialPolynomialOptions | None = None
) -> StepFit[RadialPolynomialVignetting]:
    """The ``"vignetting"`` step by the radial polynomial with a fitted centre [LF]_.

    Parameters
    ----------
    data : VignettingData
        The sensor-uniformised views and their correspondences.
    options : RadialPolynomialOptions, optional

    Returns
    -------
    StepFit
        The fitted :class:`RadialPolynomialVignetting` and a report.

    Raises
    ------
    CalibrationError
        Too few pairs or views, observations bunched in one spot, or a fit
        that cannot be trusted; the message says which.
    """
    opts = options or RadialPolynomialOptions()
    values, xy, view, track = sample_tracks(data, opts.sample_radius)
    shape = _check_image_shape(data.image_shape)
    obs = pair_observations(
        values, xy, view, track, shape, min_pairs=opts.min_pairs, min_spread=opts.min_spread
    )
    fit = fit_pair_model(
        _pair_model(shape),
        obs,
        shape,
        normalise=opts.normalise,
        scale_invariant=opts.scale_invariant,
        max_uncertainty=opts.max_uncertainty,
        max_nfev=opts.max_nfev,
        view_gains=wants_view_gains(opts.view_gains, data),
        view_gain_sigma=opts.view_gain_sigma,
    )
    if not np.all(fit.converged):
        raise CalibrationError(f"the vignetting fit cannot be trusted: {fit.message}")
    model = RadialPolynomialVignetting(METHOD_NAME, fit.params)
    return StepFit(model, fit.report(len(data.tracks)))


VIGNETTING_METHODS.add(
    Method(
        "vignetting",
        METHOD_NAME,
        characterise_vignetting_RadialPolynomial,
        options=RadialPolynomialOptions,
        model=RadialPolynomialVignetting,
        reference="lensfun 'pa' / Hugin Vb, Vc, Vd, Vx, Vy; https://lensfun.github.io/",
        needs=frozenset({"tracks"}),
    ),
    replace=True,
)
