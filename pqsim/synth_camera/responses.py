"""Ground-truth response curves of the synthetic camera.

A response curve ``F`` maps the *normalised exposure* ``e`` of a pixel (its
electron count divided by the sensor's full-well capacity, so that ``e = 1`` is
the saturation of a linear sensor) to a normalised output ``F(e)`` in
``[0, 1]``; the camera then outputs ``a_λ · c_max · F(e)`` (eq. 1 of [PQ], with
``f_λ(X) = c_max · F(X · exposure_scale / full_well)``).

Every curve here is monotonic (non-decreasing on ``[0, ∞)``, strictly
increasing below its saturation exposure) so that it has an inverse on its
range, which the ground truth ``g_λ = ln f_λ⁻¹`` (eq. 7 of [PQ]) needs.

Public objects
--------------
- :func:`response_linear`: CCD-like, linear with a hard clip (optional soft knee).
- :func:`response_gamma`: power law ``e**gamma``.
- :func:`response_s_curve`: CMOS-like S-curve, strictly increasing, ``F(0)=0``,
  ``F(1)=1``.
- :func:`response_table`: a curve given by a monotonic table (piecewise linear);
  :func:`load_response_table` reads one from a CSV/text or JSON file.
- :func:`response_emor`: a response from the space of real ones, the EMoR
  model ``f0 + Σ c_k h_k`` of [GN04]; :func:`draw_emor_coefficients` draws
  monotone coefficients within the spread of real cameras
  (:func:`emor_coefficient_spread`).
- :func:`response_film`: a film-like characteristic (H&D) curve with a toe
  and a shoulder in log exposure.
- ``knee``: the ``"emor"`` and ``"film"`` kinds take, like ``"linear"``, a
  knee just below saturation (:func:`apply_knee`).
- :class:`ResponseCurve`: a frozen ``(kind, params)`` record, callable, with an
  exact vectorised :meth:`~ResponseCurve.inverse`.
- :data:`RESPONSE_MODELS`: the registry ``kind → ResponseModel``.

References
----------
.. [PQ] The photoquantity paper: eq. 1 (model),
   eq. 5 and 7 (log inverse response ``g_λ``), §3.2.2 (exposure and response).
.. [DM97] P. E. Debevec and J. Malik, "Recovering high dynamic range radiance
   maps from photographs", SIGGRAPH 1997, doi:10.1145/258734.258884.
.. [GN04] M. D. Grossberg and S. K. Nayar, "Modeling the space of camera
   response functions", IEEE TPAMI 26(10), 2004, doi:10.1109/TPAMI.2004.88
   (real response curves are monotonic, most are S-shaped in log exposure).
.. [HD1890] F. Hurter and V. C. Driffield, "Photo-chemical investigations and
   a new method of determination of the sensitiveness of photographic
   plates", J. Soc. Chem. Ind. 9, 1890 (the characteristic curve: toe,
   straight line, shoulder in log exposure).
.. [MJ77] C. E. K. Mees and T. H. James (eds.), *The Theory of the
   Photographic Process*, 4th ed., Macmillan, 1977, ch. 17 (sensitometry).
"""

from __future__ import annotations

import csv
import functools
import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_array, check_int, check_positive, emor_basis, validate_method

__all__ = [
    "response_linear",
    "response_linear_inverse",
    "response_gamma",
    "response_gamma_inverse",
    "response_s_curve",
    "response_s_curve_inverse",
    "response_table",
    "response_emor",
    "response_emor_table",
    "response_emor_inverse",
    "emor_coefficient_spread",
    "draw_emor_coefficients",
    "response_film",
    "response_film_inverse",
    "apply_knee",
    "apply_knee_inverse",
    "response_table_forward",
    "response_table_inverse",
    "load_response_table",
    "numeric_inverse",
    "ResponseModel",
    "ResponseCurve",
    "RESPONSE_MODELS",
]


# ---------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------


def _exposure(e: Any, name: str = "e") -> np.ndarray:
    """Return ``e`` as a float64 array of finite or +inf, non-negative exposures."""
    if np.size(e) == 0:  # an empty array evaluates to an empty array
        return np.asarray(e, dtype=np.float64)
    arr = check_array(e, name, kind="iuf").astype(np.float64)
    if np.any(np.isnan(arr)):
        raise InputError(f"`{name}` contains NaN")
    if np.any(arr < 0):
        raise InputError(f"`{name}` must be non-negative normalised exposures, got min {arr.min()}")
    return arr


def _output(F: Any, name: str = "F") -> np.ndarray:
    """Return ``F`` as a float64 array of values in ``[0, 1]``."""
    if np.size(F) == 0:
        return np.asarray(F, dtype=np.float64)
    arr = check_array(F, name, kind="iuf", finite=True).astype(np.float64)
    if np.any(arr < 0) or np.any(arr > 1):
        raise InputError(
            f"`{name}` must lie in [0, 1] (normalised response), got [{arr.min()}, {arr.max()}]"
        )
    return arr


def _knee(knee: Any) -> float | None:
    if knee is None:
        return None
    k = check_positive(knee, "knee")
    if not k < 1:
        raise InputError(f"`knee` must lie in (0, 1), got {knee!r}")
    return k


def _s_params(contrast: Any, pivot: Any) -> tuple[float, float]:
    c = check_positive(contrast, "contrast")
    p = check_positive(pivot, "pivot")
    if not p < 1:
        raise InputError(f"`pivot` must lie in (0, 1), got {pivot!r}")
    return c, p


# ---------------------------------------------------------------------------
# Linear (CCD)
# ---------------------------------------------------------------------------


def response_linear(e: Any, knee: float | None = None) -> np.ndarray:
    """Linear response with saturation (CCD-like), optionally with a soft knee.

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0`` (``+inf`` allowed).
    knee : float in (0, 1), optional
        Without a knee the response is ``F(e) = min(e, 1)`` (a hard clip at the
        full well). With a knee ``k`` it stays linear up to ``k`` and then bends
        over a quadratic shoulder with continuous slope,
        ``F = k + d - d² / (4 (1 - k))`` for ``d = e - k``, which reaches ``1``
        with zero slope at ``e = 2 - k`` and clips there.

    Returns
    -------
    ndarray, float64
        ``F(e)`` in ``[0, 1]``, same shape as ``e``.

    Notes
    -----
    The shoulder models the gain compression of a CCD close to its full well:
    the response is concave, ``C¹``, strictly increasing on ``[0, 2 - k)``.

    Examples
    --------
    >>> response_linear([0.0, 0.5, 2.0]).tolist()
    [0.0, 0.5, 1.0]
    >>> round(float(response_linear(1.0, knee=0.8)), 12)
    0.95
    """
    e = _exposure(e)
    k = _knee(knee)
    if k is None:
        return np.minimum(e, 1.0)
    d = np.clip(e - k, 0.0, 2.0 * (1.0 - k))
    shoulder = np.minimum(k + d - d * d / (4.0 * (1.0 - k)), 1.0)  # rounding may exceed 1
    # exactly 1 from the saturation exposure 2 - k on (the same float as the inverse's)
    return np.where(e <= k, e, np.where(e >= 2.0 - k, 1.0, shoulder))


def response_linear_inverse(F: Any, knee: float | None = None) -> np.ndarray:
    """Exact inverse of :func:`response_linear` on ``[0, 1]``.

    ``F = 1`` maps to the saturation exposure (``1``, or ``2 - knee``): the
    smallest exposure that saturates.
    """
    F = _output(F)
    k = _knee(knee)
    if k is None:
        return F.copy()
    q = np.clip((F - k) / (1.0 - k), 0.0, 1.0)
    shoulder = np.minimum(k + 2.0 * (1.0 - k) * (1.0 - np.sqrt(1.0 - q)), 2.0 - k)
    return np.where(F <= k, F, np.where(F >= 1.0, 2.0 - k, shoulder))


# ---------------------------------------------------------------------------
# Gamma
# ---------------------------------------------------------------------------


def response_gamma(e: Any, gamma: float = 1.0 / 2.2) -> np.ndarray:
    """Power-law response ``F(e) = min(e, 1) ** gamma``.

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0``.
    gamma : float
        Positive exponent; ``1/2.2`` mimics a display-encoded camera.

    Returns
    -------
    ndarray, float64
        ``F(e)`` in ``[0, 1]``.

    Examples
    --------
    >>> float(response_gamma(0.25, gamma=0.5))
    0.5
    """
    e = _exposure(e)
    g = check_positive(gamma, "gamma")
    return np.minimum(e, 1.0) ** g


def response_gamma_inverse(F: Any, gamma: float = 1.0 / 2.2) -> np.ndarray:
    """Exact inverse of :func:`response_gamma`: ``e = F ** (1 / gamma)``."""
    F = _output(F)
    g = check_positive(gamma, "gamma")
    return F ** (1.0 / g)


# ---------------------------------------------------------------------------
# S-curve (CMOS)
# ---------------------------------------------------------------------------


def _logistic(z: np.ndarray) -> np.ndarray:
    """``1 / (1 + exp(-z))`` without overflow for either sign (``±inf`` allowed)."""
    ez = np.exp(-np.abs(z))
    return np.where(z >= 0, 1.0 / (1.0 + ez), ez / (1.0 + ez))


def response_s_curve(e: Any, contrast: float = 1.5, pivot: float = 0.25) -> np.ndarray:
    """CMOS-like S-curve, strictly increasing on ``[0, 1]`` with ``F(0)=0``, ``F(1)=1``.

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0``; exposures above 1 saturate (``F = 1``).
    contrast : float
        Positive steepness ``c``: ``F ~ e**c`` near 0 and ``1 - F ~ (1-e)**c``
        near 1; ``c > 1`` gives an S (toe and shoulder), ``c = 1`` with
        ``pivot = 1/2`` the identity.
    pivot : float in (0, 1)
        Exposure mapped to mid-output: ``F(pivot) = 1/2``.

    Returns
    -------
    ndarray, float64
        ``F(e) = r**c / (1 + r**c)`` with ``r = (e / (1 - e)) · ((1 - p) / p)``.

    Notes
    -----
    A logistic curve in the log-odds of the exposure; its inverse is analytic,
    ``e = q / (1 + q)`` with ``q = (F / (1 - F))**(1/c) · p / (1 - p)``.

    Examples
    --------
    >>> round(float(response_s_curve(0.25, contrast=1.5, pivot=0.25)), 12)
    0.5
    """
    return _s_curve_valid(_exposure(e), contrast, pivot)


_CHUNK = 16384
"""Elements a chunked kernel works on at once (128 KiB of float64: its buffers stay in cache)."""


def _s_curve_valid(e: np.ndarray, contrast: float = 1.5, pivot: float = 0.25) -> np.ndarray:
    """:func:`response_s_curve` of float64 exposures already checked (``>= 0``, no NaN).

    The formula of :func:`response_s_curve` and :func:`_logistic`, the same operations in
    the same order (so the same values to the bit), evaluated in place on chunks of
    :data:`_CHUNK` elements: no temporaries the size of a frame, no masked copies. At
    ``e >= 1``, ``log r = +inf`` and the logistic gives exactly 1, the saturated output.
    """
    c, p = _s_params(contrast, pivot)
    log_odds = math.log((1.0 - p) / p)
    x = np.minimum(e, 1.0, out=np.empty(np.shape(e)))
    flat = x.reshape(-1)  # a view of the fresh x: its chunks are overwritten with F
    m = min(_CHUNK, flat.size)
    a, b, positive = np.empty(m), np.empty(m), np.empty(m, dtype=bool)
    with np.errstate(divide="ignore"):
        for start in range(0, flat.size, _CHUNK):
            o = flat[start : start + _CHUNK]
            k = o.size
            ak, bk, pk = a[:k], b[:k], positive[:k]
            np.negative(o, out=ak)
            np.log1p(ak, out=ak)  # log(1 - x)
            np.log(o, out=o)
            o -= ak
            o += log_odds  # log r: 0 → -inf, 1 → +inf
            o *= c  # z
            np.greater_equal(o, 0.0, out=pk)
            np.abs(o, out=ak)
            np.negative(ak, out=ak)
            np.exp(ak, out=ak)  # exp(-|z|)
            np.add(ak, 1.0, out=bk)
            np.copyto(ak, 1.0, where=pk)  # numerator: 1 where z >= 0, exp(-|z|) elsewhere
            np.divide(ak, bk, out=o)
    return x


def response_s_curve_inverse(F: Any, contrast: float = 1.5, pivot: float = 0.25) -> np.ndarray:
    """Exact inverse of :func:`response_s_curve` on ``[0, 1]`` (``F = 1 → e = 1``)."""
    F = _output(F)
    c, p = _s_params(contrast, pivot)
    out = np.ones_like(F)
    inside = F < 1.0
    Fi = F[inside]
    with np.errstate(divide="ignore"):
        log_q = (np.log(Fi) - np.log1p(-Fi)) / c + math.log(p / (1.0 - p))
    out[inside] = _logistic(log_q)  # e = q / (1 + q)
    return out


# ---------------------------------------------------------------------------
# Table
# ---------------------------------------------------------------------------


def _table(x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate a response table and return it as float64 arrays (starting at e = 0)."""
    xa = check_array(x, "x", ndim=1, kind="iuf", finite=True).astype(np.float64)
    ya = check_array(y, "y", ndim=1, kind="iuf", finite=True).astype(np.float64)
    if xa.size != ya.size:
        raise InputError(f"`x` and `y` must have the same length, got {xa.size} and {ya.size}")
    if xa[0] < 0:
        raise InputError(f"`x` must be non-negative normalised exposures, got x[0] = {xa[0]}")
    if np.any(np.diff(xa) <= 0):
        raise InputError("`x` must be strictly increasing")
    if np.any(np.diff(ya) <= 0):
        raise InputError(
            "`y` must be strictly increasing (a monotonic, invertible response); "
            "cut a table that saturates at its first value of 1"
        )
    if ya[0] < 0 or ya[-1] > 1:
        raise InputError(f"`y` must lie in [0, 1], got [{ya[0]}, {ya[-1]}]")
    if xa[0] > 0:
        if ya[0] <= 0:
            raise InputError("`y` must be positive when the table starts at x[0] > 0")
        xa = np.concatenate([[0.0], xa])
        ya = np.concatenate([[0.0], ya])
    return xa, ya


def response_table_forward(e: Any, x: Any, y: Any) -> np.ndarray:
    """Evaluate a tabulated response: piecewise linear through ``(x, y)``.

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0``.
    x, y : array_like, shape (M,)
        Strictly increasing exposures ``x >= 0`` and outputs ``y`` in
        ``[0, 1]``. A table starting at ``x[0] > 0`` is extended by ``(0, 0)``.

    Returns
    -------
    ndarray, float64
        ``F(e)``; exposures beyond ``x[-1]`` give ``y[-1]`` (saturation).
    """
    e = _exposure(e)
    xa, ya = _table(x, y)
    return np.interp(e, xa, ya)


def response_table_inverse(F: Any, x: Any, y: Any) -> np.ndarray:
    """Exact inverse of :func:`response_table_forward` on ``[y[0], y[-1]]``.

    Outputs below ``y[0]`` map to ``x[0]``; outputs above ``y[-1]`` are
    refused (no exposure produces them).
    """
    F = _output(F)
    xa, ya = _table(x, y)
    if np.any(F > ya[-1]):
        raise InputError(f"`F` exceeds the table's maximum output {ya[-1]}")
    return np.interp(F, ya, xa)


def response_table(x: Any, y: Any) -> ResponseCurve:
    """Build a :class:`ResponseCurve` from a monotonic table ``(x, y)``.

    Parameters
    ----------
    x, y : array_like, shape (M,)
        Normalised exposures (strictly increasing, ``>= 0``) and outputs
        (strictly increasing, in ``[0, 1]``); see :func:`response_table_forward`.

    Returns
    -------
    ResponseCurve
        ``ResponseCurve("table", {"x": (...), "y": (...)})``.

    Examples
    --------
    >>> curve = response_table([0.0, 0.5, 1.0], [0.0, 0.8, 1.0])
    >>> float(curve(0.25))
    0.4
    """
    xa, ya = _table(x, y)
    return ResponseCurve("table", {"x": tuple(xa.tolist()), "y": tuple(ya.tolist())})


def load_response_table(path: str | Path) -> ResponseCurve:
    """Read a response table from a CSV/text file or a JSON file.

    Parameters
    ----------
    path : str or Path
        - ``.json``: an object ``{"x": [...], "y": [...]}`` (``"exposure"`` and
          ``"response"`` are accepted as aliases), or a list of ``[x, y]`` pairs.
        - anything else: two columns ``x, y`` separated by commas, semicolons or
          whitespace; lines starting with ``#`` and a non-numeric header line
          are skipped.

    Returns
    -------
    ResponseCurve
        A ``"table"`` curve; the table is validated by :func:`response_table`.

    Raises
    ------
    InputError
        If the file is missing, malformed or not a monotonic table.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"`path`: cannot read response table {str(path)!r}: {exc}") from None
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"`path`: {str(path)!r} is not valid JSON: {exc}") from None
        if isinstance(data, Mapping):
            xs = data.get("x", data.get("exposure"))
            ys = data.get("y", data.get("response"))
            if xs is None or ys is None:
                raise InputError(f"`path`: {str(path)!r} must hold keys 'x' and 'y'")
        elif isinstance(data, list) and all(isinstance(r, list) and len(r) == 2 for r in data):
            xs = [r[0] for r in data]
            ys = [r[1] for r in data]
        else:
            raise InputError(f"`path`: {str(path)!r} must hold {{'x': [...], 'y': [...]}}")
        try:
            return response_table(
                np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
            )
        except (TypeError, ValueError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"`path`: {str(path)!r} holds non-numeric values") from None
    rows: list[tuple[float, float]] = []
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"`path`: {str(path)!r} holds no table rows")
    reader = csv.reader(io.StringIO("\n".join(ln.replace(";", ",") for ln in lines)))
    for i, row in enumerate(reader):
        cells = [c for part in row for c in part.split()]
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if i == 0:  # header
                continue
            raise InputError(f"`path`: {str(path)!r} row {i + 1} is not numeric: {row}") from None
        if len(values) != 2:
            raise InputError(f"`path`: {str(path)!r} row {i + 1} must have 2 columns, got {row}")
        rows.append((values[0], values[1]))
    if not rows:
        raise InputError(f"`path`: {str(path)!r} holds no table rows")
    arr = np.asarray(rows, dtype=np.float64)
    return response_table(arr[:, 0], arr[:, 1])


# ---------------------------------------------------------------------------
# Knee just below saturation, for any curve
# ---------------------------------------------------------------------------


def _knee_point(
    forward: Callable[[np.ndarray], np.ndarray],
    inverse: Callable[[np.ndarray], np.ndarray],
    k: float,
) -> tuple[float, float]:
    """``(e_k, s)``: the exposure where the curve reaches ``k`` and its slope there (from the left)."""
    e_k = float(inverse(np.array([k]))[0])
    if not e_k > 0:
        raise InputError(f"`knee` {k} is reached at exposure 0: no room for a shoulder")
    de = 1e-7 * e_k
    s = float((k - forward(np.array([e_k - de]))[0]) / de)
    if not (math.isfinite(s) and s > 0):
        raise InputError(f"the curve is flat below the knee {k}: no shoulder can join it")
    return e_k, s


def apply_knee(
    e: np.ndarray,
    forward: Callable[[np.ndarray], np.ndarray],
    inverse: Callable[[np.ndarray], np.ndarray],
    knee: float | None,
) -> np.ndarray:
    """A curve ``F`` with a soft knee at output ``knee`` (just below saturation).

    Parameters
    ----------
    e : ndarray
        Normalised exposures (already checked).
    forward, inverse : callable
        The curve without knee and its inverse.
    knee : float in (0, 1) or None
        Output level ``k`` where the shoulder starts; ``None`` returns ``F(e)``.

    Returns
    -------
    ndarray
        ``F(e)`` up to ``e_k = F⁻¹(k)``; above, the quadratic shoulder of
        :func:`response_linear` generalised to the slope ``s = F'(e_k)``:
        ``G = k + s d − s² d² / (4 (1 − k))`` for ``d = e − e_k``, which
        joins ``F`` with a continuous slope and reaches 1 with zero slope at
        ``e_k + 2 (1 − k) / s`` (then clips). For ``F(e) = e`` it is
        ``response_linear(e, knee)`` exactly.

    Notes
    -----
    The gain compression of a sensor close to its full well, or a camera's
    highlight roll-off, bends the response just below saturation; this adds
    it to a curve of any family.
    """
    k = _knee(knee)
    if k is None:
        return forward(e)
    e_k, s = _knee_point(forward, inverse, k)
    span = 2.0 * (1.0 - k) / s
    d = np.clip(e - e_k, 0.0, span)
    shoulder = np.minimum(k + s * d - (s * d) ** 2 / (4.0 * (1.0 - k)), 1.0)
    base = forward(np.minimum(e, e_k))
    return np.where(e <= e_k, base, np.where(e >= e_k + span, 1.0, shoulder))


def apply_knee_inverse(
    F: np.ndarray,
    forward: Callable[[np.ndarray], np.ndarray],
    inverse: Callable[[np.ndarray], np.ndarray],
    knee: float | None,
) -> np.ndarray:
    """Exact inverse of :func:`apply_knee` on ``[0, 1]`` (``F = 1`` → the saturation exposure)."""
    k = _knee(knee)
    if k is None:
        return inverse(F)
    e_k, s = _knee_point(forward, inverse, k)
    span = 2.0 * (1.0 - k) / s
    q = np.clip((F - k) / (1.0 - k), 0.0, 1.0)
    shoulder = np.minimum(e_k + span * (1.0 - np.sqrt(1.0 - q)), e_k + span)
    return np.where(F <= k, inverse(np.minimum(F, k)), np.where(F >= 1.0, e_k + span, shoulder))


# ---------------------------------------------------------------------------
# EMoR: responses from the space of real ones
# ---------------------------------------------------------------------------

EMOR_MIN_STEP = 1e-9
"""Smallest rise of a drawn EMoR curve between adjacent grid points: a curve
rising less anywhere is not strictly monotone (it is redrawn)."""


def _film_reference(e: np.ndarray, toe: float, shoulder: float, pivot: float) -> np.ndarray:
    return response_film(e, toe=toe, shoulder=shoulder, pivot=pivot)


@functools.cache
def _reference_responses() -> tuple[tuple[str, np.ndarray], ...]:
    """The reference curves behind :func:`emor_coefficient_spread`, on the EMoR grid."""
    e, _, _ = emor_basis()
    refs: list[tuple[str, np.ndarray]] = []
    for g in np.linspace(1.0, 2.6, 9):  # gamma-encoded cameras, linear to 1/2.6
        refs.append((f"gamma 1/{g:.1f}", e ** (1.0 / g)))
    srgb = np.where(e <= 0.0031308, 12.92 * e, 1.055 * e ** (1 / 2.4) - 0.055)
    rec709 = np.where(e < 0.018, 4.5 * e, 1.099 * e**0.45 - 0.099)
    refs += [("sRGB", srgb), ("Rec. 709", rec709)]
    for toe, shoulder, pivot in (
        (1.6, 1.0, 0.3),
        (2.2, 1.5, 0.4),
        (1.3, 0.8, 0.2),
        (1.8, 2.0, 0.5),
    ):
        refs.append((f"film {toe}/{shoulder}/{pivot}", _film_reference(e, toe, shoulder, pivot)))
    return tuple(refs)


@functools.cache
def _spread(n: int) -> np.ndarray:
    e, f0, h = emor_basis()
    curves = np.array([c for _, c in _reference_responses()])
    coeffs = (curves - f0) @ h[:n].T  # orthonormal basis: least-squares coefficients
    out = np.sqrt(np.mean(coeffs**2, axis=0))
    out.setflags(write=False)
    return out


def emor_coefficient_spread(n_components: int = 5) -> np.ndarray:
    """Standard deviations ``σ_k`` of the EMoR coefficients of real-like responses.

    Parameters
    ----------
    n_components : int
        ``K``, 1 to 25.

    Returns
    -------
    ndarray, shape (K,), read-only
        ``σ_k = sqrt(mean_j c_{jk}²)``, the root mean square of the
        coefficients ``c_jk = h_k · (f_j − f0)`` of a documented set of
        reference responses ``f_j`` about the EMoR mean ``f0`` [GN04].

    Notes
    -----
    **Which spread, and why.** The EMoR file (``emor.txt`` of the DoRF
    database) holds the mean and the components but not their eigenvalues,
    and the 201 DoRF curves are not shipped, so the variance per component
    cannot be read off the database. It is derived instead from curves of
    the categories DoRF collects [GN04] (§3: video and digital cameras with
    gamma encodings, and films): power laws ``E^(1/γ)`` for ``γ`` from 1.0
    (linear) to 2.6 in nine steps, the sRGB and Rec. 709 encodings, and four
    film characteristic curves (:func:`response_film`, toe 1.3–2.2, shoulder
    0.8–2.0, pivot 0.2–0.5), each projected on the (orthonormal) basis. The
    spread is taken about ``f0`` (the DoRF mean), since draws are centred
    there. For ``K = 5`` it is about ``(2.95, 1.01, 0.26, 0.13, 0.05)``: the
    first component varies most, as in the database's ordering.

    Examples
    --------
    >>> s = emor_coefficient_spread(3)
    >>> s.shape, bool(s[0] > s[1] > s[2] > 0)
    ((3,), True)
    """
    n = check_int(n_components, "n_components", 1, 25)
    return _spread(n)


def draw_emor_coefficients(
    rng: np.random.Generator | int,
    n_components: int = 5,  # noqa: ARG001 - recorded beside the coefficients
    *,
    spread_scale: float = 1.0,
    max_draws: int = 1000,
) -> np.ndarray:
    """Draw EMoR coefficients of a strictly monotone response, seeded.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of randomness (an int seeds ``default_rng``).
    n_components : int
        ``K``, 1 to 25.
    spread_scale : float
        Multiplies the spread of :func:`emor_coefficient_spread` (1: real cameras).
    max_draws : int
        Most proposals before giving up.

    Returns
    -------
    ndarray, shape (K,)
        ``c_k = spread_scale · σ_k · z_k``, ``z ~ N(0, I)``, redrawn until
        ``f0 + Σ c_k h_k`` rises by more than :data:`EMOR_MIN_STEP` at every
        grid step: a sample of the normal distribution restricted to monotone
        responses (about 70 % of the proposals are accepted for ``K = 5``).
        The curve passes through ``(0, 0)`` and ``(1, 1)`` (every ``h_k``
        vanishes there), so a monotone one lies within ``[0, 1]``.

    Examples
    --------
    >>> c = draw_emor_coefficients(3, 4)
    >>> c.shape, bool(np.all(np.diff(response_emor_table(c)) > 0))
    ((4,), True)
    """
    n = check_int(n_components, "n_components", 1, 25)
    scale = check_positive(spread_scale, "spread_scale")
    tries = check_int(max_draws, "max_draws", 1)
    if isinstance(rng, np.random.Generator):
        gen = rng
    elif isinstance(rng, int | np.integer) and not isinstance(rng, bool) and int(rng) >= 0:
        gen = np.random.default_rng(int(rng))
    else:
        raise InputError(
            f"`rng` must be a numpy.random.Generator or a non-negative int, got {rng!r}"
        )
    sigma = scale * emor_coefficient_spread(n)
    for _ in range(tries):
        c = sigma * gen.standard_normal(n)
        if np.all(np.diff(response_emor_table(c)) > EMOR_MIN_STEP):
            return c
    raise InputError(f"no monotone EMoR response in {tries} draws (spread_scale {scale})")


def response_emor_table(coefficients: Any) -> np.ndarray:
    """``f = f0 + Σ_k c_k h_k`` on the EMoR grid of 1024 exposures [GN04]."""
    c = check_array(coefficients, "coefficients", ndim=1, kind="iuf", finite=True).astype(
        np.float64
    )
    if not 1 <= c.size <= 25:
        raise InputError(f"`coefficients` must hold 1 to 25 EMoR coefficients, got {c.size}")
    _, f0, h = emor_basis()
    return f0 + c @ h[: c.size]


@functools.lru_cache(maxsize=64)
def _emor_curve(coefficients: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    e, _, _ = emor_basis()
    f = response_emor_table(np.asarray(coefficients))
    if not np.all(np.diff(f) > 0):
        raise InputError(
            "`coefficients` give an EMoR response that is not strictly increasing "
            f"(its smallest step is {np.diff(f).min():.3g})"
        )
    f = f.copy()
    f.setflags(write=False)
    return e, f


def _emor_params(coefficients: Any) -> tuple[float, ...]:
    if coefficients is None:
        raise InputError("`coefficients`: an EMoR response needs coefficients or a seed")
    return tuple(float(v) for v in np.asarray(coefficients, dtype=np.float64).ravel())


def response_emor(
    e: Any,
    coefficients: Any = None,
    seed: int | None = None,  # noqa: ARG001 - recorded beside the coefficients
    n_components: int = 5,  # noqa: ARG001 - recorded beside the coefficients
    knee: float | None = None,
) -> np.ndarray:
    """A response from the space of real ones: the EMoR model of [GN04].

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0``; exposures above 1 saturate.
    coefficients : array_like, shape (K,)
        ``c_1 … c_K``; the curve ``f = f0 + Σ c_k h_k`` on the basis' 1024
        exposures must be strictly increasing.
    seed, n_components : int
        How the coefficients were drawn (:func:`draw_emor_coefficients`),
        recorded beside them; a :class:`ResponseCurve` of kind ``"emor"``
        given a seed and no coefficients draws them.
    knee : float in (0, 1), optional
        A soft knee just below saturation (:func:`apply_knee`).

    Returns
    -------
    ndarray, float64
        ``F(e)``, linear between the grid points (as the basis is tabulated).

    Examples
    --------
    >>> F = response_emor([0.0, 1.0, 2.0], coefficients=[0.5, -0.2])
    >>> F.tolist()
    [0.0, 1.0, 1.0]
    """
    x = _exposure(e)
    grid, f = _emor_curve(_emor_params(coefficients))

    def fwd(v: np.ndarray) -> np.ndarray:
        return np.interp(np.minimum(v, 1.0), grid, f)

    def inv(F: np.ndarray) -> np.ndarray:
        return np.interp(F, f, grid)

    return apply_knee(x, fwd, inv, knee)


def response_emor_inverse(
    F: Any,
    coefficients: Any = None,
    seed: int | None = None,  # noqa: ARG001 - recorded beside the coefficients
    n_components: int = 5,  # noqa: ARG001 - recorded beside the coefficients
    knee: float | None = None,
) -> np.ndarray:
    """Exact inverse of :func:`response_emor` on ``[0, 1]`` (``F = 1`` → ``e = 1``, or the knee's end)."""
    Fa = _output(F)
    grid, f = _emor_curve(_emor_params(coefficients))

    def fwd(v: np.ndarray) -> np.ndarray:
        return np.interp(np.minimum(v, 1.0), grid, f)

    def inv(y: np.ndarray) -> np.ndarray:
        return np.interp(y, f, grid)

    return apply_knee_inverse(Fa, fwd, inv, knee)


def _resolve_emor(params: dict[str, Any]) -> dict[str, Any]:
    """Draw the coefficients of an ``"emor"`` record that gives only a seed."""
    n = check_int(params["n_components"], "n_components", 1, 25)
    out = dict(params, n_components=n)
    if params["coefficients"] is None:
        seed = params["seed"]
        if seed is None:
            raise InputError("`params`: response 'emor' needs `coefficients` or a `seed`")
        check_int(seed, "seed", 0)
        out["coefficients"] = tuple(float(v) for v in draw_emor_coefficients(int(seed), n))
    elif params["seed"] is not None:
        check_int(params["seed"], "seed", 0)
    return out


# ---------------------------------------------------------------------------
# Film characteristic curve (toe and shoulder)
# ---------------------------------------------------------------------------


def _film_params(toe: Any, shoulder: Any, pivot: Any) -> tuple[float, float, float]:
    return (
        check_positive(toe, "toe"),
        check_positive(shoulder, "shoulder"),
        check_positive(pivot, "pivot"),
    )


def _film_log_r(e: np.ndarray, t: float, s: float, p: float) -> np.ndarray:
    """``ln R(e)`` with ``R = (1 + (p/e)^s)^(−t/s)``, stable for every ``e >= 0``."""
    with np.errstate(divide="ignore"):
        z = s * (math.log(p) - np.log(e))
    return -(t / s) * np.logaddexp(0.0, z)


def response_film(
    e: Any, toe: float = 1.6, shoulder: float = 1.0, pivot: float = 0.3, knee: float | None = None
) -> np.ndarray:
    """A film-like characteristic curve: a toe and a shoulder in log exposure [HD1890]_.

    Parameters
    ----------
    e : array_like
        Normalised exposure, ``>= 0``; exposures above 1 saturate (the
        scanner's or printer's white).
    toe : float
        Positive exponent of the toe: ``F ∝ e^toe`` for ``e ≪ pivot`` (a
        slope ``toe`` in log–log; ``> 1`` gives the film's slow start).
    shoulder : float
        Positive rate of the shoulder: ``1 − R ∝ (pivot/e)^shoulder`` for
        ``e ≫ pivot``; smaller values give a longer, softer shoulder.
    pivot : float
        Exposure where the toe turns into the shoulder.
    knee : float in (0, 1), optional
        A soft knee just below saturation (:func:`apply_knee`).

    Returns
    -------
    ndarray, float64
        ``F(e) = R(min(e, 1)) / R(1)`` with
        ``R(e) = (1 + (pivot / e)^shoulder)^(−toe / shoulder)``.

    Notes
    -----
    ``R`` is the Richards (generalised logistic) curve in ``ln e``, the usual
    analytic stand-in for a film's H&D characteristic curve: straight in
    log–log between a toe and a shoulder, asymmetric when ``toe ≠
    shoulder`` [MJ77]_. Its inverse is analytic:
    ``e = pivot · (R^(−shoulder/toe) − 1)^(−1/shoulder)``.

    Examples
    --------
    >>> F = response_film([0.0, 0.3, 1.0], toe=2.0, shoulder=2.0, pivot=0.3)
    >>> [round(float(v), 6) for v in F]
    [0.0, 0.545, 1.0]
    """
    x = _exposure(e)
    t, s, p = _film_params(toe, shoulder, pivot)
    log_r1 = float(_film_log_r(np.array([1.0]), t, s, p)[0])

    def fwd(v: np.ndarray) -> np.ndarray:
        return np.minimum(np.exp(_film_log_r(np.minimum(v, 1.0), t, s, p) - log_r1), 1.0)

    def inv(F: np.ndarray) -> np.ndarray:
        return _film_inverse(F, t, s, p, log_r1)

    return apply_knee(x, fwd, inv, knee)


def _film_inverse(F: np.ndarray, t: float, s: float, p: float, log_r1: float) -> np.ndarray:
    out = np.zeros_like(F)
    pos = F > 0
    with np.errstate(divide="ignore"):
        log_r = np.log(F[pos]) + log_r1  # ln R < 0
    # R^(-s/t) - 1 = expm1(-(s/t) ln R) > 0
    out[pos] = p * np.expm1(-(s / t) * log_r) ** (-1.0 / s)
    return np.where(F >= 1.0, 1.0, np.minimum(out, 1.0))


def response_film_inverse(
    F: Any, toe: float = 1.6, shoulder: float = 1.0, pivot: float = 0.3, knee: float | None = None
) -> np.ndarray:
    """Exact inverse of :func:`response_film` on ``[0, 1]`` (``F = 1`` → the saturation exposure)."""
    Fa = _output(F)
    t, s, p = _film_params(toe, shoulder, pivot)
    log_r1 = float(_film_log_r(np.array([1.0]), t, s, p)[0])

    def fwd(v: np.ndarray) -> np.ndarray:
        return np.minimum(np.exp(_film_log_r(np.minimum(v, 1.0), t, s, p) - log_r1), 1.0)

    def inv(y: np.ndarray) -> np.ndarray:
        return _film_inverse(y, t, s, p, log_r1)

    return apply_knee_inverse(Fa, fwd, inv, knee)


# ---------------------------------------------------------------------------
# Numeric inverse, registry and the curve record
# ---------------------------------------------------------------------------


def numeric_inverse(
    forward: Callable[[np.ndarray], np.ndarray],
    F: Any,
    *,
    e_max: float = 2.0**20,
) -> np.ndarray:
    """Invert a monotonic response numerically by vectorised bisection on the float grid.

    Parameters
    ----------
    forward : callable
        Non-decreasing ``F(e)`` on ``[0, ∞)``, vectorised.
    F : array_like
        Outputs to invert, in ``[0, 1]``.
    e_max : float
        Largest exposure searched; outputs not reached below it are refused.

    Returns
    -------
    ndarray, float64
        The smallest float64 ``e`` with ``forward(e) >= F``: the exact inverse
        where ``forward`` is strictly increasing (to one ulp of ``e``), the
        start of the saturated range where it is flat.

    Notes
    -----
    The bisection runs on the integer bit patterns of non-negative float64
    values, which are ordered like the values, so it ends with adjacent floats
    after at most 64 steps whatever the scale of ``e`` (also for curves of
    infinite slope at 0, such as ``e**0.25``).
    """
    F = _output(F)
    if F.size == 0:
        return F.copy()
    hi = np.ones_like(F)
    while True:
        low = forward(hi) < F
        if not np.any(low):
            break
        if hi.max() >= e_max:
            raise InputError(f"`F`: values {np.unique(F[low])[:5].tolist()} are never reached")
        hi = np.where(low, hi * 2.0, hi)
    lo_bits = np.zeros(F.shape, dtype=np.int64)
    hi_bits = hi.view(np.int64).copy()
    while np.any(hi_bits - lo_bits > 1):
        mid_bits = lo_bits + (hi_bits - lo_bits) // 2
        below = forward(mid_bits.view(np.float64)) < F
        lo_bits = np.where(below, mid_bits, lo_bits)
        hi_bits = np.where(below, hi_bits, mid_bits)
    at_zero = forward(np.zeros_like(F)) >= F
    return np.where(at_zero, 0.0, hi_bits.view(np.float64))


@dataclass(frozen=True)
class ResponseModel:
    """One family of response curves: its forward map and (optional) exact inverse.

    Parameters
    ----------
    forward : callable
        ``forward(e, **params) -> F``.
    inverse : callable or None
        ``inverse(F, **params) -> e``; ``None`` falls back to
        :func:`numeric_inverse`.
    defaults : mapping
        The parameters and their default values; any other key is refused.
    max_output : callable
        ``max_output(**params) -> float``: ``F(∞)``, the saturation output.
    resolve : callable or None
        ``resolve(params) -> params``: completes a record's parameters once
        (the ``"emor"`` kind draws its coefficients from its seed).
    forward_valid : callable or None
        ``forward_valid(e, **params) -> F`` for float64 exposures already known to be
        ``>= 0`` without NaN, the same values as ``forward`` without its checks (the
        simulator's frames); ``None``: ``forward``.
    """

    forward: Callable[..., np.ndarray]
    inverse: Callable[..., np.ndarray] | None
    defaults: Mapping[str, Any]
    max_output: Callable[..., float] = lambda **_: 1.0  # noqa: E731
    resolve: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    forward_valid: Callable[..., np.ndarray] | None = None


RESPONSE_MODELS: dict[str, ResponseModel] = {
    "linear": ResponseModel(response_linear, response_linear_inverse, {"knee": None}),
    "gamma": ResponseModel(response_gamma, response_gamma_inverse, {"gamma": 1.0 / 2.2}),
    "s_curve": ResponseModel(
        response_s_curve,
        response_s_curve_inverse,
        {"contrast": 1.5, "pivot": 0.25},
        forward_valid=_s_curve_valid,
    ),
    "table": ResponseModel(
        response_table_forward,
        response_table_inverse,
        {"x": None, "y": None},
        lambda **p: float(_table(p["x"], p["y"])[1][-1]),
    ),
    "emor": ResponseModel(
        response_emor,
        response_emor_inverse,
        {"coefficients": None, "seed": None, "n_components": 5, "knee": None},
        resolve=_resolve_emor,
    ),
    "film": ResponseModel(
        response_film,
        response_film_inverse,
        {"toe": 1.6, "shoulder": 1.0, "pivot": 0.3, "knee": None},
    ),
}
"""Registry of response families: ``kind → ResponseModel``."""


def _jsonable(value: Any) -> Any:
    """Parameters as JSON-friendly immutable values (arrays become tuples of floats)."""
    if isinstance(value, np.ndarray | list | tuple):
        return tuple(float(v) for v in np.asarray(value, dtype=np.float64).ravel())
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass(frozen=True, eq=True)
class ResponseCurve:
    """A ground-truth response curve: a family name and its parameters.

    Parameters
    ----------
    kind : str
        A key of :data:`RESPONSE_MODELS` (``"linear"``, ``"gamma"``,
        ``"s_curve"``, ``"table"``, ``"emor"``, ``"film"``), case-insensitive.
        An ``"emor"`` record may give a ``seed`` (and ``n_components``)
        instead of ``coefficients``: they are drawn once
        (:func:`draw_emor_coefficients`) and kept in ``params``.
    params : dict
        Keyword parameters of the family; missing ones take their defaults,
        unknown ones are refused. Arrays are stored as tuples of floats.

    Examples
    --------
    >>> curve = ResponseCurve("gamma", {"gamma": 0.5})
    >>> float(curve(0.25)), float(curve.inverse(0.5))
    (0.5, 0.25)
    """

    kind: str
    params: dict[str, Any]

    def __post_init__(self) -> None:
        kind = validate_method(self.kind, RESPONSE_MODELS, "response")
        model = RESPONSE_MODELS[kind]
        if not isinstance(self.params, Mapping):
            raise InputError(f"`params` must be a mapping, got {type(self.params).__name__}")
        unknown = set(self.params) - set(model.defaults)
        if unknown:
            raise InputError(
                f"`params`: unknown parameter(s) {sorted(unknown)} for response {kind!r}; "
                f"valid: {sorted(model.defaults)}"
            )
        params = {k: _jsonable(self.params.get(k, v)) for k, v in model.defaults.items()}
        missing = [k for k, v in params.items() if v is None and k in ("x", "y")]
        if missing:
            raise InputError(f"`params`: response {kind!r} needs {missing}")
        if model.resolve is not None:
            params = {k: _jsonable(v) for k, v in model.resolve(params).items()}
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "params", params)
        # validate the parameters once, by evaluating the curve
        self(np.array([0.0, 0.5, 1.0]))

    def __hash__(self) -> int:
        return hash((self.kind, tuple(sorted(self.params.items()))))

    def __call__(self, e: Any) -> np.ndarray:
        """``F(e)``: normalised output in ``[0, 1]`` of normalised exposure ``e >= 0``."""
        return RESPONSE_MODELS[self.kind].forward(e, **self.params)

    def forward_valid(self, e: np.ndarray) -> np.ndarray:
        """``F(e)`` of float64 exposures its caller made (``>= 0``, no NaN): the values of
        :meth:`__call__` without its input checks, where the family has such a path."""
        model = RESPONSE_MODELS[self.kind]
        forward = model.forward if model.forward_valid is None else model.forward_valid
        return forward(e, **self.params)

    def inverse(self, F: Any) -> np.ndarray:
        """Exact inverse ``e = F⁻¹(F)`` for ``F`` in ``[0, max_output]``, vectorised.

        Where the curve is flat (``F = max_output``), returns the smallest
        exposure that reaches it (the saturation exposure).
        """
        model = RESPONSE_MODELS[self.kind]
        if model.inverse is not None:
            return model.inverse(F, **self.params)
        return numeric_inverse(lambda e: model.forward(e, **self.params), F)

    @property
    def max_output(self) -> float:
        """``F(∞)``: the output of a saturated pixel (1 for the analytic families)."""
        return float(RESPONSE_MODELS[self.kind].max_output(**self.params))

    @property
    def saturation_exposure(self) -> float:
        """Smallest normalised exposure at which the output saturates."""
        return float(self.inverse(self.max_output))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"kind": ..., "params": {...}}``."""
        return {"kind": self.kind, "params": {k: _to_json(v) for k, v in self.params.items()}}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ResponseCurve:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError(f"`data` must be a mapping with a 'kind', got {data!r}")
        return cls(str(data["kind"]), dict(data.get("params", {})))

    @classmethod
    def linear(cls, knee: float | None = None) -> ResponseCurve:
        """Shortcut for ``ResponseCurve("linear", {"knee": knee})``."""
        return cls("linear", {"knee": knee})

    @classmethod
    def gamma(cls, gamma: float = 1.0 / 2.2) -> ResponseCurve:
        """Shortcut for ``ResponseCurve("gamma", {"gamma": gamma})``."""
        return cls("gamma", {"gamma": gamma})

    @classmethod
    def emor(
        cls,
        seed: int | None = None,
        n_components: int = 5,
        coefficients: Any = None,
        knee: float | None = None,
    ) -> ResponseCurve:
        """An EMoR response: drawn from ``seed`` or given by its ``coefficients``."""
        return cls(
            "emor",
            {
                "coefficients": coefficients,
                "seed": seed,
                "n_components": n_components,
                "knee": knee,
            },
        )

    @classmethod
    def film(
        cls, toe: float = 1.6, shoulder: float = 1.0, pivot: float = 0.3, knee: float | None = None
    ) -> ResponseCurve:
        """A film characteristic curve (:func:`response_film`)."""
        return cls("film", {"toe": toe, "shoulder": shoulder, "pivot": pivot, "knee": knee})

    @classmethod
    def s_curve(cls, contrast: float = 1.5, pivot: float = 0.25) -> ResponseCurve:
        """Shortcut for ``ResponseCurve("s_curve", {"contrast": ..., "pivot": ...})``."""
        return cls("s_curve", {"contrast": contrast, "pivot": pivot})


def _to_json(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
