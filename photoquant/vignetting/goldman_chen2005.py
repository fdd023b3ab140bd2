"""Vignetting: the original Goldman–Chen model, radially symmetric about the image centre.

Goldman & Chen [GC05]_ model vignetting as an even polynomial of the distance
``r`` to the optical centre, which they take to be the image centre,

.. math::

    v(r) = 1 + α_1 r^2 + α_2 r^4 + α_3 r^6 ,

one set of ``α`` per colour channel, ``v = 1`` at the centre. The radius is
normalised here by the half-diagonal of the image,

.. math::

    r^2 = \\frac{(x + 0.5 - W/2)^2 + (y + 0.5 - H/2)^2}{(W^2 + H^2) / 4},

(pixel ``(x, y)`` has its centre at ``(x + 0.5, y + 0.5)``), so ``r = 1`` at the
corners of the image and circles in pixels are circles of ``v`` whatever the
aspect ratio. This is the normalisation of Hugin's and lensfun's vignetting
polynomial ([LF]_: "for vignetting it uses 1.0 = half diagonal length") and of
TUM's photometric calibration ([Ber18]_), so the ``α`` are comparable with
theirs. [GC05]_ state the polynomial, not a unit of ``r``: the half-diagonal
is our choice.

The fit is the pairwise one of the paper's extended model (§5.5 of [PQ]_):
every pair of observations of one scene point in two views gives a residual
``c_is v_js − c_js v_is``, weighted by the inverse mean of its track and
divided by the RMS of ``v``, minimised by Levenberg–Marquardt from the linear
least-squares start (the residual is linear in ``α``). [GC05]_ estimate
exposures and the response jointly; here, as in the paper, the views are
already linearised and sensor-uniformised, so only ``α`` remains.

Public objects
--------------
- :func:`radius_squared_GoldmanChen2005`, :func:`vignetting_GoldmanChen2005`
- :class:`GoldmanChen2005Vignetting`, :class:`GoldmanChen2005Options`
- :func:`characterise_vignetting_GoldmanChen2005` (method ``"Goldman-Chen 2005"``)

References
----------
.. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration and
   compensation", Proc. IEEE ICCV 2005, vol. 1, pp. 899–906.
   doi:10.1109/ICCV.2005.249
.. [PQ] The photoquantity paper, §5.5.
.. [LF] lensfun, ``libs/lensfun/mod-color.cpp`` (vignetting model ``pa``,
   Pablo d'Angelo's, as in Hugin: ``1 + k1 r² + k2 r⁴ + k3 r⁶``).
   https://lensfun.github.io/
.. [Ber18] P. Bergmann, R. Wang and D. Cremers, "Online photometric calibration
   of auto exposure video for realtime visual odometry and SLAM", IEEE RA-L
   3(2), 2018, pp. 627–634. doi:10.1109/LRA.2017.2777002
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

__all__ = [
    "GOLDMAN_CHEN_2005_PARAMETER_NAMES",
    "radius_squared_GoldmanChen2005",
    "vignetting_GoldmanChen2005",
    "GoldmanChen2005Vignetting",
    "GoldmanChen2005Options",
    "characterise_vignetting_GoldmanChen2005",
]

METHOD_NAME = "Goldman-Chen 2005"

GOLDMAN_CHEN_2005_PARAMETER_NAMES: tuple[str, ...] = ("alpha1", "alpha2", "alpha3")
"""The coefficients of ``r²``, ``r⁴`` and ``r⁶``."""


def radius_squared_GoldmanChen2005(
    x_n: Any, y_n: Any, image_shape: tuple[int, int], centre: tuple[Any, Any] = (0.5, 0.5)
) -> np.ndarray:
    """Squared radius normalised by the half-diagonal, ``r = 1`` at the image corners.

    Parameters
    ----------
    x_n, y_n : array_like
        Normalised pixel-centre coordinates ``(x + 0.5)/W``, ``(y + 0.5)/H``.
    image_shape : (H, W)
    centre : (c_x, c_y)
        Centre of symmetry in normalised coordinates (broadcasting); the image
        centre ``(0.5, 0.5)`` by default.

    Returns
    -------
    ndarray
        ``r² = (W² (x_n − c_x)² + H² (y_n − c_y)²) / ((W² + H²) / 4)``.

    Examples
    --------
    >>> float(radius_squared_GoldmanChen2005(1.0, 1.0, (3, 4)))
    1.0
    """
    h, w = _check_image_shape(image_shape)
    a_x, a_y = _axis_weights((h, w))
    x_n = np.asarray(x_n, dtype=np.float64)
    y_n = np.asarray(y_n, dtype=np.float64)
    return a_x * (x_n - centre[0]) ** 2 + a_y * (y_n - centre[1]) ** 2


def _axis_weights(image_shape: tuple[int, int]) -> tuple[float, float]:
    """``(4 W² / (W² + H²), 4 H² / (W² + H²))``: ``r²`` per squared normalised offset."""
    h, w = image_shape
    d2 = float(w * w + h * h)
    return 4.0 * w * w / d2, 4.0 * h * h / d2


def _polynomial(rho: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``1 + k1 ρ + k2 ρ² + k3 ρ³`` with ``ρ = r²``; ``k`` has shape (..., 3)."""
    k1, k2, k3 = np.moveaxis(k, -1, 0)
    return 1.0 + rho * (k1 + rho * (k2 + rho * k3))


def vignetting_GoldmanChen2005(
    x_n: Any, y_n: Any, alpha: Any, image_shape: tuple[int, int]
) -> np.ndarray:
    """Evaluate the Goldman–Chen 2005 vignetting polynomial [GC05]_.

    Parameters
    ----------
    x_n, y_n : array_like
        Normalised pixel-centre coordinates (see
        :func:`photoquant.vignetting.normalised_coordinates`).
    alpha : array_like, shape (..., 3)
        ``(α1, α2, α3)``; leading axes broadcast against the coordinates (a
        ``(C, 3)`` array with ``(H, W, 1)`` coordinates gives ``(H, W, C)``).
    image_shape : (H, W)
        Shape of the image, which sets the unit of ``r`` (the half-diagonal).

    Returns
    -------
    ndarray, float64
        ``v = 1 + α1 r² + α2 r⁴ + α3 r⁶``, dimensionless, 1 at the image centre.

    Examples
    --------
    >>> vignetting_GoldmanChen2005([0.5, 1.0], [0.5, 1.0], [-0.3, 0.0, 0.0], (4, 4))
    array([1. , 0.7])
    """
    x_n = check_array(x_n, "x_n", kind="iuf").astype(np.float64)
    y_n = check_array(y_n, "y_n", kind="iuf").astype(np.float64)
    alpha = check_array(alpha, "alpha", kind="iuf").astype(np.float64)
    if alpha.shape[-1:] != (3,):
        raise InputError(f"`alpha` must have shape (..., 3), got {alpha.shape}")
    return _polynomial(radius_squared_GoldmanChen2005(x_n, y_n, image_shape), alpha)


def _pair_model(image_shape: tuple[int, int]) -> PairModel:
    a_x, a_y = _axis_weights(image_shape)

    def rho(x_n: np.ndarray, y_n: np.ndarray) -> np.ndarray:
        return a_x * (x_n - 0.5) ** 2 + a_y * (y_n - 0.5) ** 2

    def value(p: np.ndarray, x_n: np.ndarray, y_n: np.ndarray) -> np.ndarray:
        return _polynomial(rho(x_n, y_n), p)

    def value_and_jacobian(
        p: np.ndarray, x_n: np.ndarray, y_n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        r = rho(x_n, y_n)
        return _polynomial(r, p), np.stack([r, r**2, r**3], axis=1)

    def linear_start(x_n: np.ndarray, y_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = rho(x_n, y_n)
        return np.stack([r, r**2, r**3], axis=1), np.empty(0)

    return PairModel(
        METHOD_NAME, GOLDMAN_CHEN_2005_PARAMETER_NAMES, value, value_and_jacobian, linear_start
    )


def _params_from_json(values: Any, n_params: int, what: str) -> np.ndarray:
    if not isinstance(values, list):
        raise InputError(f"{what} `params` must be a list of lists, got {values!r}")
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{what} `params` must be numbers (C rows of {n_params})") from None


@dataclass(frozen=True, eq=False)
class GoldmanChen2005Vignetting(VignettingModel):
    """The Goldman–Chen 2005 model [GC05]_: ``(α1, α2, α3)`` per channel, centred.

    Parameters
    ----------
    method : str
        The method that fitted it.
    params : ndarray, shape (C, 3)
        ``(α1, α2, α3)`` per channel, for ``r`` in half-diagonals (see
        :func:`vignetting_GoldmanChen2005`).
    """

    method: str
    params: np.ndarray

    def __post_init__(self) -> None:
        p = check_array(self.params, "vignetting params", ndim=2, kind="iuf", finite=True)
        if p.shape[1] != 3:
            raise InputError(
                "the Goldman-Chen 2005 model has 3 parameters per channel "
                f"({', '.join(GOLDMAN_CHEN_2005_PARAMETER_NAMES)}), got shape {p.shape}"
            )
        object.__setattr__(self, "params", p.astype(np.float64))

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        h, w = _check_image_shape(image_shape)
        x_n, y_n = pixel_grid((h, w))
        return vignetting_GoldmanChen2005(x_n[..., None], y_n[..., None], self.params, (h, w))

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return (
            {
                "model": METHOD_NAME,
                "parameter_names": list(GOLDMAN_CHEN_2005_PARAMETER_NAMES),
                "formula": "v = 1 + alpha1 r^2 + alpha2 r^4 + alpha3 r^6",
                "radius": "r^2 = ((x + 0.5 - W/2)^2 + (y + 0.5 - H/2)^2) / ((W^2 + H^2) / 4)",
                "params": self.params.tolist(),
            },
            {},
        )

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> GoldmanChen2005Vignetting:
        del images
        return cls(method, _params_from_json(params.get("params"), 3, "Goldman-Chen 2005"))


@dataclass(frozen=True)
class GoldmanChen2005Options(PairFitOptions):
    """Options of the ``"Goldman-Chen 2005"`` vignetting fit.

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


def characterise_vignetting_GoldmanChen2005(
    data: VignettingData, options: GoldmanChen2005Options | None = None
) -> StepFit[GoldmanChen2005Vignetting]:
    """The ``"vignetting"`` step by the Goldman–Chen 2005 model [GC05]_.

    Parameters
    ----------
    data : VignettingData
        The sensor-uniformised views and their correspondences.
    options : GoldmanChen2005Options, optional

    Returns
    -------
    StepFit
        The fitted :class:`GoldmanChen2005Vignetting` and a report (counts,
        residual RMS, map uncertainty, message).

    Raises
    ------
    CalibrationError
        Too few pairs or views, observations bunched in one spot, or a fit
        that cannot be trusted (not converged, not positive, collapsed, or
        poorly constrained); the message says which.
    """
    opts = options or GoldmanChen2005Options()
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
    model = GoldmanChen2005Vignetting(METHOD_NAME, fit.params)
    return StepFit(model, fit.report(len(data.tracks)))


VIGNETTING_METHODS.add(
    Method(
        "vignetting",
        METHOD_NAME,
        characterise_vignetting_GoldmanChen2005,
        options=GoldmanChen2005Options,
        model=GoldmanChen2005Vignetting,
        reference="Goldman & Chen 2005, doi:10.1109/ICCV.2005.249",
        needs=frozenset({"tracks"}),
    ),
    replace=True,
)
