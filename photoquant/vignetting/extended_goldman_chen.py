"""Vignetting: the extended Goldman–Chen model and its calibration from rotated views.

Vignetting is the fall-off of the light that reaches a sensor cell with the
cell's position, caused by the optics (§5.5 of [PQ]). Per channel ``λ`` it is
modelled as a cubic polynomial in an elliptical radius,

.. math::

    v_λ(x_n, y_n) = 1 + m_1 R + m_2 R^2 + m_3 R^3, \\qquad
    R = m_4 (x_n - m_5)^2 + (y_n - m_6)^2,

an extension of the polynomial model of Goldman & Chen [GC05]_ with an
axis-aligned elliptical symmetry of centre ``(m5, m6)`` and aspect ``m4``.
Coordinates are normalised to pixel centres, ``x_n = (x + 0.5) / W`` and
``y_n = (y + 0.5) / H`` (x right, y down; pixel ``(x, y)`` covers
``[x, x + 1) × [y, y + 1)``), so ``m5 = m6 = 0.5`` is the image centre and
``v = 1`` there.

Calibration uses a static scene seen from ``V`` view directions of a camera
rotated about its centre of projection. A scene point ``s`` seen in views
``i`` and ``j`` gives linearised, colour-balanced, sensor-uniformised values
``c_is = v_is l_s`` and ``c_js = v_js l_s``, hence ``c_is v_js − c_js v_is = 0``;
the parameters minimise the sum of squares of these residuals over all pairs of
views of all points, by Levenberg–Marquardt [Mor78]_.

Public objects
--------------
- :data:`VIGNETTING_PARAMETER_NAMES`, :data:`IDENTITY_VIGNETTING`
- :func:`normalised_coordinates`
- :func:`vignetting_ExtendedGoldmanChen`, :func:`vignetting_map`
- :class:`VignettingFit`, :func:`fit_vignetting_ExtendedGoldmanChen`
- :data:`VIGNETTING_METHODS`, :func:`fit_vignetting`

References
----------
.. [PQ] The photoquantity paper, §5.5
   "Vignetting" (model and calibration) and §6.3 (fitted values).
.. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration and
   compensation", Proc. IEEE ICCV 2005, vol. 1, pp. 899–906.
   doi:10.1109/ICCV.2005.249
.. [Mor78] J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and
   theory", in *Numerical Analysis*, Lecture Notes in Mathematics 630,
   Springer, 1978, pp. 105–116. doi:10.1007/BFb0067700
.. [Liang1986] K.-Y. Liang and S. L. Zeger, "Longitudinal data analysis using
   generalized linear models", Biometrika 73(1), 1986, pp. 13–22.
   doi:10.1093/biomet/73.1.13
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from photoquant._checks import (
    UNCORRECTED_BIAS_MODES,
    check_array,
    check_choice,
    check_int,
    check_positive,
)
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import Method, StepFit
from photoquant.vignetting.base import (
    MAX_FALLOFF,
    VIGNETTING_METHODS,
    VignettingData,
    VignettingModel,
    check_view_gains_option,
    wants_view_gains,
)
from photoquant.vignetting.trust import residual_warnings

__all__ = [
    "VIGNETTING_PARAMETER_NAMES",
    "IDENTITY_VIGNETTING",
    "normalised_coordinates",
    "vignetting_ExtendedGoldmanChen",
    "vignetting_map",
    "VignettingFit",
    "fit_vignetting_ExtendedGoldmanChen",
    "ExtendedGoldmanChenVignetting",
    "ExtendedGoldmanChenOptions",
    "characterise_vignetting_ExtendedGoldmanChen",
    "fit_vignetting",
]

VIGNETTING_PARAMETER_NAMES: tuple[str, ...] = ("m1", "m2", "m3", "m4", "m5", "m6")
"""Names of the six parameters of the extended Goldman–Chen model, in order."""

IDENTITY_VIGNETTING: np.ndarray = np.array([0.0, 0.0, 0.0, 1.0, 0.5, 0.5])
"""Parameters of ``v ≡ 1`` (no vignetting) with the centre at the image centre."""
IDENTITY_VIGNETTING.setflags(write=False)

_N_PARAMS = len(VIGNETTING_PARAMETER_NAMES)


# ---------------------------------------------------------------------------
# Model
# ---------------------------------------------------------------------------


def _check_image_shape(image_shape: Any, name: str = "image_shape") -> tuple[int, int]:
    """Return ``(H, W)`` as two positive ints, or raise an InputError naming ``name``."""
    try:
        items = tuple(image_shape)
    except TypeError:
        raise InputError(f"`{name}` must be a pair (H, W), got {image_shape!r}") from None
    if len(items) < 2:
        raise InputError(f"`{name}` must be a pair (H, W), got {image_shape!r}")
    out = []
    for item in items[:2]:
        if isinstance(item, bool) or not isinstance(item, int | np.integer) or int(item) < 1:
            raise InputError(
                f"`{name}` must hold two positive integers (H, W), got {image_shape!r}"
            )
        out.append(int(item))
    return out[0], out[1]


def normalised_coordinates(
    x: Any, y: Any, image_shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Normalise pixel coordinates to pixel centres in ``[0, 1]``.

    Parameters
    ----------
    x, y : array_like
        Pixel coordinates, x right and y down; integer values are pixel
        indices (pixel ``(x, y)`` covers ``[x, x + 1) × [y, y + 1)``), float
        values are sub-pixel positions on the same scale.
    image_shape : tuple of int
        ``(H, W)``; extra trailing entries (channels) are ignored.

    Returns
    -------
    x_n, y_n : ndarray, float64
        ``x_n = (x + 0.5) / W`` and ``y_n = (y + 0.5) / H``: the centre of the
        top-left pixel is ``(0.5/W, 0.5/H)`` and the image centre is
        ``(0.5, 0.5)``.

    Examples
    --------
    >>> normalised_coordinates([0, 3], [0, 1], (2, 4))
    (array([0.125, 0.875]), array([0.25, 0.75]))
    """
    h, w = _check_image_shape(image_shape)
    x = check_array(x, "x", kind="iuf").astype(np.float64)
    y = check_array(y, "y", kind="iuf").astype(np.float64)
    return (x + 0.5) / w, (y + 0.5) / h


def vignetting_ExtendedGoldmanChen(x_n: Any, y_n: Any, params: Any) -> np.ndarray:
    """Evaluate the extended Goldman–Chen vignetting model of [PQ]_ §5.5.

    Parameters
    ----------
    x_n, y_n : array_like
        Normalised pixel-centre coordinates (see :func:`normalised_coordinates`).
    params : array_like, shape (..., 6)
        ``(m1, m2, m3, m4, m5, m6)``; a ``(6,)`` vector applies to every point,
        leading axes broadcast against ``x_n`` and ``y_n`` (e.g. ``(C, 6)``
        parameters with ``(H, W, 1)`` coordinates give ``(H, W, C)``).

    Returns
    -------
    ndarray, float64
        ``v = 1 + m1 R + m2 R² + m3 R³`` with ``R = m4 (x_n − m5)² + (y_n − m6)²``.
        Dimensionless: the fraction of the light at the centre of symmetry that
        reaches the point.

    References
    ----------
    .. [PQ] The photoquantity paper, §5.5 "Vignetting".
    .. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration
       and compensation", ICCV 2005. doi:10.1109/ICCV.2005.249

    Examples
    --------
    >>> p = [-0.4, 0.0, 0.0, 1.0, 0.5, 0.5]
    >>> vignetting_ExtendedGoldmanChen([0.5, 1.0], [0.5, 0.5], p)
    array([1. , 0.9])
    """
    x_n = check_array(x_n, "x_n", kind="iuf").astype(np.float64)
    y_n = check_array(y_n, "y_n", kind="iuf").astype(np.float64)
    params = check_array(params, "params", kind="iuf").astype(np.float64)
    if params.shape[-1] != _N_PARAMS:
        raise InputError(f"`params` must have shape (..., 6), got {params.shape}")
    return _evaluate(x_n, y_n, params)


def _evaluate(x_n: np.ndarray, y_n: np.ndarray, params: np.ndarray) -> np.ndarray:
    """The model without input checks; ``params`` has shape ``(..., 6)``."""
    m1, m2, m3, m4, m5, m6 = np.moveaxis(params, -1, 0)
    r = m4 * (x_n - m5) ** 2 + (y_n - m6) ** 2
    # 1 + r (m1 + r (m2 + r m3)) by Horner's rule in one buffer: the same operations in
    # the same order (IEEE addition and multiplication commute exactly), without the five
    # full-size temporaries of the expression (a map of 1024×768×3 is 19 MB each)
    v = r * m3
    v += m2
    v *= r
    v += m1
    v *= r
    v += 1.0
    return v


def _as_channel_params(params: Any, name: str = "params") -> np.ndarray:
    """Return parameters as a finite float64 ``(C, 6)`` array."""
    params = check_array(params, name, kind="iuf", finite=True).astype(np.float64)
    if params.ndim == 1:
        params = params[None, :]
    if params.ndim != 2 or params.shape[1] != _N_PARAMS:
        raise InputError(f"`{name}` must have shape (C, 6) or (6,), got {params.shape}")
    return params


def _pixel_centres(
    h: int, w: int, y0: int = 0, y1: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(x_n, y_n)`` of the pixel centres of rows ``y0 … y1 − 1`` (every row by default)
    in raster order, ``((x + 0.5)/W, (y + 0.5)/H)``."""
    y1 = h if y1 is None else y1
    x_n = np.tile((np.arange(w, dtype=np.float64) + 0.5) / w, y1 - y0)
    y_n = np.repeat((np.arange(y0, y1, dtype=np.float64) + 0.5) / h, w)
    return x_n, y_n


_MAP_BAND_PIXELS = 1 << 14
"""Pixels per band of :meth:`ExtendedGoldmanChenVignetting.log_map_variance` (its
Jacobian, 6 × 8 bytes a pixel, 0.75 MiB: within a core's L2 cache)."""


def _log_variance_rows(
    x_n: np.ndarray, y_n: np.ndarray, p: np.ndarray, cov: np.ndarray, at_gradient: Any
) -> np.ndarray:
    """``Var(ln v)`` at the points ``(x_n, y_n)`` of one channel (``at_gradient``: less
    the gradient at a reference point, or ``None``), clipped at 0."""
    v, rows = _model_and_jacobian_rows(x_n, y_n, p)  # (6, N)
    if at_gradient is None:
        # gᵀ Cov g per pixel as Σ_j g_j (Cov g)_j: one matrix product, one reduction
        var = np.einsum("jn,jn->n", rows, cov @ rows) / (v * v)
    else:
        rows = rows / v - at_gradient[:, None]
        var = np.einsum("jn,jn->n", rows, cov @ rows)
    return np.maximum(var, 0.0)


def _normalised_point(
    point: tuple[float, float] | None, h: int, w: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """A point ``(x, y)`` in pixels as one-element ``(x_n, y_n)`` arrays (``None`` stays);
    a point that is not finite is an error naming ``relative_to``."""
    if point is None:
        return None
    x_r, y_r = (float(c) for c in point)
    if not (np.isfinite(x_r) and np.isfinite(y_r)):
        raise InputError(f"`relative_to` must be a finite point (x, y), got {point!r}")
    return np.array([x_r / w]), np.array([y_r / h])


def _log_gradient_at(at: tuple[np.ndarray, np.ndarray], params: np.ndarray) -> np.ndarray:
    """``∂ln v/∂p`` at one normalised point, shape ``(6,)``."""
    v, rows = _model_and_jacobian_rows(*at, params)
    return rows[:, 0] / v[0]


def vignetting_map(params: Any, image_shape: tuple[int, int]) -> np.ndarray:
    """Evaluate the vignetting model at every pixel centre of an image.

    Parameters
    ----------
    params : array_like, shape (C, 6) or (6,)
        Model parameters per channel (a ``(6,)`` vector is one channel).
    image_shape : tuple of int
        ``(H, W)``; extra trailing entries are ignored.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``v`` at pixel ``(x, y)`` (row ``y``, column ``x``), evaluated at
        ``((x + 0.5)/W, (y + 0.5)/H)``.

    Examples
    --------
    >>> v = vignetting_map([[-0.4, 0, 0, 1, 0.5, 0.5]], (3, 3))
    >>> v.shape, float(v[1, 1, 0])
    ((3, 3, 1), 1.0)
    """
    params = _as_channel_params(params)
    h, w = _check_image_shape(image_shape)
    x_n = ((np.arange(w, dtype=np.float64) + 0.5) / w)[None, :, None]
    y_n = ((np.arange(h, dtype=np.float64) + 0.5) / h)[:, None, None]
    return vignetting_ExtendedGoldmanChen(x_n, y_n, params)


def _model_and_jacobian(
    x_n: np.ndarray, y_n: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Return ``v`` (N,) and ``∂v/∂p`` (N, 6) for one channel's parameters ``p``."""
    m1, m2, m3, m4, m5, m6 = p
    dx = x_n - m5
    dy = y_n - m6
    r = m4 * dx**2 + dy**2
    v = 1.0 + r * (m1 + r * (m2 + r * m3))
    dv_dr = m1 + r * (2.0 * m2 + 3.0 * r * m3)
    jac = np.empty((x_n.size, _N_PARAMS))
    jac[:, 0] = r
    jac[:, 1] = r**2
    jac[:, 2] = r**3
    jac[:, 3] = dv_dr * dx**2
    jac[:, 4] = dv_dr * (-2.0 * m4 * dx)
    jac[:, 5] = dv_dr * (-2.0 * dy)
    return v, jac


def _model_and_jacobian_rows(
    x_n: np.ndarray, y_n: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_model_and_jacobian` with the Jacobian transposed, ``(6, N)`` C-ordered.

    One contiguous row per parameter: the fit combines the rows of the pairs'
    two observations with 1-D weights, which numpy streams row by row instead
    of walking six interleaved columns (the fit's Jacobian, 3× faster).
    """
    m1, m2, m3, m4, m5, m6 = p
    dx = x_n - m5
    dy = y_n - m6
    dx2 = dx * dx
    r = m4 * dx2 + dy * dy
    v = 1.0 + r * (m1 + r * (m2 + r * m3))
    dv_dr = m1 + r * (2.0 * m2 + 3.0 * r * m3)
    jac = np.empty((_N_PARAMS, x_n.size))
    jac[0] = r
    np.multiply(r, r, out=jac[1])
    np.multiply(jac[1], r, out=jac[2])
    np.multiply(dv_dr, dx2, out=jac[3])
    np.multiply(dv_dr, -2.0 * m4 * dx, out=jac[4])
    np.multiply(dv_dr, -2.0 * dy, out=jac[5])
    return v, jac


def _range_over_image(p: np.ndarray, image_shape: tuple[int, int]) -> tuple[float, float]:
    """Exact minimum and maximum of ``v`` over the rectangle spanned by the pixel centres.

    ``R`` is continuous on that rectangle, so it takes every value of
    ``[R_min, R_max]``; the extrema of the cubic ``v(R)`` on that interval lie
    at its ends or at a stationary point. The minimum bounds ``v`` on the pixel
    grid from below without evaluating the full map.
    """
    h, w = image_shape
    m1, m2, m3, m4, m5, m6 = p

    def square_range(lo: float, hi: float, c: float) -> tuple[float, float]:
        ends = ((lo - c) ** 2, (hi - c) ** 2)
        return (0.0 if lo <= c <= hi else min(ends)), max(ends)

    x_lo, x_hi = square_range(0.5 / w, (w - 0.5) / w, m5)
    y_lo, y_hi = square_range(0.5 / h, (h - 0.5) / h, m6)
    rx = (m4 * x_lo, m4 * x_hi)
    r_lo, r_hi = min(rx) + y_lo, max(rx) + y_hi
    candidates = [r_lo, r_hi]
    if m2 != 0.0 or m3 != 0.0:
        for root in np.roots([3.0 * m3, 2.0 * m2, m1]):
            if abs(root.imag) < 1e-12 and r_lo <= root.real <= r_hi:
                candidates.append(float(root.real))
    r = np.asarray(candidates)
    v = 1.0 + r * (m1 + r * (m2 + r * m3))
    return float(np.min(v)), float(np.max(v))


# ---------------------------------------------------------------------------
# Calibration
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class VignettingFit:
    """Result of a vignetting calibration.

    Attributes
    ----------
    params : ndarray, shape (C, 6)
        Fitted ``(m1, m2, m3, m4, m5, m6)`` per channel.
    residual_rms : ndarray, shape (C,)
        Root mean square of the final residuals of each channel, as fitted
        (see ``normalise`` and ``scale_invariant`` of
        :func:`fit_vignetting_ExtendedGoldmanChen`): relative, i.e.
        dimensionless, for the default ``normalise="track"``.
    n_tracks : int
        Tracks (scene points) with at least two usable observations.
    n_pairs : int
        Pairs of observations, i.e. residuals per channel.
    n_observations : int
        Usable observations in those tracks.
    converged : ndarray of bool, shape (C,)
        Whether the solver met its tolerances *and* the fitted model is
        positive over the whole image and has not collapsed towards zero.
        ``False`` marks a result that must not be trusted.
    message : str
        Human-readable summary, with the reason for every ``False`` in
        ``converged`` and the number of dropped observations.
    map_uncertainty : ndarray, shape (C,), optional
        First-order standard uncertainty of the fitted map relative to its
        value, averaged over the image (from the residual variance and the
        Jacobian at the solution). A large value says the views do not
        constrain the model, e.g. a pure pan leaves the vertical profile
        nearly free. Statistical only: it excludes systematic errors such as
        misregistered correspondences, and as a linearisation it understates
        the error of a badly constrained fit. ``None`` when not computed.
    view_gains : ndarray, shape (C, V), optional
        With ``view_gains=True``: the fitted gain ``a_j`` of each view, the
        factor that puts view ``j``'s values on the scale of the reference
        view (the lowest-numbered view with observations, gain 1): the
        exposure correction of view ``j`` is ``t_j → t_j / a_j``. NaN for a
        view without observations; ``None`` without view gains.
    view_gain_std : ndarray, shape (C, V), optional
        First-order standard uncertainty of ``view_gains`` (0 for the reference).
    param_covariance : ndarray, shape (C, 6, 6), optional
        First-order covariance of ``params`` per channel (marginal over the
        view gains), with ``value_log_loadings`` its part inherited from them
        included; NaN for a channel that did not converge.
    param_response_covariance : ndarray, shape (C, 6, 6), optional
        With ``value_log_loadings``: the part of ``param_covariance``
        inherited from them (the rest is the fit's own statistical error,
        which ``map_uncertainty`` averages).
    """

    params: np.ndarray
    residual_rms: np.ndarray
    n_tracks: int
    n_pairs: int
    n_observations: int
    converged: np.ndarray
    message: str
    map_uncertainty: np.ndarray | None = None
    view_gains: np.ndarray | None = None
    view_gain_std: np.ndarray | None = None
    param_covariance: np.ndarray | None = None
    param_response_covariance: np.ndarray | None = None


def _pairs_within_tracks(
    track_index: np.ndarray, order_key: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All index pairs ``(a, b)`` with equal ``track_index``, ordered by ``order_key``.

    Returns ``(a, b, pair_track)``; ``order_key[a] < order_key[b]`` when the keys
    within a track are distinct. Vectorised over tracks of equal size (one
    iteration per distinct track length, which is at most the number of views).
    """
    order = np.lexsort((order_key, track_index))
    sorted_tracks = track_index[order]
    starts = np.flatnonzero(np.r_[True, sorted_tracks[1:] != sorted_tracks[:-1]])
    sizes = np.diff(np.r_[starts, sorted_tracks.size])
    a_parts, b_parts = [], []
    for size in np.unique(sizes):
        if size < 2:
            continue
        first, second = np.triu_indices(int(size), k=1)
        group_starts = starts[sizes == size]
        a_parts.append((group_starts[:, None] + first[None, :]).ravel())
        b_parts.append((group_starts[:, None] + second[None, :]).ravel())
    if not a_parts:
        empty = np.empty(0, dtype=np.intp)
        return empty, empty, empty
    a = order[np.concatenate(a_parts)]
    b = order[np.concatenate(b_parts)]
    return a, b, track_index[a]


def _labels(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(x, return_inverse=True)``, in O(n) when ``x`` is sorted (tracks in order)."""
    x = np.asarray(x)
    if x.size and np.all(x[1:] >= x[:-1]):
        new = np.r_[True, x[1:] != x[:-1]]
        return x[new], np.cumsum(new) - 1
    values, inverse = np.unique(x, return_inverse=True)
    return values, inverse.reshape(-1)


def _view_labels(view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(view, return_inverse=True)`` for small non-negative view indices (a table)."""
    present = np.flatnonzero(np.bincount(view))
    table = np.full(int(present[-1]) + 1 if present.size else 1, -1, dtype=np.intp)
    table[present] = np.arange(present.size)
    return present, table[view]


def _spread(coord: np.ndarray) -> float:
    """Extent of ``coord`` between its 5th and 95th percentiles."""
    lo, hi = np.percentile(coord, [5.0, 95.0])
    return float(hi - lo)


def _view_gain_columns(
    weight: np.ndarray,
    first: np.ndarray,
    second: np.ndarray,
    ratio: np.ndarray | float,
    gains: np.ndarray,
    gain_a: np.ndarray,
    gain_b: np.ndarray,
) -> np.ndarray:
    """``∂u/∂a_k`` of ``u = w (ρ first − second / ρ)``, ``ρ = √(a_i / a_j)``, for ``k ≥ 1``.

    ``gains`` are all the gains (``gains[0] = 1``, fixed); ``gain_a``/``gain_b``
    the gain indices of each pair's two views; ``ratio`` is ``ρ`` per pair.
    """
    n_gains = gains.size - 1
    cols = np.zeros((weight.size, n_gains))
    rows = np.arange(weight.size)
    rho = np.broadcast_to(np.asarray(ratio, dtype=np.float64), weight.shape)
    common = weight * (first + second / rho**2) * rho / 2.0  # ∂u/∂ρ · ρ / 2
    sel = gain_a > 0
    np.add.at(cols, (rows[sel], gain_a[sel] - 1), common[sel] / gains[gain_a[sel]])
    sel = gain_b > 0
    np.add.at(cols, (rows[sel], gain_b[sel] - 1), -common[sel] / gains[gain_b[sel]])
    return cols


def _solve_pairs(
    residuals: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray], np.ndarray],
    p0: np.ndarray,
    n_model: int,
    max_nfev: int,
    gain_prior: float | None = None,
) -> tuple[Any, np.ndarray, np.ndarray]:
    """Levenberg–Marquardt on the pair residuals, with an optional Gaussian prior on the gains.

    The parameters are ``n_model`` of the model followed by the free view gains.
    With ``gain_prior = σ_a`` the objective is ``Σ r² / σ_r² + Σ (a_j − 1)² / σ_a²``
    (``σ_r`` the residuals' own scale, measured by a first fit with every gain
    at 1): the rows ``(σ_r / σ_a)(a_j − 1)`` are appended. Returns the solver's
    result, the data residuals at the solution and the parameters' covariance
    ``σ_r² (JᵀJ)⁺`` over all rows (the posterior's, first order).
    """
    from scipy.optimize import least_squares  # here only: 70 ms to import

    n_gains = p0.size - n_model
    lam = 0.0
    if n_gains and gain_prior is not None:
        fixed = np.r_[p0[:n_model], np.ones(n_gains)]

        def res_model(q: np.ndarray) -> np.ndarray:
            return residuals(np.r_[q, fixed[n_model:]])

        def jac_model(q: np.ndarray) -> np.ndarray:
            return jacobian(np.r_[q, fixed[n_model:]])[:, :n_model]

        first = least_squares(
            res_model, p0[:n_model], jac=jac_model, method="lm", x_scale="jac", max_nfev=max_nfev
        )
        sigma_r = float(np.sqrt(first.fun @ first.fun / max(first.fun.size - n_model, 1)))
        lam = sigma_r / float(gain_prior)
        p0 = np.r_[first.x, np.ones(n_gains)]

    def res(p: np.ndarray) -> np.ndarray:
        r = residuals(p)
        return np.r_[r, lam * (p[n_model:] - 1.0)] if lam else r

    def jac(p: np.ndarray) -> np.ndarray:
        j = jacobian(p)
        if not lam:
            return j
        prior = np.zeros((n_gains, p.size))
        prior[:, n_model:] = lam * np.eye(n_gains)
        return np.r_[j, prior]

    result = least_squares(
        res,
        p0,
        jac=jac,
        method="lm",
        x_scale="jac",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
        max_nfev=int(max_nfev),
    )
    fun = result.fun[: result.fun.size - (n_gains if lam else 0)]
    dof = max(fun.size - (n_model if lam else p0.size), 1)
    cov = float(fun @ fun) / dof * np.linalg.pinv(result.jac.T @ result.jac, rcond=1e-12)
    return result, fun, cov


@dataclass(frozen=True)
class _FitSettings:
    """The checked options of one extended Goldman–Chen fit.

    See :func:`fit_vignetting_ExtendedGoldmanChen` for their meaning;
    ``scale_invariant`` and ``view_gains`` are plain bools, the others are
    kept as given.
    """

    normalise: str
    scale_invariant: bool
    view_gains: bool
    view_gain_centre: str
    view_gain_sigma: float | None
    min_pairs: int
    max_nfev: int
    min_spread: float
    max_uncertainty: float
    sample_radius: int = 0

    @classmethod
    def checked(
        cls,
        *,
        normalise: str,
        scale_invariant: bool,
        view_gains: bool,
        view_gain_centre: str,
        view_gain_sigma: float | None,
        min_pairs: int,
        max_nfev: int,
        min_spread: float,
        max_uncertainty: float,
        sample_radius: int = 0,
    ) -> _FitSettings:
        """The settings, or an InputError naming the first malformed option (in this order)."""
        if normalise not in ("track", "none"):
            raise InputError(f"`normalise` must be 'track' or 'none', got {normalise!r}")
        if not isinstance(scale_invariant, bool | np.bool_):
            raise InputError(f"`scale_invariant` must be a bool, got {scale_invariant!r}")
        if not isinstance(view_gains, bool | np.bool_):
            raise InputError(f"`view_gains` must be a bool, got {view_gains!r}")
        if view_gain_centre not in ("image", "free"):
            raise InputError(
                f"`view_gain_centre` must be 'image' or 'free', got {view_gain_centre!r}"
            )
        if view_gain_sigma is not None and not (
            isinstance(view_gain_sigma, int | float | np.number) and view_gain_sigma > 0
        ):
            raise InputError(
                f"`view_gain_sigma` must be a positive number, got {view_gain_sigma!r}"
            )
        min_pairs = check_int(min_pairs, "min_pairs", 1)
        max_nfev = check_int(max_nfev, "max_nfev", 1)
        if not isinstance(min_spread, int | float | np.number) or not 0.0 <= min_spread <= 1.0:
            raise InputError(f"`min_spread` must be a number in [0, 1], got {min_spread!r}")
        if not isinstance(max_uncertainty, int | float | np.number) or not max_uncertainty > 0:
            raise InputError(
                f"`max_uncertainty` must be a positive number, got {max_uncertainty!r}"
            )
        sample_radius = check_int(sample_radius, "sample_radius", 0, 64)
        return cls(
            normalise=normalise,
            scale_invariant=bool(scale_invariant),
            view_gains=bool(view_gains),
            view_gain_centre=view_gain_centre,
            view_gain_sigma=view_gain_sigma,
            min_pairs=min_pairs,
            max_nfev=max_nfev,
            min_spread=min_spread,
            max_uncertainty=max_uncertainty,
            sample_radius=sample_radius,
        )


def _checked_observations(
    values: Any, xy: Any, view: Any, track: Any, image_shape: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """The observations as checked arrays, and ``(H, W)``.

    ``values`` (M, C) and ``xy`` (M, 2) as float64, ``view`` and ``track``
    (M,) as integers; an InputError names the first malformed argument.
    """
    values = check_array(values, "values", ndim=2, kind="iuf").astype(np.float64)
    m = values.shape[0]
    xy = check_array(xy, "xy", shape=(m, 2), kind="iuf", finite=True).astype(np.float64)
    view = check_array(view, "view", shape=(m,), kind="iu")
    track = check_array(track, "track", shape=(m,), kind="iu")
    return values, xy, view, track, _check_image_shape(image_shape)


def _check_positions(xy: np.ndarray, view: np.ndarray, image_shape: tuple[int, int]) -> None:
    """Raise an InputError for a point outside the image or a negative view index."""
    h, w = image_shape
    x, y = xy[:, 0], xy[:, 1]
    if np.any((x < -0.5) | (x > w - 0.5) | (y < -0.5) | (y > h - 0.5)):
        raise InputError(
            f"`xy` has points outside the image of shape {(h, w)} "
            "(valid: -0.5 <= x <= W - 0.5 and -0.5 <= y <= H - 0.5)"
        )
    if np.any(view < 0):
        raise InputError("`view` must hold non-negative view indices")


def _starting_parameters(initial: Any, n_channels: int, view_gains: bool) -> np.ndarray | None:
    """``initial`` as ``(C, 6)`` starting parameters, a ``(6,)`` vector repeated per channel.

    ``None`` without ``initial``: each channel then starts from its linear
    least-squares solution (:meth:`_PairProblem.linear_start`).
    """
    if initial is None:
        return None
    start = _as_channel_params(initial, "initial")
    if view_gains:
        raise InputError("`initial` cannot be combined with `view_gains`")
    if start.shape[0] == 1:
        return np.repeat(start, n_channels, axis=0)
    if start.shape[0] != n_channels:
        raise InputError(f"`initial` must have shape (6,) or ({n_channels}, 6), got {start.shape}")
    return start


def _track_index(track: np.ndarray, view: np.ndarray) -> np.ndarray:
    """Each observation's track as a label ``0 … T − 1``, in the order of the track ids.

    A track that lists a view twice is malformed, not noisy: an InputError.
    """
    # np.unique's hash path is 70 ms on 3 × 10⁵ observations: sorted input and
    # small view indices take the O(n) routes of _labels and _view_labels
    _, track_index = _labels(track)
    key = track_index.astype(np.int64) * (int(view.max()) + 1) + view.astype(np.int64)
    if not np.all(key[1:] > key[:-1]):
        key = np.sort(key)
        if np.any(key[1:] == key[:-1]):
            raise InputError("`track` lists the same view twice for at least one scene point")
    return track_index


@dataclass(frozen=True)
class _PairedObservations:
    """The usable observations that take part in a pair, and the pairs ``(a, b)``.

    An observation is usable when its values are finite and positive in every
    channel; every pair of usable observations of one track is a pair, ``a``
    in the lower-numbered view.
    """

    values: np.ndarray  # (n_observations, C)
    x_n: np.ndarray  # (n_observations,) normalised pixel-centre coordinates
    y_n: np.ndarray
    a: np.ndarray  # (n_pairs,) indices into the observations
    b: np.ndarray
    obs_view: np.ndarray  # (n_observations,) view of each observation
    obs_track: np.ndarray  # (n_observations,) track label 0 … n_tracks − 1
    pair_track: np.ndarray  # (n_pairs,) track label of each pair
    source: np.ndarray  # (n_observations,) index of each among the observations given
    n_tracks: int
    n_pairs: int
    n_observations: int
    n_views: int
    dropped_note: str  # how many observations were dropped as unusable, in words


def _paired_observations(
    values: np.ndarray,
    xy: np.ndarray,
    view: np.ndarray,
    track_index: np.ndarray,
    image_shape: tuple[int, int],
) -> _PairedObservations:
    """The usable observations in pairs within their tracks, re-indexed to those in a pair.

    Raises a CalibrationError when fewer than two views have usable observations.
    """
    h, w = image_shape
    m = values.shape[0]
    usable = np.all(np.isfinite(values) & (values > 0), axis=1)
    n_dropped = int(m - np.count_nonzero(usable))
    dropped_note = f"{n_dropped} of {m} observations dropped for non-finite or non-positive values"
    n_usable_views = int(np.count_nonzero(np.bincount(view[usable]))) if usable.any() else 0
    if n_usable_views < 2:
        raise CalibrationError(
            f"vignetting fit needs usable observations in at least 2 views (view directions); "
            f"got {n_usable_views} ({dropped_note})"
        )
    a, b, _ = _pairs_within_tracks(track_index[usable], view[usable])
    in_pair = np.zeros(np.count_nonzero(usable), dtype=bool)
    in_pair[a] = True
    in_pair[b] = True
    used = np.flatnonzero(in_pair)
    remap = np.full(np.count_nonzero(usable), -1)
    remap[used] = np.arange(used.size)
    a, b = remap[a], remap[b]
    obs_view = view[usable][used]
    obs_track = _labels(track_index[usable][used])[1]
    n_obs = int(used.size)
    return _PairedObservations(
        values=values[usable][used],
        x_n=(xy[usable][used, 0] + 0.5) / w,
        y_n=(xy[usable][used, 1] + 0.5) / h,
        a=a,
        b=b,
        obs_view=obs_view,
        obs_track=obs_track,
        pair_track=obs_track[a],
        source=np.flatnonzero(usable)[used],
        n_tracks=int(obs_track.max()) + 1 if n_obs else 0,
        n_pairs=int(a.size),
        n_observations=n_obs,
        n_views=int(np.count_nonzero(np.bincount(obs_view))),
        dropped_note=dropped_note,
    )


def _check_pairs_suffice(pairs: _PairedObservations, min_pairs: int, min_spread: float) -> None:
    """Raise a CalibrationError when the pairs are too few or bunched in one spot of the image."""
    if pairs.n_pairs < min_pairs:
        raise CalibrationError(
            f"vignetting fit needs at least {min_pairs} pairs of observations of one scene "
            f"point in two views; only {pairs.n_pairs} usable pairs from {pairs.n_tracks} "
            f"tracks ({pairs.dropped_note})"
        )
    spread_x, spread_y = _spread(pairs.x_n), _spread(pairs.y_n)
    if min(spread_x, spread_y) < min_spread:
        raise CalibrationError(
            f"vignetting fit needs observations spread over the image: the "
            f"{pairs.n_observations} usable observations span {spread_x:.1%} of the width "
            f"and {spread_y:.1%} of the height (5th to 95th percentile); at least "
            f"{min_spread:.0%} of each is needed"
        )


def _pair_weights(c: np.ndarray, pairs: _PairedObservations, normalise: str) -> np.ndarray:
    """The weight of each pair's residual: 1 over its track's mean of ``c``, or 1.

    The former with ``normalise="track"``, the latter with ``"none"``.
    """
    if normalise == "track":
        track_mean = np.bincount(pairs.obs_track, weights=c) / np.bincount(pairs.obs_track)
        return 1.0 / track_mean[pairs.pair_track]
    return np.ones(pairs.n_pairs)


def _pair_problem(
    pairs: _PairedObservations,
    c: np.ndarray,
    settings: _FitSettings,
    gain_index: np.ndarray,
    n_gains: int,
) -> _PairProblem:
    """The least-squares problem of one channel's values ``c`` over the pairs, with
    ``n_gains`` free view gains (none: the views' gain indices are not passed)."""
    return _PairProblem(
        pairs.x_n,
        pairs.y_n,
        pairs.a,
        pairs.b,
        c[pairs.a],
        c[pairs.b],
        _pair_weights(c, pairs, settings.normalise),
        settings.scale_invariant,
        gain_index[pairs.a] if n_gains else None,
        gain_index[pairs.b] if n_gains else None,
        n_gains,
    )


def _centred_gains(
    pairs: _PairedObservations,
    c: np.ndarray,
    settings: _FitSettings,
    gain_index: np.ndarray,
    n_gains: int,
    loadings: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One channel's view gains (reference first, 1) and their std, centre held at the
    image's; with ``loadings`` ``(n_obs, R)`` also the moves of their logarithms per unit
    of each variate, ``(n_gains + 1, R)`` (0 for the reference; :func:`_response_shift`)."""
    problem = _pair_problem(pairs, c, settings, gain_index, n_gains)
    free = np.r_[0, 1, 2, 3, np.arange(_N_PARAMS, _N_PARAMS + n_gains)]

    def full(q: np.ndarray) -> np.ndarray:
        return np.r_[q[:4], 0.5, 0.5, q[4:]]

    result, _, cov = _solve_pairs(
        lambda q: problem.residuals(full(q)),
        lambda q: problem.jacobian(full(q))[:, free],
        problem.linear_start()[free],
        4,
        settings.max_nfev,
        settings.view_gain_sigma,
    )
    std = np.sqrt(np.maximum(np.diag(cov)[4:], 0.0))
    gains = np.r_[1.0, result.x[4:]]
    moves = None
    if loadings is not None:
        shift = _response_shift(problem, pairs, c, settings, full(result.x), loadings, free)
        moves = np.vstack([np.zeros((1, loadings.shape[1])), shift[:, 4:].T / gains[1:, None]])
    return gains, np.r_[0.0, std], moves


@dataclass(frozen=True)
class _PairProblem:
    """Residuals ``w (c_a v_b − c_b v_a) / s`` of one channel and their Jacobian.

    ``s = sqrt(mean(v²))``, the RMS of ``v`` over the observations, when
    ``scale_invariant``, else 1: the residual is of degree 1 in ``v``, so
    dividing by ``s`` makes it invariant to a common scale of ``v``.

    With ``n_gains > 0`` the parameters are the six of the model followed by
    the free view gains ``a_1 … a_{n_gains}`` (``a_0 = 1``); ``gain_a`` and
    ``gain_b`` give the gain index of the views of ``a`` and ``b``, and the
    residual is ``w (a_i c_a v_b − a_j c_b v_a) / (s √(a_i a_j))``: dividing
    by ``√(a_i a_j)`` makes it invariant to a common scale of the gains, as
    ``s`` does for ``v`` (without it, shrinking every gain but the fixed one
    would shrink the residuals).
    """

    x_n: np.ndarray
    y_n: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c_a: np.ndarray
    c_b: np.ndarray
    weight: np.ndarray
    scale_invariant: bool
    gain_a: np.ndarray | None = None
    gain_b: np.ndarray | None = None
    n_gains: int = 0

    def _ratio(self, p: np.ndarray) -> tuple[np.ndarray | float, np.ndarray]:
        """``ρ = √(a_i / a_j)`` per pair (1 without gains) and all gains."""
        gains = np.r_[1.0, p[_N_PARAMS:]]
        if not self.n_gains or self.gain_a is None or self.gain_b is None:
            return 1.0, gains
        return np.sqrt(gains[self.gain_a] / gains[self.gain_b]), gains

    def residuals(self, p: np.ndarray) -> np.ndarray:
        v = _evaluate(self.x_n, self.y_n, p[:_N_PARAMS])
        rho, _ = self._ratio(p)
        u = self.weight * (rho * self.c_a * v[self.b] - self.c_b * v[self.a] / rho)
        return u / np.sqrt(np.mean(v**2)) if self.scale_invariant else u

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        v, jv_rows = _model_and_jacobian_rows(self.x_n, self.y_n, p[:_N_PARAMS])
        rho, gains = self._ratio(p)
        ca = np.broadcast_to(np.asarray(rho * self.c_a), self.c_a.shape)
        cb = np.broadcast_to(np.asarray(self.c_b / rho), self.c_b.shape)
        # du_j = w (ca ∂v_b/∂p_j − cb ∂v_a/∂p_j), built row by row (6, P), returned as
        # its transpose (P, 6), Fortran-ordered as MINPACK stores a Jacobian
        wa, wb = self.weight * cb, self.weight * ca
        du_rows = jv_rows.take(self.b, axis=1)
        du_rows *= wb
        du_rows -= jv_rows.take(self.a, axis=1) * wa
        if not self.scale_invariant and not self.n_gains:
            return du_rows.T
        du = du_rows.T
        if self.n_gains and self.gain_a is not None and self.gain_b is not None:
            du = np.c_[
                du,
                _view_gain_columns(
                    self.weight,
                    self.c_a * v[self.b],
                    self.c_b * v[self.a],
                    rho,
                    gains,
                    self.gain_a,
                    self.gain_b,
                ),
            ]
        if not self.scale_invariant:
            return du
        # r = u / s with s = sqrt(mean(v²)): ∂r = (∂u − r ∂s) / s, ∂s = mean(v ∂v) / s
        # (s does not depend on the gains).
        s = np.sqrt(np.mean(v**2))
        r = self.weight * (ca * v[self.b] - cb * v[self.a]) / s
        ds = np.r_[(jv_rows @ v) / (v.size * s), np.zeros(du.shape[1] - _N_PARAMS)]
        if du.shape[1] == _N_PARAMS:  # in place, row by row, on the (6, P) rows
            du_rows -= ds[:, None] * r[None, :]
            du_rows /= s
            return du_rows.T
        return (du - r[:, None] * ds[None, :]) / s

    def linear_start(self) -> np.ndarray:
        """Least-squares ``m1..m3`` (and gains) at ``m4 = 1, m5 = m6 = 0.5``.

        ``c_a v_b − c_b v_a = (c_a − c_b) + Σ_k m_k (c_a R_b^k − c_b R_a^k)`` is
        linear in ``m1..m3``; view gains ``a = 1 + δ`` add, to first order in
        ``m`` and ``δ``, ``(δ_i − δ_j)(c_a + c_b) / 2``, also linear.
        """
        r = (self.x_n - 0.5) ** 2 + (self.y_n - 0.5) ** 2
        powers = np.stack([r, r**2, r**3], axis=1)
        design = self.weight[:, None] * (
            self.c_a[:, None] * powers[self.b] - self.c_b[:, None] * powers[self.a]
        )
        if self.n_gains and self.gain_a is not None and self.gain_b is not None:
            design = np.c_[
                design,
                _view_gain_columns(
                    self.weight,
                    self.c_a,
                    self.c_b,
                    1.0,
                    np.ones(self.n_gains + 1),
                    self.gain_a,
                    self.gain_b,
                ),
            ]
        target = -self.weight * (self.c_a - self.c_b)
        coef, *_ = np.linalg.lstsq(design, target, rcond=None)
        return np.r_[coef[:3], 1.0, 0.5, 0.5, 1.0 + coef[3:]]


def _map_uncertainty(
    p: np.ndarray,
    fun: np.ndarray,
    jac: np.ndarray,
    image_shape: tuple[int, int],
    cov: np.ndarray | None = None,
) -> float:
    """Mean first-order relative standard uncertainty of ``v`` over the image.

    ``Cov(p) ≈ σ² (JᵀJ)⁺`` with ``σ² = Σ r² / (P − n_params)``; the variance of ``v``
    at a point is ``gᵀ Cov g`` with ``g = ∂v/∂p``, evaluated on a grid of at
    most 32 × 32 pixel centres. The pseudo-inverse ignores directions that do
    not change the map (e.g. the centre when ``m1 = m2 = m3 = 0``).
    """
    h, w = image_shape
    cov = (_parameter_covariance(fun, jac) if cov is None else cov)[:_N_PARAMS, :_N_PARAMS]
    xs = (np.unique(np.linspace(0, w - 1, min(w, 32)).round()) + 0.5) / w
    ys = (np.unique(np.linspace(0, h - 1, min(h, 32)).round()) + 0.5) / h
    gx, gy = np.meshgrid(xs, ys)
    v, g = _model_and_jacobian(gx.ravel(), gy.ravel(), p[:_N_PARAMS])
    var = np.einsum("ij,jk,ik->i", g, cov, g)
    return float(np.mean(np.sqrt(np.maximum(var, 0.0)) / np.abs(v)))


def _track_clustered_covariance(
    jac: np.ndarray,
    fun: np.ndarray,
    pair_track: np.ndarray,
    neighbours: np.ndarray | None = None,
) -> np.ndarray:
    """``B⁺ M B⁺``, ``B = JᵀJ``: the sandwich covariance of all parameters with the
    track as the cluster [Liang1986]_, neighbouring tracks correlated [Conley1999]_.

    The pair residuals of one track share its values (and, track-normalised, its
    mean), so they are not independent as ``σ² (JᵀJ)⁺`` assumes: measured on
    analytic tracks with independent 0.5 % noise per value (three views, 400
    points, 40 seeds), the maps' scatter was 1.24× what ``σ² (JᵀJ)⁺`` states.
    ``M = T/(T − 1) (Σ_t s_t s_tᵀ + Σ_{(t, u)} (s_t s_uᵀ + s_u s_tᵀ))`` with
    ``s_t = Σ_{pairs of t} J_i r_i`` over the data rows, the second sum over the
    pairs of tracks in ``neighbours``: values averaged over windows that share
    pixels share their noise, and ``s_t s_uᵀ`` estimates the covariance of two
    such tracks' scores whatever the noise (a spatial HAC term with a uniform
    kernel cut at the windows' reach; the result is made positive semi-definite
    by clipping ``M``'s negative eigenvalues). Tracks 2 px apart sampled over
    3 × 3 windows (pqsim's capture sets, ``sample_radius = 1``): the
    track-clustered form alone stated 0.7× the maps' actual scatter. Rows beyond
    the data (a Gaussian prior on view gains) enter ``M`` as observations of the
    residual variance ``σ² = Σ r² / (n − P)``.

    References
    ----------
    .. [Conley1999] T. G. Conley, "GMM estimation with cross sectional
       dependence", J. Econometrics 92(1), 1999 (the spatial HAC covariance).
    """
    n_data, n_par = fun.size, jac.shape[1]
    data, extra = jac[:n_data], jac[n_data:]
    labels, cluster = np.unique(pair_track, return_inverse=True)
    n_clusters = int(cluster.max()) + 1 if cluster.size else 0
    scores = np.stack(
        [np.bincount(cluster, data[:, j] * fun, n_clusters) for j in range(n_par)], axis=1
    )
    meat: np.ndarray = np.asarray(scores.T @ scores, dtype=np.float64)
    if neighbours is not None and neighbours.size and n_clusters:
        t = np.searchsorted(labels, neighbours[:, 0])
        u = np.searchsorted(labels, neighbours[:, 1])
        cross = scores[t].T @ scores[u]
        meat = meat + cross + cross.T
        eigval, eigvec = np.linalg.eigh(0.5 * (meat + meat.T))
        meat = (eigvec * np.maximum(eigval, 0.0)) @ eigvec.T
    meat = meat * (n_clusters / max(n_clusters - 1, 1))
    if extra.size:
        meat += float(fun @ fun) / max(n_data - n_par, 1) * (extra.T @ extra)
    bread = np.linalg.pinv(jac.T @ jac, rcond=1e-12)
    cov = bread @ meat @ bread
    return 0.5 * (cov + cov.T)


def _overlapping_tracks(
    pairs: _PairedObservations, image_shape: tuple[int, int], radius: int
) -> np.ndarray:
    """Pairs ``(t, u)``, ``t < u``, of track labels with observations in one view whose
    sampling windows (``(2r + 1)²`` bilinear samples about each point) share pixels:
    ``|Δx| < 2r + 1`` and ``|Δy| < 2r + 1`` at pixel centres, ``< 2r + 2`` where any
    point lies between them (a bilinear sample reads the next pixel too); shape
    ``(n, 2)`` (none for ``r = 0`` at pixel centres, whose samples share no pixel)."""
    h, w = image_shape
    x = pairs.x_n * w - 0.5
    y = pairs.y_n * h - 0.5
    on_centres = bool(
        np.all(np.abs(x - np.round(x)) < 1e-9) and np.all(np.abs(y - np.round(y)) < 1e-9)
    )
    reach = 2 * radius + (1 if on_centres else 2)
    found = []
    for view in np.unique(pairs.obs_view):
        idx = np.flatnonzero(pairs.obs_view == view)
        if idx.size < 2:
            continue
        cell_x = np.floor(x[idx] / reach).astype(np.int64)
        cell_y = np.floor(y[idx] / reach).astype(np.int64)
        n_cx = int(cell_x.max()) + 3
        key = (cell_y + 1) * n_cx + (cell_x + 1)
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        for dy in (-1, 0, 1):  # a window's reach is one cell: the 3 × 3 cells about it
            for dx in (-1, 0, 1):
                target = sorted_key + (dy * n_cx + dx)  # sorted too: a fast search
                lo = np.searchsorted(sorted_key, target, side="left")
                hi = np.searchsorted(sorted_key, target, side="right")
                count = hi - lo
                if not count.any():
                    continue
                first = np.repeat(order, count)
                offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
                second = order[np.repeat(lo, count) + offset]
                a, b = idx[first], idx[second]
                close = (np.abs(x[a] - x[b]) < reach) & (np.abs(y[a] - y[b]) < reach)
                found.append(np.stack([pairs.obs_track[a[close]], pairs.obs_track[b[close]]], 1))
    if not found:
        return np.empty((0, 2), dtype=np.int64)
    both = np.concatenate(found).astype(np.int64)
    both = both[both[:, 0] < both[:, 1]]  # each unordered pair once, a track never with itself
    code = np.unique(both[:, 0] * np.int64(pairs.n_tracks) + both[:, 1])
    return np.stack([code // pairs.n_tracks, code % pairs.n_tracks], axis=1)


def _parameter_covariance(fun: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """``σ² (JᵀJ)⁺`` with ``σ² = Σ r² / (n − P)``: the first-order covariance of all parameters.

    With view gains the model block of it is the covariance *marginal* over
    the gains (their correlation with the map is accounted for).
    """
    dof = max(fun.size - jac.shape[1], 1)
    return float(fun @ fun) / dof * np.linalg.pinv(jac.T @ jac, rcond=1e-12)


@dataclass(frozen=True)
class _ChannelFit:
    """One channel's fitted parameters, residual RMS and whether it can be trusted.

    ``note`` says why not (``None`` when it can). ``uncertainty`` (the map's
    mean relative uncertainty) and ``covariance`` (of the six parameters,
    clustered by track) are stated only when the solver converged; ``gains``
    and ``gain_std`` only when the view gains were fitted with the model, one
    per view with observations (the reference first).
    """

    params: np.ndarray
    rms: float
    converged: bool
    note: str | None
    uncertainty: float = float("nan")
    covariance: np.ndarray | None = None
    gains: np.ndarray | None = None
    gain_std: np.ndarray | None = None
    response_covariance: np.ndarray | None = None


def _why_untrusted(
    ch: int,
    p: np.ndarray,
    uncertainty: float,
    image_shape: tuple[int, int],
    max_uncertainty: float,
) -> str | None:
    """Why channel ``ch``'s converged parameters ``p`` cannot be trusted, or ``None``.

    The fitted ``v`` must be positive over the image, must not have collapsed
    towards 0, must not span more than :data:`MAX_FALLOFF`, and the map's
    uncertainty must not exceed ``max_uncertainty``.
    """
    v_min, v_max = _range_over_image(p[:_N_PARAMS], image_shape)
    if not v_min > 0:
        return (
            f"channel {ch}: fitted vignetting is not positive over the image "
            f"(minimum {v_min:.3g}); it cannot be used for correction"
        )
    if v_max < 0.5:
        return (
            f"channel {ch}: fitted vignetting is below 0.5 everywhere in the image "
            f"(maximum {v_max:.3g}, centre ({p[4]:.3g}, {p[5]:.3g})): "
            "the fit has collapsed towards v = 0"
        )
    if v_max > MAX_FALLOFF * v_min:
        return (
            f"channel {ch}: fitted vignetting spans a factor {v_max / v_min:.3g} over "
            f"the image (more than {MAX_FALLOFF:g}): the polynomial diverged, no lens "
            "falls off so (check the response and the correspondences)"
        )
    if not uncertainty <= max_uncertainty:
        return (
            f"channel {ch}: the views constrain the model poorly (map uncertainty "
            f"{uncertainty:.1%} > {max_uncertainty:.1%}); spread the view "
            "directions in both axes (pan and tilt) and use more points"
        )
    return None


def _fit_channel(
    pairs: _PairedObservations,
    c: np.ndarray,
    ch: int,
    settings: _FitSettings,
    p0: np.ndarray | None,
    gain_index: np.ndarray,
    n_gains: int,
    image_shape: tuple[int, int],
    neighbours: np.ndarray,
    loadings: np.ndarray | None = None,
) -> _ChannelFit:
    """The fit of channel ``ch`` (values ``c``) from ``p0``, or from the linear start.

    With ``n_gains`` the free view gains are fitted with the model (with the
    prior ``settings.view_gain_sigma``); the stated covariance is clustered by
    track, as a track's pairs share its values, with the tracks ``neighbours``
    (pairs of track labels whose sampling windows share pixels) correlated.
    """
    problem = _pair_problem(pairs, c, settings, gain_index, n_gains)
    result, fun, cov = _solve_pairs(
        problem.residuals,
        problem.jacobian,
        p0 if p0 is not None else problem.linear_start(),
        _N_PARAMS,
        settings.max_nfev,
        settings.view_gain_sigma if n_gains else None,
    )
    gains: np.ndarray | None = None
    gain_std: np.ndarray | None = None
    if n_gains:
        gains = np.r_[1.0, result.x[_N_PARAMS:]]
        gain_std = np.r_[0.0, np.sqrt(np.maximum(np.diag(cov)[_N_PARAMS:], 0.0))]
    params = result.x[:_N_PARAMS]
    rms = float(np.sqrt(np.mean(fun**2)))
    if not (bool(result.success) and bool(np.all(np.isfinite(result.x)))):
        reason = f"channel {ch}: did not converge ({result.message})"
        return _ChannelFit(
            params, rms, converged=False, note=reason, gains=gains, gain_std=gain_std
        )
    covariance = _track_clustered_covariance(result.jac, fun, pairs.pair_track, neighbours)
    uncertainty = _map_uncertainty(result.x, fun, result.jac, image_shape, cov)
    note = _why_untrusted(ch, result.x, uncertainty, image_shape, settings.max_uncertainty)
    inherited = None
    if loadings is not None:  # the response's error, carried through the values
        shift = _response_shift(problem, pairs, c, settings, result.x, loadings)
        inherited = (shift.T @ shift)[:_N_PARAMS, :_N_PARAMS]
    return _ChannelFit(
        params,
        rms,
        converged=note is None,
        note=note,
        uncertainty=uncertainty,
        covariance=covariance[:_N_PARAMS, :_N_PARAMS],
        gains=gains,
        gain_std=gain_std,
        response_covariance=inherited,
    )


def _response_shift(
    problem: _PairProblem,
    pairs: _PairedObservations,
    c: np.ndarray,
    settings: _FitSettings,
    x: np.ndarray,
    loadings: np.ndarray,
    columns: np.ndarray | None = None,
) -> np.ndarray:
    """``(R, n_params)``: how the solution moves per unit of each of the response's error
    variates, which move the observations' ``ln c`` by ``loadings`` ``(n_obs, R)``
    (``columns``: the parameters solved for, of the problem's; all by default).

    To first order the least-squares solution moves by ``δx = −J⁺ δr``, ``δr``
    the residuals' change at the solution when the values move: with
    ``c → c (1 + δ)``, ``δu = w (ρ c_a δ_a v_b − c_b δ_b v_a / ρ) / s − u δw/w``,
    and for ``normalise="track"`` ``δw/w`` is the move of the track's mean
    value, ``Σ c δ / Σ c`` over its observations (tested against refits of
    moved values). ``Σ_r δx_r δx_rᵀ`` is the parameters' covariance inherited
    from the response (GUM §5.1.2).
    """
    carried = np.all(np.isfinite(loadings), axis=1)
    use = carried[problem.a] & carried[problem.b]  # the pairs of the tracks that carry it
    loadings = np.where(carried[:, None], loadings, 0.0)
    a, b = problem.a[use], problem.b[use]
    v = _evaluate(problem.x_n, problem.y_n, x[:_N_PARAMS])
    rho, _ = problem._ratio(x)
    scale = float(np.sqrt(np.mean(v**2))) if problem.scale_invariant else 1.0
    rho_col = np.broadcast_to(np.asarray(rho, dtype=np.float64).reshape(-1, 1), (use.size, 1))
    weight = problem.weight[use]
    term_a = (weight * problem.c_a[use] * v[b])[:, None] * rho_col[use]
    term_b = (weight * problem.c_b[use] * v[a])[:, None] / rho_col[use]
    moved = (term_a * loadings[a] - term_b * loadings[b]) / scale
    if settings.normalise == "track":
        track_sum = np.bincount(pairs.obs_track, weights=c, minlength=pairs.n_tracks)
        relative = (
            np.stack(
                [
                    np.bincount(
                        pairs.obs_track, weights=c * loadings[:, r], minlength=pairs.n_tracks
                    )
                    for r in range(loadings.shape[1])
                ],
                axis=1,
            )
            / track_sum[:, None]
        )
        moved -= problem.residuals(x)[use][:, None] * relative[pairs.pair_track[use]]
    jac = problem.jacobian(x)[use]
    jac = jac if columns is None else jac[:, columns]
    # the normal equations' pseudo-inverse, as the fit's covariance takes it (a direction
    # the data leave free moves nothing): a 6×6 system, not an SVD of the pairs
    step = np.linalg.pinv(jac.T @ jac) @ (jac.T @ moved)
    return -step.T


@dataclass(frozen=True)
class _ChannelFits:
    """The fits of all channels, as the arrays of :class:`VignettingFit`, and their notes."""

    params: np.ndarray  # (C, 6)
    rms: np.ndarray  # (C,)
    converged: np.ndarray  # (C,) bool
    uncertainty: np.ndarray  # (C,), NaN where the solver failed
    param_covariance: np.ndarray  # (C, 6, 6), NaN where the solver failed
    response_covariance: np.ndarray | None  # (C, 6, 6): the part inherited from loadings
    gains: np.ndarray | None  # (C, V) with view gains, NaN for a view without observations
    gain_std: np.ndarray | None
    notes: tuple[str, ...]  # why a channel cannot be trusted, channel by channel


def _fit_channels(
    pairs: _PairedObservations,
    settings: _FitSettings,
    start: np.ndarray | None,
    image_shape: tuple[int, int],
    n_view_slots: int,
    loadings: np.ndarray | None = None,
) -> _ChannelFits:
    """Every channel's fit, and with ``settings.view_gains`` every view's gain.

    With ``view_gain_centre="image"`` the gains are fitted first with the
    centre held at the image centre (no ramp to trade for them), their
    geometric mean over the channels is applied to the values, and the model
    is fitted with them held; with ``"free"`` each channel fits its own gains
    with the model. ``n_view_slots`` is the number of columns of the gains.
    """
    n_channels = pairs.values.shape[1]
    params = np.empty((n_channels, _N_PARAMS))
    rms = np.empty(n_channels)
    uncertainty = np.full(n_channels, np.nan)
    param_cov = np.full((n_channels, _N_PARAMS, _N_PARAMS), np.nan)
    inherited = None if loadings is None else np.full_like(param_cov, np.nan)
    converged = np.zeros(n_channels, dtype=bool)
    notes: list[str] = []
    present, gain_index = _view_labels(pairs.obs_view)
    neighbours = _overlapping_tracks(pairs, image_shape, settings.sample_radius)
    n_gains = int(present.size - 1) if settings.view_gains else 0
    gains = np.full((n_channels, n_view_slots), np.nan)
    gain_std = np.full((n_channels, n_view_slots), np.nan)
    values = pairs.values
    if n_gains and settings.view_gain_centre == "image":
        moves: list[np.ndarray] = []
        for ch in range(n_channels):
            gains[ch, present], gain_std[ch, present], moved = _centred_gains(
                pairs,
                values[:, ch],
                settings,
                gain_index,
                n_gains,
                None if loadings is None else loadings[pairs.source, ch],
            )
            if moved is not None:
                moves.append(moved)
        common = np.exp(np.mean(np.log(gains[:, present]), axis=0))
        values = values * common[gain_index][:, None]
        if loadings is not None:  # the common gains move with the values, and the values
            common_move = np.mean(moves, axis=0)[gain_index]  # (n_obs, R)
            loadings = loadings.copy()
            loadings[pairs.source] += common_move[:, None, :]
        n_gains = 0
    for ch in range(n_channels):
        p0 = start[ch] if start is not None else None
        fit = _fit_channel(
            pairs,
            values[:, ch],
            ch,
            settings,
            p0,
            gain_index,
            n_gains,
            image_shape,
            neighbours,
            None if loadings is None else loadings[pairs.source, ch],
        )
        params[ch], rms[ch], converged[ch] = fit.params, fit.rms, fit.converged
        if fit.gains is not None:
            gains[ch, present], gain_std[ch, present] = fit.gains, fit.gain_std
        if fit.covariance is not None:
            param_cov[ch], uncertainty[ch] = fit.covariance, fit.uncertainty
            if inherited is not None and fit.response_covariance is not None:
                inherited[ch] = fit.response_covariance
                param_cov[ch] = param_cov[ch] + fit.response_covariance
        if fit.note is not None:
            notes.append(fit.note)
    return _ChannelFits(
        params=params,
        rms=rms,
        converged=converged,
        uncertainty=uncertainty,
        param_covariance=param_cov,
        response_covariance=inherited,
        gains=gains if settings.view_gains else None,
        gain_std=gain_std if settings.view_gains else None,
        notes=tuple(notes),
    )


def _fit_message(pairs: _PairedObservations, settings: _FitSettings, fits: _ChannelFits) -> str:
    """The fit's summary: counts, options, dropped observations, map uncertainties, notes."""
    status = "converged" if fits.converged.all() else "NOT TRUSTWORTHY"
    message = (
        f"{status}: extended Goldman-Chen fit of {fits.params.shape[0]} channel(s) from "
        f"{pairs.n_tracks} tracks, {pairs.n_pairs} pairs, {pairs.n_observations} observations "
        f"in {pairs.n_views} views (normalise={settings.normalise!r}, "
        f"scale_invariant={settings.scale_invariant}"
        f"{', view gains' if settings.view_gains else ''}); {pairs.dropped_note}; "
        "relative map uncertainty (1 sigma, image mean) "
        + ", ".join("n/a" if np.isnan(u) else f"{u:.2%}" for u in fits.uncertainty)
    )
    if fits.notes:
        message += "; " + "; ".join(fits.notes)
    return message


def fit_vignetting_ExtendedGoldmanChen(
    values: Any,
    xy: Any,
    view: Any,
    track: Any,
    image_shape: tuple[int, int],
    *,
    initial: Any = None,
    normalise: Literal["track", "none"] = "track",
    scale_invariant: bool = True,
    min_pairs: int = 30,
    min_spread: float = 0.25,
    max_uncertainty: float = 0.02,
    max_nfev: int = 2000,
    view_gains: bool = False,
    view_gain_sigma: float | None = None,
    view_gain_centre: Literal["image", "free"] = "image",
    sample_radius: int = 0,
    value_log_loadings: Any = None,
) -> VignettingFit:
    """Fit the extended Goldman–Chen vignetting model to values seen from several views.

    Parameters
    ----------
    values : array_like, shape (M, C)
        Linearised, colour-balanced, sensor-uniformised values ``c`` at the
        ``M`` observations (any positive linear unit).
    xy : array_like, shape (M, 2)
        Pixel coordinates ``(x, y)`` of each observation in its view, on the
        convention of :func:`normalised_coordinates` (integer values are pixel
        centres; ``-0.5 <= x <= W - 0.5``).
    view : array_like of int, shape (M,)
        View (camera direction) of each observation.
    track : array_like of int, shape (M,)
        Scene-point id of each observation: observations with the same id are
        the same point seen in different views. A track must not list a view
        twice.
    image_shape : tuple of int
        ``(H, W)`` of the views.
    initial : array_like, shape (6,) or (C, 6), optional
        Starting parameters. By default each channel starts from the linear
        least-squares solution for ``m1..m3`` at ``m4 = 1``, ``m5 = m6 = 0.5``
        (see Notes).
    normalise : {"track", "none"}
        Weight of each residual. ``"none"``: the residual of [PQ]_,
        ``c_is v_js − c_js v_is``, in value units. ``"track"`` (default): that
        residual divided by the mean value of its track in the channel — the
        same equation, weighted so that bright points do not dominate and the
        residuals are relative (dimensionless). Both vanish at the true
        parameters for noise-free data.
    scale_invariant : bool
        Divide every residual by the RMS of ``v`` over the observations (default).
        This common, parameter-dependent factor keeps the zero set of the
        equations but stops the fit from shrinking the residuals by shrinking
        ``v`` (see Notes). ``normalise="none", scale_invariant=False`` is the
        objective of [PQ]_ exactly.
    min_pairs : int
        Fewest usable pairs of observations accepted.
    min_spread : float
        Fewest fraction of the image width and of the image height that the
        usable observations must span (between their 5th and 95th
        percentiles): points bunched in one spot cannot constrain a model of
        the whole image.
    max_uncertainty : float
        Largest accepted first-order relative standard uncertainty of the
        fitted map, averaged over the image (``VignettingFit.map_uncertainty``);
        a larger one marks the channel as not trustworthy.
    max_nfev : int
        Most evaluations of the residuals per channel.
    view_gains : bool
        Give every view but the reference (the lowest-numbered one) a free
        gain ``a_j``, fitted per channel with the model: the residual becomes
        ``a_i c_is v_js − a_j c_js v_is`` (normalised as above). It absorbs an
        error of each view's exposure scale (see Notes), reported in
        ``VignettingFit.view_gains``.
    view_gain_sigma : float, optional
        With ``view_gains``: the prior standard deviation of each gain about 1
        (how well the views' exposure scales are known beforehand), a
        Gaussian prior added to the least squares; ``None``: free gains.
    view_gain_centre : {"image", "free"}
        How the gains are told from the vignetting (see Notes). ``"image"``
        (default): the gains are fitted with the model's centre held at the
        image centre (``m5 = m6 = 0.5``), one gain per view is taken for all
        channels (their geometric mean: an exposure error is common to the
        channels), and the full model is then fitted to the values so
        corrected. ``"free"``: gains and model jointly, per channel.
    sample_radius : int
        Half-size ``r`` of the windows the values were averaged over
        (:func:`photoquant.correspondences.sample_image`; 0: single samples).
        Tracks whose windows share pixels in a view have correlated errors:
        the stated covariance counts them (see Notes).
    value_log_loadings : array_like, shape (M, C, R), optional
        How ``R`` independent standard variates of an error common to the
        observations (the response's, through the merge:
        :func:`photoquant.merge.uncertainty.response_loadings_Debevec1997`)
        move each observation's ``ln c``: the parameters' covariance gains
        ``Σ_r δp_r δp_rᵀ``, ``δp_r`` the solution's first-order move per
        unit of variate ``r``, from the pairs whose two observations both
        have finite loadings (NaN rows: a subset of whole tracks carries
        it, see :data:`RESPONSE_ERROR_TRACKS`). The map's trust
        (``max_uncertainty``) is judged on the fit's own statistical error.

    Returns
    -------
    VignettingFit
        ``converged`` is ``False`` for a channel whose solver stopped without
        meeting its tolerances, whose fitted ``v`` is not positive over the
        whole image, whose ``v`` stays below 0.5 over the whole image (a
        collapse, see Notes), or whose map uncertainty exceeds
        ``max_uncertainty``; ``message`` says which and why.

    Raises
    ------
    InputError
        Malformed arguments (the message names the argument).
    CalibrationError
        Fewer than ``min_pairs`` usable pairs, fewer than two views with usable
        observations, or observations that do not spread over the image.

    Notes
    -----
    Observations whose values are non-finite or non-positive in any channel
    are dropped (the count is reported in ``message``); tracks with fewer than
    two remaining observations contribute nothing. Every pair ``i < j`` of
    views within each track gives one residual per channel: a point seen in
    all ``V`` views gives ``V (V − 1) / 2`` pairs.

    The residual is linear in ``m1..m3`` for fixed ``m4..m6``, so the starting
    point is the linear least-squares solution at ``m4 = 1, m5 = m6 = 0.5``.
    Starting from ``m1 = m2 = m3 = 0`` would stall: there ``∂v/∂R = 0`` and the
    Jacobian with respect to ``m4..m6`` vanishes. The non-linear problem is
    then solved by MINPACK's Levenberg–Marquardt [Mor78]_
    (``scipy.optimize.least_squares(method="lm")``) with an analytic Jacobian.

    The residuals of [PQ]_ are proportional to ``v``, and the model can make
    ``v`` arbitrarily small over the image: with the centre ``(m5, m6)`` far
    outside and a root of the cubic near the resulting ``R``, ``v ≈ α q(x, y)``
    with ``α → 0``. With noisy data the unnormalised objective therefore has
    its infimum (zero) there, not at the truth, and Levenberg–Marquardt can
    slide into it when the views constrain the model weakly (e.g. a pure pan
    with 0.5 % noise). Dividing by ``sqrt(mean(v²))`` makes the objective
    invariant to a common scale of ``v`` and removes that reward. A collapsed
    fit is flagged either way.

    Views displaced along one axis only constrain the profile along the other
    axis only through the model's non-separability: with a pure pan, the
    vertical fall-off of a mild vignette is nearly free (in a simulation with
    0.5 % noise, 400 points and three views 10 % apart, a pure pan gave map
    errors of 1–47 % and a pan plus a tilt 0.04–0.4 %). ``map_uncertainty``
    reports the resulting first-order uncertainty, and ``max_uncertainty``
    flags it: pan *and* tilt the camera.

    *View gains.* The views are merged from their own exposure brackets, and
    a bracket's exposure scale is known only as well as its shutter: nominal
    times off by a few percent, or times re-estimated from the data
    (:mod:`photoquant.exposure`), which fix each bracket's scale only up to
    its own gauge (about ``σ/√K`` of its jitter, different per view). A view
    whose exposure is off by a factor ``e_j`` has values ``e_j v l``, and the
    pair equations read ``e_i v_is − e_j v_js`` ∝ a vignetting ratio times a
    view ratio, which a model without gains can only explain as vignetting
    (a 1 % gauge difference gave a 4.7 % map error). This is the joint
    exposure and vignetting estimation of Goldman & Chen [GC05]_ (their
    per-image exposure ``t_j`` beside the vignetting). The two are
    identifiable: a view gain is one constant factor over the whole view,
    whereas the vignetting ratio ``v(x_is) / v(x_js)`` of a track varies with
    where the point lies in the two views, and the model is normalised to
    ``v = 1`` at its centre. With two or more views and tracks spread over
    the image (pan *and* tilt), every track gives a different vignetting
    ratio but the same gain ratio, so both are determined — up to one
    exact ambiguity: for views related by shifts ``d_j``, ``v → v·exp(a·x)``,
    ``l → l·exp(−a·X)``, ``a_j → a_j·exp(−a·d_j)`` leaves every value
    unchanged. Only the model's form can exclude the ramp ``exp(a·x)``; a
    centred model (``"Goldman-Chen 2005"``) does, but this model's free
    centre ``(m5, m6)`` reproduces it to second order in ``R`` (moving the
    centre by ``δ`` adds ``−2 m1 m4 δ·x``), so for a mild, nearly quadratic
    vignette only the small ``m2, m3`` terms hold the gains, and a fit with
    pqsim's CCD vignetting (``m1 = −0.35``) and 0.5 % noise is refused as
    poorly constrained (map uncertainty ≈ 6 %), while the paper's fitted
    vignetting (§6.3) gives gains to 0.1 % and its map to 0.3 %.
    ``map_uncertainty`` (marginal over the gains) reports how much freedom
    is left; ``view_gain_sigma`` adds what is known of the gains beforehand
    as a Gaussian prior. ``view_gain_centre="image"`` (default) resolves the
    ambiguity by the physics of a lens instead: its vignetting is centred
    on the optical axis, near the image centre, so the gains are those that
    a vignetting centred there needs; a true centre off by ``δ`` biases them
    by about ``2 |m1| m4 δ·d_j`` (0.3–0.5 % for pqsim's CCD preset, centre
    2–3 % off, views 25 % apart: a map error of 0.5 % where 3 % exposure
    jitter gave 9 %), and the full model, fitted with those gains held, is
    free to put its centre where the data say. Its ``map_uncertainty`` is
    then conditional on the gains. The residual is divided by ``√(a_i a_j)`` so that
    it is invariant to a common scale of the gains. A gain common to every
    view, the scale of ``l``, stays undetermined as before (view 0's is
    fixed).

    References
    ----------
    .. [PQ] The photoquantity paper, §5.5 "Vignetting".
    .. [GC05] D. B. Goldman and J.-H. Chen, "Vignette and exposure calibration
       and compensation", ICCV 2005. doi:10.1109/ICCV.2005.249
    .. [Mor78] J. J. Moré, "The Levenberg–Marquardt algorithm: implementation
       and theory", Lecture Notes in Mathematics 630, 1978.
       doi:10.1007/BFb0067700
    """
    values, xy, view, track, shape = _checked_observations(values, xy, view, track, image_shape)
    settings = _FitSettings.checked(
        normalise=normalise,
        scale_invariant=scale_invariant,
        view_gains=view_gains,
        view_gain_centre=view_gain_centre,
        view_gain_sigma=view_gain_sigma,
        min_pairs=min_pairs,
        max_nfev=max_nfev,
        min_spread=min_spread,
        max_uncertainty=max_uncertainty,
        sample_radius=sample_radius,
    )
    _check_positions(xy, view, shape)
    start = _starting_parameters(initial, values.shape[1], settings.view_gains)
    loadings = None
    if value_log_loadings is not None:
        loadings = check_array(value_log_loadings, "value_log_loadings", ndim=3, kind="f")
        if loadings.shape[:2] != values.shape or np.any(np.isinf(loadings)):
            raise InputError(
                f"`value_log_loadings` must be (M, C, R) with (M, C) = {values.shape}, finite "
                f"or NaN, got shape {loadings.shape}"
            )
    pairs = _paired_observations(values, xy, view, _track_index(track, view), shape)
    _check_pairs_suffice(pairs, settings.min_pairs, settings.min_spread)
    fits = _fit_channels(
        pairs, settings, start, shape, n_view_slots=int(view.max()) + 1, loadings=loadings
    )
    return VignettingFit(
        params=fits.params,
        residual_rms=fits.rms,
        n_tracks=pairs.n_tracks,
        n_pairs=pairs.n_pairs,
        n_observations=pairs.n_observations,
        converged=fits.converged,
        message=_fit_message(pairs, settings, fits),
        map_uncertainty=fits.uncertainty,
        view_gains=fits.gains,
        view_gain_std=fits.gain_std,
        param_covariance=fits.param_covariance,
        param_response_covariance=fits.response_covariance,
    )


# ---------------------------------------------------------------------------
# The "vignetting" step: models, data, methods
# ---------------------------------------------------------------------------


def _checked_covariance(value: Any, name: str, n_channels: int) -> np.ndarray:
    """A ``(C, 6, 6)`` covariance of the model's parameters, finite with non-negative
    variances, made exactly symmetric (float64)."""
    cov = check_array(
        value,
        f"vignetting {name}",
        shape=(n_channels, _N_PARAMS, _N_PARAMS),
        kind="iuf",
        finite=True,
    ).astype(np.float64)
    if np.any(np.diagonal(cov, axis1=1, axis2=2) < 0):
        raise InputError(f"vignetting `{name}` must have non-negative variances")
    return 0.5 * (cov + cov.transpose(0, 2, 1))


@dataclass(frozen=True, eq=False)
class ExtendedGoldmanChenVignetting(VignettingModel):
    """The paper's extended Goldman–Chen model (§5.5): ``m1 … m6`` per channel.

    Parameters
    ----------
    method : str
        The method that fitted it.
    params : ndarray, shape (C, 6)
        ``(m1, m2, m3, m4, m5, m6)`` per channel on normalised coordinates
        (see :func:`vignetting_ExtendedGoldmanChen`).
    param_covariance : ndarray, shape (C, 6, 6), optional
        The fit's first-order covariance of ``params`` (``σ² (JᵀJ)⁺`` of the
        Levenberg–Marquardt solution, marginal over the view gains), for the
        map's uncertainty (:meth:`log_map_variance`). ``None``: not stated.
    param_response_covariance : ndarray, shape (C, 6, 6), optional
        The part of ``param_covariance`` the map inherited from the response's
        error (``response_error="propagated"``); ``None``: none stated.
    """

    method: str
    params: np.ndarray
    param_covariance: np.ndarray | None = None
    param_response_covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        p = check_array(self.params, "vignetting params", ndim=2, kind="iuf", finite=True)
        if p.shape[1] != _N_PARAMS:
            raise InputError(
                f"the extended Goldman-Chen model has {_N_PARAMS} parameters per channel "
                f"({', '.join(VIGNETTING_PARAMETER_NAMES)}), got shape {p.shape}"
            )
        object.__setattr__(self, "params", p.astype(np.float64))
        if self.param_response_covariance is not None and self.param_covariance is None:
            raise InputError(
                "vignetting `param_response_covariance` is a part of `param_covariance`, "
                "which is not given"
            )
        for name in ("param_covariance", "param_response_covariance"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _checked_covariance(value, name, p.shape[0]))

    def excluding_response_error(self) -> ExtendedGoldmanChenVignetting:
        """The model with the covariance it inherited from the response taken out
        (:meth:`VignettingModel.excluding_response_error`)."""
        if self.param_response_covariance is None or self.param_covariance is None:
            return self
        return dataclasses.replace(
            self,
            param_covariance=self.param_covariance - self.param_response_covariance,
            param_response_covariance=None,
        )

    @classmethod
    def identity(cls, n_channels: int) -> ExtendedGoldmanChenVignetting:
        """``v ≡ 1`` in this model's parameters (``m1 = m2 = m3 = 0``)."""
        return cls("Extended Goldman-Chen", np.tile(IDENTITY_VIGNETTING, (n_channels, 1)))

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        return vignetting_map(self.params, image_shape)

    def log_map_variance(
        self, image_shape: tuple[int, int], relative_to: tuple[float, float] | None = None
    ) -> np.ndarray | None:
        """``Var(ln v) = gᵀ Cov(p) g`` at every pixel centre, ``g = ∂ln v/∂p`` (first
        order, the law of propagation of uncertainty, GUM §5.1.2); ``None`` without a
        covariance. ``relative_to`` (a point ``(x, y)`` in pixels, e.g. the white
        chart's centre): ``g = ∂(ln v − ln v(x, y))/∂p``, the map's error less its
        error there (zero at the point)."""
        if self.param_covariance is None:
            return None
        h, w = _check_image_shape(image_shape)
        at = _normalised_point(relative_to, h, w)
        n_ch = self.params.shape[0]
        out = np.empty((h, w, n_ch))
        flat = out.reshape(h * w, n_ch)
        gradients = [None if at is None else _log_gradient_at(at, p) for p in self.params]
        # in bands of rows whose Jacobian (6 rows of a band's pixels) stays in the CPU's
        # cache: each pixel's variance is computed from that pixel alone, so the bands give
        # the values of the whole image at once (tests: bands of every size)
        rows_per_band = max(1, _MAP_BAND_PIXELS // w)
        for y0 in range(0, h, rows_per_band):
            y1 = min(h, y0 + rows_per_band)
            x_n, y_n = _pixel_centres(h, w, y0, y1)
            for ch, (p, cov) in enumerate(zip(self.params, self.param_covariance, strict=True)):
                flat[y0 * w : y1 * w, ch] = _log_variance_rows(x_n, y_n, p, cov, gradients[ch])
        return out

    def log_mean_variance(
        self,
        image_shape: tuple[int, int],
        weights: np.ndarray,
        relative_to: tuple[float, float] | None = None,
    ) -> np.ndarray | None:
        """``ḡᵀ Cov(p) ḡ`` per channel, ``ḡ`` the weighted mean over the pixel centres of
        ``∂ln v/∂p`` (less its value at ``relative_to``): the variance of a region's
        mean of ``ln v`` (first order); ``None`` without a covariance."""
        if self.param_covariance is None:
            return None
        h, w = _check_image_shape(image_shape)
        n_ch = self.params.shape[0]
        wts = np.asarray(weights, dtype=np.float64)
        if wts.shape != (h, w, n_ch) or not np.all(np.isfinite(wts)) or np.any(wts < 0):
            raise InputError(
                f"`weights` must be finite non-negative ({h}, {w}, {n_ch}), got shape {wts.shape}"
            )
        x_n, y_n = _pixel_centres(h, w)
        at = _normalised_point(relative_to, h, w)
        out = np.full(n_ch, np.nan)
        for ch, (p, cov) in enumerate(zip(self.params, self.param_covariance, strict=True)):
            total = float(wts[..., ch].sum())
            if total <= 0:
                continue
            v, rows = _model_and_jacobian_rows(x_n, y_n, p)
            mean = (rows / v) @ wts[..., ch].ravel() / total
            if at is not None:
                mean = mean - _log_gradient_at(at, p)
            out[ch] = max(float(mean @ cov @ mean), 0.0)
        return out

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        extra: dict[str, Any] = {}
        if self.param_covariance is not None:
            extra["param_covariance"] = self.param_covariance.tolist()
        if self.param_response_covariance is not None:
            extra["param_response_covariance"] = self.param_response_covariance.tolist()
        return (
            {
                "model": "Extended Goldman-Chen",
                "parameter_names": list(VIGNETTING_PARAMETER_NAMES),
                "coordinates": "x_n = (x + 0.5) / W, y_n = (y + 0.5) / H",
                "params": self.params.tolist(),
                **extra,
            },
            {},
        )

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> ExtendedGoldmanChenVignetting:
        del images
        values = params["params"]
        if not isinstance(values, list):
            raise InputError(f"vignetting `params` must be a list of lists, got {values!r}")
        covariances = []
        for key in ("param_covariance", "param_response_covariance"):
            listed = params.get(key)
            if listed is not None and not isinstance(listed, list):
                raise InputError(f"vignetting `{key}` must be a list, got {listed!r}")
            covariances.append(listed)
        try:
            arr = np.asarray(values, dtype=np.float64)
            cov, inherited = (
                None if c is None else np.asarray(c, dtype=np.float64) for c in covariances
            )
        except (TypeError, ValueError):
            raise InputError("vignetting `params` must be numbers (C rows of 6)") from None
        return cls(method, arr, cov, inherited)


@dataclass(frozen=True)
class ExtendedGoldmanChenOptions:
    """Options of the ``"Extended Goldman-Chen"`` vignetting fit (§5.5).

    Attributes
    ----------
    normalise : {"track", "none"}
        Residuals divided by their track's mean (default) or in value units
        (the paper's).
    scale_invariant : bool
        Divide the residuals by the RMS of ``v`` (default): the gauge fix that
        stops the fit from shrinking ``v`` towards 0; the paper's objective
        taken literally has no such fix.
    sample_radius : int
        Half-size of the window averaged at each correspondence.
    max_tracks : int, optional
        At most this many tracks are used, evenly spread over the given list
        (every ``n/max_tracks``-th; ``None``: all). Six parameters per
        channel need thousands of tracks, not 10⁵: at the paper's settings
        (1024×768, 97 798 tracks) the map error is held by systematic errors
        (the LUT's, the response's), ten times its statistical uncertainty
        with every track, and 30 000 tracks change it by a few percent of
        itself while the step runs 3× faster (README, vignetting).
    min_pairs, min_spread, max_uncertainty, max_nfev
        See :func:`fit_vignetting_ExtendedGoldmanChen`.
    view_gains : bool or "auto"
        A gain per view: each view's exposure-scale error is fitted beside
        the vignetting and reported (``view_gains``, ``view_gain_std`` and
        ``exposure_correction`` in the step's report) instead of being read
        as vignetting (:func:`fit_vignetting_ExtendedGoldmanChen`, Notes).
        ``"auto"`` (default; the paper's profile sets ``False``): when the
        views' exposure scales are uncertain by more than
        :data:`~photoquant.vignetting.base.AUTO_VIEW_GAIN_STD` (their
        refinement says so, ``VignettingData.exposure_scale_std``); exact
        or unknown exposures keep the fit without gains, which the gains'
        centre assumption would bias by 0.3–0.5 %.
    view_gain_sigma : float, optional
        With ``view_gains``: the prior standard deviation of each gain about
        1 (how well the views' exposure scales are known beforehand);
        ``None`` (default): free gains.
    view_gain_centre : {"image", "free"}
        With ``view_gains``: the gains fitted with the centre held at the
        image centre, then held in the full fit (default), or jointly.
    response_error : {"propagated", "ignored"}
        Where the data carry the response's error
        (:attr:`~photoquant.vignetting.VignettingData.response_loadings`):
        carry it through the fit into the parameters' covariance (default;
        ``value_log_loadings`` of :func:`fit_vignetting_ExtendedGoldmanChen`),
        or state the fit's own statistical error only. The views the map is
        fitted to are merged with the recovered ``g``, whose error moves
        their values level by level: the map inherits it.
    uncorrected_bias : {"ignored", "stated"}
        With ``"stated"`` (the paper's profile) and options that depart from
        these defaults, the same data are also fitted with the defaults and
        the parameters' difference ``δm`` is added to their covariance as
        ``δm δmᵀ``: the parameters are kept, the map's stated uncertainty
        covers the bias the chosen options leave (the RSSu treatment of an
        uncorrected bias, :mod:`photoquant.response.covariance`). Costs one
        more fit; the report gives the bias's RMS over the map per channel.
    """

    normalise: str = "track"
    scale_invariant: bool = True
    sample_radius: int = 1
    max_tracks: int | None = 30_000
    min_pairs: int = 30
    min_spread: float = 0.25
    max_uncertainty: float = 0.02
    max_nfev: int = 2000
    view_gains: bool | str = "auto"
    view_gain_sigma: float | None = None
    view_gain_centre: str = "image"
    response_error: str = "propagated"
    uncorrected_bias: str = "ignored"

    def __post_init__(self) -> None:
        check_choice(self.response_error, "response_error", ("propagated", "ignored"))
        check_choice(self.uncorrected_bias, "uncorrected_bias", UNCORRECTED_BIAS_MODES)
        if self.normalise not in ("track", "none"):
            raise InputError(f"`normalise` must be 'track' or 'none', got {self.normalise!r}")
        if not isinstance(self.scale_invariant, bool):
            raise InputError(
                f"`scale_invariant` must be true or false, got {self.scale_invariant!r}"
            )
        check_view_gains_option(self.view_gains)
        if self.view_gain_sigma is not None:
            check_positive(self.view_gain_sigma, "view_gain_sigma")
        if self.view_gain_centre not in ("image", "free"):
            raise InputError(
                f"`view_gain_centre` must be 'image' or 'free', got {self.view_gain_centre!r}"
            )
        check_int(self.sample_radius, "sample_radius", 0, 64)
        if self.max_tracks is not None:
            check_int(self.max_tracks, "max_tracks", 2)
        check_int(self.min_pairs, "min_pairs", 1)
        check_int(self.max_nfev, "max_nfev", 1)
        for name in ("min_spread", "max_uncertainty"):
            check_positive(getattr(self, name), name, allow_zero=True)


def view_gain_report(gains: np.ndarray | None, std: np.ndarray | None) -> dict[str, Any]:
    """The view gains of a fit as a step report's entries (nothing without gains).

    ``view_gains`` and ``view_gain_std`` per channel and view (``None`` for a
    view without observations); ``exposure_correction``, per view, the
    geometric mean of its gains over the channels: one view's exposure error
    is common to its channels, so ``t_j / exposure_correction_j`` puts view
    ``j`` on the reference view's exposure scale.
    """
    if gains is None:
        return {}

    def listed(arr: np.ndarray) -> list[list[float | None]]:
        return [[float(v) if np.isfinite(v) else None for v in row] for row in arr]

    with np.errstate(invalid="ignore"):
        common = np.exp(np.mean(np.log(gains), axis=0))
    return {
        "view_gains": listed(gains),
        "view_gain_std": listed(std if std is not None else np.full_like(gains, np.nan)),
        "exposure_correction": [float(v) if np.isfinite(v) else None for v in common],
    }


def characterise_vignetting_ExtendedGoldmanChen(
    data: VignettingData, options: ExtendedGoldmanChenOptions | None = None
) -> StepFit[ExtendedGoldmanChenVignetting]:
    """The ``"vignetting"`` step by the extended Goldman–Chen model (§5.5 of [PQ]_).

    Samples every view at the correspondences (a ``(2r+1)²`` window mean)
    and fits ``m1 … m6`` per channel by Levenberg–Marquardt
    (:func:`fit_vignetting_ExtendedGoldmanChen`). A fit that cannot be
    trusted is a :class:`CalibrationError`, never a number.
    """
    from photoquant.correspondences import sample_image, tracks_to_observations

    opts = options or ExtendedGoldmanChenOptions()
    n_views = len(data.uniform_views)
    tracks = list(data.tracks)
    if opts.max_tracks is not None and len(tracks) > opts.max_tracks:
        keep = np.unique(np.linspace(0, len(tracks) - 1, opts.max_tracks).round().astype(np.intp))
        tracks = [tracks[i] for i in keep]
    view_idx, xy, track_idx = tracks_to_observations(tracks)
    if view_idx.size and (view_idx.min() < 0 or view_idx.max() >= n_views):
        raise InputError(
            f"a correspondence names view {int(view_idx.max())}, there are {n_views} views"
        )
    n_ch = data.uniform_views[0].shape[-1]
    values = np.full((view_idx.size, n_ch), np.nan)
    loadings: np.ndarray | None = None
    carry = data.response_loadings if opts.response_error == "propagated" else None
    # whole tracks, evenly spread over the list, carry the response's error
    every = max(1, -(-len(tracks) // RESPONSE_ERROR_TRACKS))
    carries = track_idx % every == 0
    for v in range(n_views):
        sel = view_idx == v
        if np.any(sel):
            values[sel] = sample_image(data.uniform_views[v], xy[sel], radius=opts.sample_radius)
            carried = sel & carries
            if carry is not None and np.any(carried):
                found = carry(v, xy[carried])
                if loadings is None:
                    loadings = np.full((view_idx.size, n_ch, found.shape[-1]), np.nan)
                loadings[carried] = found
    fit = fit_vignetting_ExtendedGoldmanChen(
        values,
        xy,
        view_idx,
        track_idx,
        data.image_shape,
        normalise=opts.normalise,  # type: ignore[arg-type]
        scale_invariant=opts.scale_invariant,
        min_pairs=opts.min_pairs,
        min_spread=opts.min_spread,
        max_uncertainty=opts.max_uncertainty,
        max_nfev=opts.max_nfev,
        view_gains=wants_view_gains(opts.view_gains, data),
        view_gain_sigma=opts.view_gain_sigma,
        view_gain_centre=opts.view_gain_centre,  # type: ignore[arg-type]
        sample_radius=opts.sample_radius,
        value_log_loadings=loadings,
    )
    if not np.all(fit.converged):
        raise CalibrationError(f"the vignetting fit cannot be trusted: {fit.message}")
    report = {
        "n_tracks_given": len(data.tracks),
        "n_tracks_sampled": len(tracks),
        "n_tracks": fit.n_tracks,
        "n_pairs": fit.n_pairs,
        "n_observations": fit.n_observations,
        "residual_rms": fit.residual_rms,
        "map_uncertainty": fit.map_uncertainty,
        "response_error": "propagated" if loadings is not None else "not stated",
        "message": fit.message,
        **view_gain_report(fit.view_gains, fit.view_gain_std),
    }
    warnings = residual_warnings(fit.residual_rms, fit.map_uncertainty)  # trust beyond the solver's
    if warnings:
        report["warnings"] = warnings
    covariance = fit.param_covariance
    if opts.uncorrected_bias == "stated" and covariance is not None:
        inherited = fit.param_response_covariance
        statistical = covariance if inherited is None else covariance - inherited
        bias = _uncorrected_bias(data, opts, fit.params, statistical, report)
        covariance = covariance + bias[:, :, None] * bias[:, None, :]
    return StepFit(
        ExtendedGoldmanChenVignetting(
            "Extended Goldman-Chen", fit.params, covariance, fit.param_response_covariance
        ),
        report,
    )


RESPONSE_ERROR_TRACKS = 5000
"""Most tracks through which ``response_error="propagated"`` carries the response's error
into the parameters (evenly spread over the tracks used): the parameters' first-order move
under a smooth error of ``g`` is a projection that a few thousand tracks fix nearly as
well as all of them. Measured (2026-12-06, the paper's profile, 1024×768, N = 2, ccd and
cmos presets): the inherited map uncertainty within 7 % of all 30 000 tracks' per channel
(1 000 tracks: up to 25 % off), at a sixth of the cost (all of them: 0.25 s more)."""


_ESTIMATOR_FIELDS = (
    "normalise",
    "scale_invariant",
    "view_gains",
    "view_gain_sigma",
    "view_gain_centre",
)
"""The options of :class:`ExtendedGoldmanChenOptions` that define the fit's objective, whose
bias ``uncorrected_bias="stated"`` states against the defaults'."""


def _uncorrected_bias(
    data: VignettingData,
    opts: ExtendedGoldmanChenOptions,
    params: np.ndarray,
    covariance: np.ndarray,
    report: dict[str, Any],
) -> np.ndarray:
    """``b`` ``(C, 6)``, the parameters less those of the default fit of the same data,
    shrunk by the two fits' statistical part (``covariance``, the fit's own; the error
    both inherit from the response is common to them and not in their difference), for
    ``Cov(m) + b bᵀ`` (``uncorrected_bias="stated"``); the report gains the bias's RMS
    over the map (``uncorrected_bias_rms``), or why none is stated (``b = 0``).

    The reference keeps the options' sampling of the data (window, tracks, trust
    limits) and takes the defaults' objective (:data:`_ESTIMATOR_FIELDS`)."""
    defaults = ExtendedGoldmanChenOptions()
    estimator = {name: getattr(defaults, name) for name in _ESTIMATOR_FIELDS}
    reference_options = dataclasses.replace(opts, uncorrected_bias="ignored", **estimator)
    none = np.zeros_like(params)
    if dataclasses.replace(opts, uncorrected_bias="ignored") == reference_options:
        report["uncorrected_bias"] = "none stated: the options are the defaults' objective"
        return none
    try:
        reference = characterise_vignetting_ExtendedGoldmanChen(
            data, dataclasses.replace(reference_options, response_error="ignored")
        ).model
    except (CalibrationError, InputError) as exc:
        report["uncorrected_bias"] = f"none stated: the reference fit failed: {exc}"
        return none
    grid = (max(2, data.image_shape[0] // 16), max(2, data.image_shape[1] // 16))  # coordinates
    log_ratio = np.log(vignetting_map(params, grid)) - np.log(
        vignetting_map(reference.params, grid)
    )
    # the difference holds both fits' statistical errors beside the bias: their mean
    # variance over the map is taken from its mean square (b² = max(δ² − σ², 0)), so the
    # statistical part is not stated twice
    square = np.mean(log_ratio**2, axis=(0, 1))
    noise = np.zeros_like(square)
    for cov in (covariance, reference.param_covariance):
        if cov is not None:
            stated = ExtendedGoldmanChenVignetting("Extended Goldman-Chen", params, cov)
            noise += np.mean(stated.log_map_variance(grid), axis=(0, 1))  # type: ignore[arg-type]
    shrink = np.sqrt(np.maximum(square - noise, 0.0) / np.where(square > 0, square, 1.0))
    report["uncorrected_bias_rms"] = np.sqrt(square) * shrink
    return (params - reference.params) * shrink[:, None]


VIGNETTING_METHODS.add(
    Method(
        "vignetting",
        "Extended Goldman-Chen",
        characterise_vignetting_ExtendedGoldmanChen,
        options=ExtendedGoldmanChenOptions,
        model=ExtendedGoldmanChenVignetting,
        reference="[PQ] §5.5; Goldman & Chen 2005, doi:10.1109/ICCV.2005.249",
        needs=frozenset({"tracks"}),
    ),
    replace=True,
)


def fit_vignetting(
    values: Any,
    xy: Any,
    view: Any,
    track: Any,
    image_shape: tuple[int, int],
    *,
    method: Literal["Extended Goldman-Chen"] | str = "Extended Goldman-Chen",
    **kwargs: Any,
) -> VignettingFit:
    """Fit the extended Goldman–Chen model to observations (array level).

    Parameters
    ----------
    values, xy, view, track, image_shape
        See :func:`fit_vignetting_ExtendedGoldmanChen`.
    method : str
        Must name the ``"Extended Goldman-Chen"`` method (the only one with
        this array-level interface); the step-level entry point for any
        registered method is :func:`photoquant.calibration.fit_vignetting_step`.
    **kwargs
        Keyword arguments of :func:`fit_vignetting_ExtendedGoldmanChen`.

    Returns
    -------
    VignettingFit
    """
    entry = VIGNETTING_METHODS[method]
    if entry.function is not characterise_vignetting_ExtendedGoldmanChen:
        raise InputError(
            f"fit_vignetting works on observations for 'Extended Goldman-Chen' only, not "
            f"{entry.name!r}"
        )
    return fit_vignetting_ExtendedGoldmanChen(values, xy, view, track, image_shape, **kwargs)
