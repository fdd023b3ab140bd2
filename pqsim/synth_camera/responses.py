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
- :class:`ResponseCurve`: a frozen ``(kind, params)`` record, callable, with an
  exact vectorised :meth:`~ResponseCurve.inverse`.
- :data:`RESPONSE_MODELS`: the registry ``kind → ResponseModel``.

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``: eq. 1 (model),
   eq. 5 and 7 (log inverse response ``g_λ``), §3.2.2 (exposure and response).
.. [DM97] P. E. Debevec and J. Malik, "Recovering high dynamic range radiance
   maps from photographs", SIGGRAPH 1997, doi:10.1145/258734.258884.
.. [GN04] M. D. Grossberg and S. K. Nayar, "Modeling the space of camera
   response functions", IEEE TPAMI 26(10), 2004, doi:10.1109/TPAMI.2004.88
   (real response curves are monotonic, most are S-shaped in log exposure).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_array, check_positive, validate_method

__all__ = [
    "response_linear",
    "response_linear_inverse",
    "response_gamma",
    "response_gamma_inverse",
    "response_s_curve",
    "response_s_curve_inverse",
    "response_table",
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
    e = _exposure(e)
    c, p = _s_params(contrast, pivot)
    x = np.minimum(e, 1.0)
    out = np.ones_like(x)
    inside = x < 1.0
    xi = x[inside]
    # log r, computed so that 0 maps to -inf without warnings
    with np.errstate(divide="ignore"):
        log_r = np.log(xi) - np.log1p(-xi) + math.log((1.0 - p) / p)
    out[inside] = _logistic(c * log_r)
    return out


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
    """

    forward: Callable[..., np.ndarray]
    inverse: Callable[..., np.ndarray] | None
    defaults: Mapping[str, Any]
    max_output: Callable[..., float] = lambda **_: 1.0  # noqa: E731


RESPONSE_MODELS: dict[str, ResponseModel] = {
    "linear": ResponseModel(response_linear, response_linear_inverse, {"knee": None}),
    "gamma": ResponseModel(response_gamma, response_gamma_inverse, {"gamma": 1.0 / 2.2}),
    "s_curve": ResponseModel(
        response_s_curve, response_s_curve_inverse, {"contrast": 1.5, "pivot": 0.25}
    ),
    "table": ResponseModel(
        response_table_forward,
        response_table_inverse,
        {"x": None, "y": None},
        lambda **p: float(_table(p["x"], p["y"])[1][-1]),
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
        ``"s_curve"``, ``"table"``), case-insensitive.
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
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "params", params)
        # validate the parameters once, by evaluating the curve
        self(np.array([0.0, 0.5, 1.0]))

    def __hash__(self) -> int:
        return hash((self.kind, tuple(sorted(self.params.items()))))

    def __call__(self, e: Any) -> np.ndarray:
        """``F(e)``: normalised output in ``[0, 1]`` of normalised exposure ``e >= 0``."""
        return RESPONSE_MODELS[self.kind].forward(e, **self.params)

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
    def s_curve(cls, contrast: float = 1.5, pivot: float = 0.25) -> ResponseCurve:
        """Shortcut for ``ResponseCurve("s_curve", {"contrast": ..., "pivot": ...})``."""
        return cls("s_curve", {"contrast": contrast, "pivot": pivot})


def _to_json(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
