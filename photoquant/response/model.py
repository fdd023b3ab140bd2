"""The response model every response method returns: ``g_λ = ln f_λ⁻¹`` tabulated per channel.

A recovered response is stored as a table of ``g`` at increasing pixel
values (``levels``), linear in between, per channel, with the channel's
saturation level, the lowest level at which the data measured it
(``valid_min``) and the black level (the value of no light). Parametric
methods (gamma, polynomial, EMoR) tabulate themselves on the same grid and
keep their parameters in ``params``, so the merge, the correction and the
camera format need to know one representation only.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [PQ] The photoquantity paper, §5.2.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from photoquant._checks import check_array
from photoquant.errors import InputError

__all__ = ["ResponseModel"]

_MAX_LOG_SPAN = 60.0
"""Largest ``g(top) − g(bottom)`` accepted (ln units): a factor ``e^60 ≈ 10^26``
between the darkest and brightest level of one exposure, far beyond any
sensor or film; a larger span is a corrupted table (its ``exp`` overflows)."""


@dataclass(frozen=True, eq=False)
class ResponseModel:
    """A camera response per channel, ``g_λ = ln f_λ⁻¹`` (without colour balance).

    Parameters
    ----------
    method : str
        The response method that produced it.
    levels : ndarray, shape (L,)
        Increasing pixel values at which ``g`` is tabulated.
    log_inverse_response : ndarray, shape (C, L)
        ``g_λ`` at ``levels`` (natural log, any additive gauge), finite and
        non-decreasing.
    saturation_level : ndarray, shape (C,)
        Clipping level of each channel; values at or above it carry no information.
    valid_min : ndarray, shape (C,), optional
        Lowest value at which the response was measured; the merge may give
        lower values no weight. Default: the first level.
    black_level : ndarray, shape (C,), optional
        The value of no light (the merge's hat weights are anchored there).
        Default 0.
    params : dict
        The method's own parameters (e.g. a gamma or EMoR coefficients), for
        the record; the table is what is applied.
    covariance_factor : ndarray, shape (C, R, L), optional
        The uncertainty of ``g``: per channel a factor ``F`` with
        ``Cov(g) ≈ Fᵀ F`` at ``levels``, relative to the level where the fit
        fixed its gauge (:mod:`photoquant.response.covariance`). ``None``: not
        estimated.
    covariance_diagonal : ndarray, shape (C, L), optional
        ``Var(g)`` at each level in full (``Fᵀ F`` keeps the leading part of
        the covariance; the rest of its diagonal is treated as uncorrelated
        between levels). Given with ``covariance_factor``.
    covariance_reference : str, optional
        What the covariance is relative to: ``None``, the level where the fit
        fixed its gauge; otherwise a description of the reference whose
        error was removed (:meth:`covariance_relative_to`, e.g. the white
        chart's merged value).
    """

    method: str
    levels: np.ndarray
    log_inverse_response: np.ndarray
    saturation_level: np.ndarray
    valid_min: np.ndarray | None = None
    black_level: np.ndarray | None = None
    params: dict[str, Any] = field(default_factory=dict)
    covariance_factor: np.ndarray | None = None
    covariance_diagonal: np.ndarray | None = None
    covariance_reference: str | None = None
    # tables derived from the response, made once (e.g. the exposure screen's lookups)
    _cache: dict[str, Any] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        levels = check_array(self.levels, "levels", ndim=1, kind="iuf", finite=True).astype(
            np.float64
        )
        if levels.size < 2 or np.any(np.diff(levels) <= 0):
            raise InputError("the response's `levels` must be at least two increasing values")
        g = check_array(self.log_inverse_response, "log_inverse_response", ndim=2, kind="iuf")
        g = g.astype(np.float64)
        if g.shape[1] != levels.size:
            raise InputError(
                f"`log_inverse_response` has {g.shape[1]} values per channel, `levels` {levels.size}"
            )
        if not np.all(np.isfinite(g)):
            raise InputError("`log_inverse_response` contains NaN or infinite values")
        n_ch = g.shape[0]
        span = float(np.max(g.max(axis=1) - g.min(axis=1))) if g.size else 0.0
        if span > _MAX_LOG_SPAN:
            raise InputError(
                f"the response spans {span:.3g} in ln exposure (a factor e^{span:.3g}) between "
                f"its lowest and highest level; no camera's does (at most {_MAX_LOG_SPAN:g})"
            )
        n_ch = g.shape[0]
        if n_ch < 1:
            raise InputError("`log_inverse_response` has no channel")
        if np.any(np.diff(g, axis=1) < 0):
            bad = sorted({int(c) for c in np.nonzero(np.diff(g, axis=1) < 0)[0]})
            raise InputError(
                f"the response of channel(s) {bad} decreases: `log_inverse_response` "
                "must be non-decreasing"
            )
        sat = check_array(
            self.saturation_level, "saturation_level", shape=(n_ch,), kind="iuf", finite=True
        ).astype(np.float64)
        lo, hi = levels[0], levels[-1]
        if np.any(sat <= lo) or np.any(sat > hi):
            raise InputError(
                f"`saturation_level` {sat.tolist()} must lie in ({lo:g}, {hi:g}], the levels' range"
            )
        black = self._per_channel(self.black_level, "black_level", n_ch, lo)
        if np.any(black >= sat):
            raise InputError(
                f"`black_level` {black.tolist()} must lie below `saturation_level` {sat.tolist()}"
            )
        valid_min = self._per_channel(self.valid_min, "valid_min", n_ch, lo)
        if np.any(valid_min >= sat):
            raise InputError(
                f"`valid_min` {valid_min.tolist()} must lie below `saturation_level` {sat.tolist()}"
            )
        if not isinstance(self.method, str) or not self.method:
            raise InputError(f"`method` must be a method name, got {self.method!r}")
        if not isinstance(self.params, dict):
            raise InputError(f"`params` must be a dict, got {type(self.params).__name__}")
        if self.covariance_factor is not None:
            factor = check_array(
                self.covariance_factor, "covariance_factor", ndim=3, kind="iuf", finite=True
            ).astype(np.float64)
            if factor.shape[0] != n_ch or factor.shape[2] != levels.size or factor.shape[1] < 1:
                raise InputError(
                    f"`covariance_factor` must be (C, R, L) = ({n_ch}, R, {levels.size}), "
                    f"got {factor.shape}"
                )
            object.__setattr__(self, "covariance_factor", factor)
        if (self.covariance_diagonal is None) != (self.covariance_factor is None):
            raise InputError("`covariance_factor` and `covariance_diagonal` go together")
        if self.covariance_diagonal is not None:
            diag = check_array(
                self.covariance_diagonal,
                "covariance_diagonal",
                shape=(n_ch, levels.size),
                kind="iuf",
                finite=True,
            ).astype(np.float64)
            if np.any(diag < 0):
                raise InputError("`covariance_diagonal` must be non-negative (variances)")
            object.__setattr__(self, "covariance_diagonal", diag)
        if self.covariance_reference is not None and (
            not isinstance(self.covariance_reference, str) or self.covariance_factor is None
        ):
            raise InputError(
                "`covariance_reference` must be a description (str) of a covariance's reference, "
                f"given with the covariance; got {self.covariance_reference!r}"
            )
        for name, value in [
            ("levels", levels),
            ("log_inverse_response", g),
            ("saturation_level", sat),
            ("valid_min", valid_min),
            ("black_level", black),
            ("params", dict(self.params)),
        ]:
            object.__setattr__(self, name, value)

    @staticmethod
    def _per_channel(value: Any, name: str, n_ch: int, default: float) -> np.ndarray:
        if value is None:
            return np.full(n_ch, float(default))
        arr = np.asarray(value, dtype=np.float64) if np.isscalar(value) else value
        arr = check_array(arr, name, kind="iuf", finite=True).astype(np.float64)
        if arr.ndim == 0:
            return np.full(n_ch, float(arr))
        if arr.shape != (n_ch,):
            raise InputError(f"`{name}` must have shape ({n_ch},), got {arr.shape}")
        return arr

    @property
    def n_channels(self) -> int:
        return int(self.log_inverse_response.shape[0])

    def log_inverse(self, values: np.ndarray) -> np.ndarray:
        """``g_λ(values)`` for pixel values ``(..., C)``, linear between levels (float64)."""
        values = np.asarray(values)
        if values.shape[-1:] != (self.n_channels,):
            raise InputError(
                f"`values` must have {self.n_channels} channels last, got shape {values.shape}"
            )
        out = np.empty(values.shape, dtype=np.float64)
        for ch in range(self.n_channels):
            out[..., ch] = np.interp(values[..., ch], self.levels, self.log_inverse_response[ch])
        return out

    def forward(self, log_exposure: np.ndarray) -> np.ndarray:
        """The response itself, ``f_λ``: pixel values ``(..., C)`` from ``ln`` exposures ``(..., C)``.

        The inverse of :meth:`log_inverse` on its increasing stretches; clipped
        to the table's first and last level. Used to predict a frame from a
        merged photoquantity (cross-validation).
        """
        log_exposure = np.asarray(log_exposure, dtype=np.float64)
        out = np.empty(log_exposure.shape, dtype=np.float64)
        for ch in range(self.n_channels):
            g = self.log_inverse_response[ch]
            # flat stretches of g map to their first level (np.interp needs increasing xp)
            keep = np.concatenate([[True], np.diff(g) > 0])
            out[..., ch] = np.interp(log_exposure[..., ch], g[keep], self.levels[keep])
        return out

    def balanced(self, balance: np.ndarray) -> ResponseModel:
        """The response with the colour balance folded in, ``g_λ + ln a_λ`` (§5.3)."""
        a = check_array(balance, "balance", shape=(self.n_channels,), kind="iuf", finite=True)
        if np.any(a <= 0):
            raise InputError(f"balance factors must be positive, got {np.asarray(a).tolist()}")
        return ResponseModel(
            method=self.method,
            levels=self.levels,
            log_inverse_response=self.log_inverse_response + np.log(a.astype(np.float64))[:, None],
            saturation_level=self.saturation_level,
            valid_min=self.valid_min,
            black_level=self.black_level,
            params=self.params,
            covariance_factor=self.covariance_factor,
            covariance_diagonal=self.covariance_diagonal,
            covariance_reference=self.covariance_reference,
        )

    def covariance_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """``(F, D)``: the covariance's factor ``(C, R, L)`` and the rest of its diagonal
        ``(C, L)``, uncorrelated between levels (``Cov(g) = Fᵀ F + diag(D)``).

        Raises
        ------
        InputError
            If the response carries no covariance.
        """
        if self.covariance_factor is None or self.covariance_diagonal is None:
            raise InputError(
                f"the response ({self.method!r}) carries no covariance: its method does not "
                "estimate one"
            )
        factor = self.covariance_factor
        return factor, np.clip(self.covariance_diagonal - np.sum(factor**2, axis=1), 0.0, None)

    def covariance_relative_to(
        self, loadings: np.ndarray, rest: np.ndarray, reference: str
    ) -> ResponseModel:
        """The response with the covariance of ``g − g_ref``: ``g``'s error less a
        reference's, the same error of ``g`` entering both.

        ``g_ref``'s error is ``Σ_r B_r ξ_r + η_ref`` in terms of the factor's
        independent variates ``ξ_r`` (``loadings`` ``B``, shape ``(C, R)``) and
        an uncorrelated rest of variance ``rest`` ``(C,)`` — e.g. the merge of
        the white chart that sets the colour balance
        (:func:`photoquant.merge.uncertainty.response_error_of_merge_Debevec1997`).
        The factor becomes ``F_r − B_r`` and gains one row, ``√rest`` at every
        level (the reference's own rest, common to all of them); the
        uncorrelated part of the diagonal is kept. ``g`` itself is unchanged:
        only the gauge of its uncertainty moves, to the reference.
        """
        old, own = self.covariance_parts()
        n_ch, n_rows, n_lv = old.shape
        b = check_array(loadings, "loadings", shape=(n_ch, n_rows), kind="f", finite=True)
        v = check_array(rest, "rest", shape=(n_ch,), kind="f", finite=True)
        if np.any(v < 0):
            raise InputError(f"`rest` must be non-negative (variances), got {v.tolist()}")
        common = np.broadcast_to(np.sqrt(v)[:, None, None], (n_ch, 1, n_lv))
        factor = np.concatenate([old - b[:, :, None], common], axis=1)
        return dataclasses.replace(
            self,
            covariance_factor=factor,
            covariance_diagonal=own + np.sum(factor**2, axis=1),
            covariance_reference=str(reference),
        )

    def log_inverse_std(self) -> np.ndarray | None:
        """Standard uncertainty of ``g`` at ``levels``, ``(C, L)`` (``None``: not estimated)."""
        if self.covariance_diagonal is None:
            return None
        return np.sqrt(self.covariance_diagonal)

    # -- persistence -----------------------------------------------------------------
    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """``(params, images)`` for the camera file: everything is small, no image."""
        extra: dict[str, Any] = {}
        if self.covariance_factor is not None:
            extra["covariance_factor"] = self.covariance_factor.tolist()
            extra["covariance_diagonal"] = cast(np.ndarray, self.covariance_diagonal).tolist()
            extra["covariance_factor_quantity"] = (
                "F per channel (C, R, L): Cov(g) = F^T F at levels, relative to "
                + (self.covariance_reference or "the gauge level")
            )
            if self.covariance_reference is not None:
                extra["covariance_reference"] = self.covariance_reference
        return (
            {
                "quantity": "g = ln f^-1 (natural log, without balance), linear between levels",
                "levels": self.levels.tolist(),
                "log_inverse_response": self.log_inverse_response.tolist(),
                "saturation_level": self.saturation_level.tolist(),
                "valid_min": cast(np.ndarray, self.valid_min).tolist(),
                "black_level": cast(np.ndarray, self.black_level).tolist(),
                "method_params": self.params,
                **extra,
            },
            {},
        )

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> ResponseModel:
        """Rebuild from :meth:`to_params` (``images`` unused)."""
        del images

        def optional(name: str) -> np.ndarray | None:
            return _float_array(params[name], name) if name in params else None

        return cls(
            method=method,
            levels=_float_array(params["levels"], "levels"),
            log_inverse_response=_float_array(
                params["log_inverse_response"], "log_inverse_response"
            ),
            saturation_level=_float_array(params["saturation_level"], "saturation_level"),
            valid_min=optional("valid_min"),
            black_level=optional("black_level"),
            params=dict(params.get("method_params") or {}),
            covariance_factor=optional("covariance_factor"),
            covariance_diagonal=optional("covariance_diagonal"),
            covariance_reference=_optional_text(params, "covariance_reference"),
        )


def _optional_text(params: dict[str, Any], name: str) -> str | None:
    """``params[name]`` where it is a string, ``None`` where absent; else an error naming it."""
    value = params.get(name)
    if value is not None and not isinstance(value, str):
        raise InputError(f"`{name}` must be a string, got {type(value).__name__}")
    return value


def _float_array(value: Any, name: str) -> np.ndarray:
    """A JSON list as a float array; anything else is an error naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, list | int | float):
        raise InputError(
            f"`{name}` must be a number or a list of numbers, got {type(value).__name__}"
        )
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must hold numbers only") from None
    if arr.dtype == object:
        raise InputError(f"`{name}` is ragged")
    return arr
