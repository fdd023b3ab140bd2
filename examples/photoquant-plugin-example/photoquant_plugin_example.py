"""An example photoquant plug-in: one response method and one vignetting model.

- ``"Linear (example)"`` (step ``"response"``): a linear sensor, ``g = ln(z − b)``
  with ``b`` the black level, no fit at all. It returns photoquant's shared
  :class:`photoquant.ResponseModel`, tabulated like every response.
- ``"Radial polynomial (example)"`` (step ``"vignetting"``):
  ``v(r) = 1 + k1 r² + k2 r⁴`` per channel, ``r`` the distance from the image
  centre (1 at the corners), fitted by linear least squares from the
  correspondences. Its model is a class of its own,
  :class:`RadialPolynomialVignetting`, which the camera folder stores and
  :func:`photoquant.load_camera` rebuilds.

The distribution declares the entry point ``example =
"photoquant_plugin_example:methods"`` in the group ``photoquant.methods``;
photoquant calls :func:`methods` once and registers what it returns. After
``pip install .`` the methods are selectable by name::

    photoquant calibrate capture.json -o camera --method response="Linear (example)"
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

import photoquant as pq
from photoquant.vignetting import VignettingData, VignettingModel

__all__ = [
    "LinearResponseOptions",
    "characterise_response_linear",
    "RadialPolynomialOptions",
    "RadialPolynomialVignetting",
    "characterise_vignetting_radial_polynomial",
    "methods",
]

RESPONSE_NAME = "Linear (example)"
VIGNETTING_NAME = "Radial polynomial (example)"


# ---------------------------------------------------------------------------
# Response: g = ln(z − b)
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearResponseOptions:
    """Options of ``"Linear (example)"``.

    Attributes
    ----------
    black_level : float
        The value of no light ``b`` (DN), the same in every channel.
    floor : float
        ``g`` is held at ``ln(floor)`` for ``z − b < floor`` (DN), where a
        linear sensor's values are noise: ``g`` stays finite and non-decreasing.
    """

    black_level: float = 0.0
    floor: float = 0.5

    def __post_init__(self) -> None:
        for name in ("black_level", "floor"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise pq.PhotoquantError(f"`{name}` must be a number, got {value!r}")
        if not self.black_level >= 0:
            raise pq.PhotoquantError(f"`black_level` must be ≥ 0, got {self.black_level!r}")
        if not self.floor > 0:
            raise pq.PhotoquantError(f"`floor` must be positive, got {self.floor!r}")


def characterise_response_linear(
    stack: pq.ExposureStack, options: LinearResponseOptions | None, rng: Any
) -> pq.StepFit[pq.ResponseModel]:
    """The response step's signature: ``fit(stack, options, rng) -> StepFit[ResponseModel]``.

    Nothing is fitted: ``g_λ(z) = ln max(z − b, floor)`` at every integer
    value of the stack's bit depth, saturating at the stack's levels.
    """
    del rng  # deterministic
    opts = options or LinearResponseOptions()
    c_max = 2**stack.bit_depth - 1
    if not opts.black_level + opts.floor < c_max:
        raise pq.PhotoquantError(
            f"`black_level` {opts.black_level:g} leaves no value below {c_max} for a "
            f"{stack.bit_depth}-bit camera"
        )
    levels = np.arange(c_max + 1, dtype=np.float64)
    g = np.log(np.maximum(levels - opts.black_level, opts.floor))
    n_ch = stack.n_channels
    model = pq.ResponseModel(
        method=RESPONSE_NAME,
        levels=levels,
        log_inverse_response=np.tile(g, (n_ch, 1)),
        saturation_level=np.asarray(stack.saturation_level, dtype=np.float64),
        valid_min=np.full(n_ch, opts.black_level + opts.floor),
        black_level=np.full(n_ch, opts.black_level),
        params={"black_level": opts.black_level, "floor": opts.floor},
    )
    return pq.StepFit(model, {"note": "linear sensor assumed: nothing fitted"})


# ---------------------------------------------------------------------------
# Vignetting: v(r) = 1 + k1 r² + k2 r⁴
# ---------------------------------------------------------------------------


def radius_squared(image_shape: tuple[int, int]) -> np.ndarray:
    """``r²`` at every pixel centre, ``(H, W)``: 0 at the centre, 1 at the corners."""
    h, w = image_shape
    y = (np.arange(h) + 0.5) / h - 0.5
    x = (np.arange(w) + 0.5) / w - 0.5
    return (x[None, :] ** 2 + y[:, None] ** 2) / 0.5


@dataclass(frozen=True, eq=False)
class RadialPolynomialVignetting(VignettingModel):
    """``v(r) = 1 + k1 r² + k2 r⁴`` per channel (``coefficients`` ``(C, 2)``)."""

    method: str
    coefficients: np.ndarray

    def __post_init__(self) -> None:
        k = np.asarray(self.coefficients, dtype=np.float64)
        if k.ndim != 2 or k.shape[1] != 2 or not np.all(np.isfinite(k)):
            raise pq.PhotoquantError(
                f"`coefficients` must be finite (k1, k2) per channel, shape (C, 2), got {k.shape}"
            )
        object.__setattr__(self, "coefficients", k)

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        """``v`` on the pixel grid, ``(H, W, C)``."""
        r2 = radius_squared(image_shape)[..., None]
        v: np.ndarray = 1.0 + self.coefficients[:, 0] * r2 + self.coefficients[:, 1] * r2**2
        return v

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """JSON parameters (no image) for the camera folder."""
        return {"coefficients": self.coefficients.tolist()}, {}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> RadialPolynomialVignetting:
        """Rebuild from :meth:`to_params` (camera files are untrusted: checked)."""
        del images
        values = params["coefficients"]
        if not isinstance(values, list):
            raise pq.PhotoquantError(f"`coefficients` must be a list, got {values!r}")
        try:
            return cls(method, np.asarray(values, dtype=np.float64))
        except (TypeError, ValueError):
            raise pq.PhotoquantError(
                "`coefficients` must be numbers, (k1, k2) per channel"
            ) from None


@dataclass(frozen=True)
class RadialPolynomialOptions:
    """Options of ``"Radial polynomial (example)"``.

    Attributes
    ----------
    min_pairs : int
        Fewest usable pairs of observations per channel.
    """

    min_pairs: int = 10

    def __post_init__(self) -> None:
        if isinstance(self.min_pairs, bool) or not isinstance(self.min_pairs, int):
            raise pq.PhotoquantError(f"`min_pairs` must be an integer, got {self.min_pairs!r}")
        if self.min_pairs < 2:
            raise pq.PhotoquantError(f"`min_pairs` must be at least 2, got {self.min_pairs}")


def characterise_vignetting_radial_polynomial(
    data: VignettingData, options: RadialPolynomialOptions | None
) -> pq.StepFit[RadialPolynomialVignetting]:
    """The vignetting step's signature: ``fit(data, options) -> StepFit[VignettingModel]``.

    A scene point seen at ``r_i`` and ``r_j`` with values ``c_i``, ``c_j``
    gives ``c_i v(r_j) − c_j v(r_i) = 0``, linear in ``(k1, k2)``; each
    equation is divided by ``(c_i + c_j) / 2`` so that bright points do not
    dominate.
    """
    opts = options or RadialPolynomialOptions()
    h, w = data.image_shape
    r2_map = radius_squared((h, w))
    n_ch = data.uniform_views[0].shape[-1]
    rows: list[list[np.ndarray]] = [[] for _ in range(n_ch)]
    rhs: list[list[float]] = [[] for _ in range(n_ch)]
    for track in data.tracks:
        obs = []
        for view, x, y in np.asarray(track, dtype=np.float64):
            xi, yi = int(round(x)), int(round(y))
            if 0 <= xi < w and 0 <= yi < h:
                obs.append((data.uniform_views[int(view)][yi, xi], r2_map[yi, xi]))
        for a in range(len(obs)):
            for b in range(a + 1, len(obs)):
                (ci, ri), (cj, rj) = obs[a], obs[b]
                for ch in range(n_ch):
                    if not (np.isfinite(ci[ch]) and np.isfinite(cj[ch])):
                        continue
                    scale = (ci[ch] + cj[ch]) / 2
                    if not scale > 0:
                        continue
                    row = np.array([ci[ch] * rj - cj[ch] * ri, ci[ch] * rj**2 - cj[ch] * ri**2])
                    rows[ch].append(row / scale)
                    rhs[ch].append(float((cj[ch] - ci[ch]) / scale))
    coefficients = np.zeros((n_ch, 2))
    n_pairs, residual_rms = [], []
    for ch in range(n_ch):
        n_pairs.append(len(rows[ch]))
        if len(rows[ch]) < opts.min_pairs:
            raise pq.PhotoquantError(
                f"channel {ch}: {len(rows[ch])} usable pairs of correspondences, "
                f"the radial polynomial fit needs at least {opts.min_pairs}"
            )
        design, target = np.stack(rows[ch]), np.asarray(rhs[ch])
        coefficients[ch] = np.linalg.lstsq(design, target, rcond=None)[0]
        residual_rms.append(float(np.sqrt(np.mean((design @ coefficients[ch] - target) ** 2))))
    model = RadialPolynomialVignetting(VIGNETTING_NAME, coefficients)
    model.check_positive((h, w))
    report = {
        "n_tracks": len(data.tracks),
        "n_tracks_given": len(data.tracks),
        "n_pairs": n_pairs,
        "residual_rms": residual_rms,
    }
    return pq.StepFit(model, report)


# ---------------------------------------------------------------------------
# The entry point
# ---------------------------------------------------------------------------


def methods() -> list[pq.Method]:
    """The entry point: the plug-in's methods (photoquant registers them once)."""
    return [
        pq.Method(
            "response",
            RESPONSE_NAME,
            characterise_response_linear,
            options=LinearResponseOptions,
            reference="example: an ideal linear sensor",
        ),
        pq.Method(
            "vignetting",
            VIGNETTING_NAME,
            characterise_vignetting_radial_polynomial,
            options=RadialPolynomialOptions,
            model=RadialPolynomialVignetting,
            reference="example: even polynomial in the radius",
        ),
    ]
