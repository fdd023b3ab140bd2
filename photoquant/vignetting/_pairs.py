"""Shared machinery of the vignetting fits from correspondences (private).

A scene point ``s`` seen in views ``i`` and ``j`` gives sensor-uniformised
values ``c_is = v_is l_s`` and ``c_js = v_js l_s``, so ``c_is v_js − c_js v_is = 0``
for the true vignetting ``v``. Every parametric model fitted from
correspondences minimises the sum of squares of these pair residuals (weighted
by the inverse mean of the track, and divided by the RMS of ``v`` so that the
objective does not reward shrinking ``v``) by Levenberg–Marquardt, exactly as
the extended Goldman–Chen fit of :mod:`photoquant.vignetting.extended_goldman_chen`
does; this module holds that fit for any model given as a :class:`PairModel`.

The observations are validated and paired as in the extended Goldman–Chen fit
(its private ``_pairs_within_tracks`` and ``_spread`` are reused); the trust
checks are the same: solver convergence, ``v > 0`` over every pixel centre of
the image, no collapse towards ``v = 0`` and a bounded first-order map
uncertainty.

With ``view_gains`` every view but the reference gets a free gain ``a_j``
(residual ``a_i c_is v_js − a_j c_js v_is``), fitted with the model and
reported: a per-view exposure error (:mod:`photoquant.exposure`) is then not
read as vignetting. Identifiability as in
:func:`photoquant.vignetting.extended_goldman_chen.fit_vignetting_ExtendedGoldmanChen`
(Notes): a gain is constant over its view, the vignetting ratio of a track
varies with where the point lies — except for a ramp ``exp(a·x)`` of ``v``,
which views related by shifts cannot tell from gains: a centred model
excludes it, a free centre reproduces it to second order.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_array, check_int, check_positive
from photoquant.errors import CalibrationError, InputError
from photoquant.vignetting.base import MAX_FALLOFF, VignettingData, check_view_gains_option
from photoquant.vignetting.extended_goldman_chen import (
    _check_image_shape,
    _pairs_within_tracks,
    _parameter_covariance,
    _solve_pairs,
    _spread,
    _view_gain_columns,
    view_gain_report,
)

__all__ = [
    "PairModel",
    "PairObservations",
    "PairFitResult",
    "PairFitOptions",
    "pair_observations",
    "fit_pair_model",
    "sample_tracks",
    "pixel_grid",
]


@dataclass(frozen=True)
class PairModel:
    """A vignetting model as the pair fit needs it, for one channel.

    Attributes
    ----------
    name : str
        Shown in messages.
    parameter_names : tuple of str
        One name per parameter.
    value : callable
        ``value(p, x_n, y_n) -> v``, broadcasting over ``x_n`` and ``y_n``.
    value_and_jacobian : callable
        ``(p, x_n, y_n) -> (v (N,), ∂v/∂p (N, P))`` for 1-D coordinates.
    linear_start : callable
        ``(x_n, y_n) -> (basis (N, 3), tail (P − 3,))``: the model at the start
        is ``v = 1 + basis @ q`` (linear in ``q``, the first three parameters)
        and the remaining parameters are ``tail``.
    """

    name: str
    parameter_names: tuple[str, ...]
    value: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    value_and_jacobian: Callable[
        [np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]
    ]
    linear_start: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]

    @property
    def n_params(self) -> int:
        return len(self.parameter_names)


@dataclass(frozen=True)
class PairObservations:
    """Usable observations and their pairs ``(a, b)`` (same track, two views)."""

    values: np.ndarray  # (n_obs, C)
    x_n: np.ndarray  # (n_obs,)
    y_n: np.ndarray
    a: np.ndarray  # (n_pairs,)
    b: np.ndarray
    obs_track: np.ndarray  # (n_obs,)
    pair_track: np.ndarray  # (n_pairs,)
    n_tracks: int
    n_pairs: int
    n_observations: int
    n_views: int
    dropped_note: str
    obs_view: np.ndarray | None = None  # (n_obs,) the view of each observation


def pair_observations(
    values: Any,
    xy: Any,
    view: Any,
    track: Any,
    image_shape: tuple[int, int],
    *,
    min_pairs: int = 30,
    min_spread: float = 0.25,
) -> PairObservations:
    """Validate observations and pair them within tracks.

    Parameters
    ----------
    values : array_like, shape (M, C)
        Linear, sensor-uniformised values at the observations.
    xy : array_like, shape (M, 2)
        Pixel coordinates ``(x, y)`` (integer values are pixel centres).
    view, track : array_like of int, shape (M,)
        View and scene-point id of each observation.
    image_shape : (H, W)
    min_pairs : int
        Fewest usable pairs accepted.
    min_spread : float
        Fewest fraction of the width and of the height that the usable
        observations must span (5th to 95th percentile).

    Raises
    ------
    InputError
        Malformed arguments (the message names the argument).
    CalibrationError
        Fewer than two views with usable observations, fewer than
        ``min_pairs`` pairs, or observations bunched in one spot.
    """
    values = check_array(values, "values", ndim=2, kind="iuf").astype(np.float64)
    m = values.shape[0]
    xy = check_array(xy, "xy", shape=(m, 2), kind="iuf", finite=True).astype(np.float64)
    view = check_array(view, "view", shape=(m,), kind="iu")
    track = check_array(track, "track", shape=(m,), kind="iu")
    h, w = _check_image_shape(image_shape)
    min_pairs = check_int(min_pairs, "min_pairs", 1)
    min_spread = check_positive(min_spread, "min_spread", allow_zero=True)
    x, y = xy[:, 0], xy[:, 1]
    if np.any((x < -0.5) | (x > w - 0.5) | (y < -0.5) | (y > h - 0.5)):
        raise InputError(
            f"`xy` has points outside the image of shape {(h, w)} "
            "(valid: -0.5 <= x <= W - 0.5 and -0.5 <= y <= H - 0.5)"
        )
    if m and np.any(view < 0):
        raise InputError("`view` must hold non-negative view indices")
    _, track_index = np.unique(track, return_inverse=True)
    if m:
        key = track_index.astype(np.int64) * (int(view.max()) + 1) + view.astype(np.int64)
        if np.unique(key).size != key.size:
            raise InputError("`track` lists the same view twice for at least one scene point")

    usable = np.all(np.isfinite(values) & (values > 0), axis=1)
    n_dropped = int(m - np.count_nonzero(usable))
    dropped_note = f"{n_dropped} of {m} observations dropped for non-finite or non-positive values"
    n_usable_views = int(np.unique(view[usable]).size)
    if n_usable_views < 2:
        raise CalibrationError(
            f"vignetting fit needs usable observations in at least 2 views (view directions); "
            f"got {n_usable_views} ({dropped_note})"
        )
    a, b, _ = _pairs_within_tracks(track_index[usable], view[usable])
    used = np.unique(np.r_[a, b])
    remap = np.full(np.count_nonzero(usable), -1)
    remap[used] = np.arange(used.size)
    a, b = remap[a], remap[b]
    obs_track = np.unique(track_index[usable][used], return_inverse=True)[1]
    n_pairs, n_obs = int(a.size), int(used.size)
    n_tracks = int(obs_track.max()) + 1 if n_obs else 0
    if n_pairs < min_pairs:
        raise CalibrationError(
            f"vignetting fit needs at least {min_pairs} pairs of observations of one scene "
            f"point in two views; only {n_pairs} usable pairs from {n_tracks} tracks "
            f"({dropped_note})"
        )
    x_n = (xy[usable][used, 0] + 0.5) / w
    y_n = (xy[usable][used, 1] + 0.5) / h
    spread_x, spread_y = _spread(x_n), _spread(y_n)
    if min(spread_x, spread_y) < min_spread:
        raise CalibrationError(
            f"vignetting fit needs observations spread over the image: the {n_obs} usable "
            f"observations span {spread_x:.1%} of the width and {spread_y:.1%} of the height "
            f"(5th to 95th percentile); at least {min_spread:.0%} of each is needed"
        )
    return PairObservations(
        values=values[usable][used],
        x_n=x_n,
        y_n=y_n,
        a=a,
        b=b,
        obs_track=obs_track,
        pair_track=obs_track[a],
        n_tracks=n_tracks,
        n_pairs=n_pairs,
        n_observations=n_obs,
        n_views=int(np.unique(view[usable][used]).size),
        dropped_note=dropped_note,
        obs_view=np.asarray(view[usable][used], dtype=np.int64),
    )


@dataclass(frozen=True)
class _Problem:
    """Residuals ``w (c_a v_b − c_b v_a) / s`` of one channel and their Jacobian.

    With view gains: ``w (a_i c_a v_b − a_j c_b v_a) / (s √(a_i a_j))``, invariant
    to a common scale of the gains (see the extended Goldman–Chen ``_PairProblem``).
    """

    model: PairModel
    x_n: np.ndarray
    y_n: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c_a: np.ndarray
    c_b: np.ndarray
    weight: np.ndarray
    scale_invariant: bool
    gain_a: np.ndarray | None = None  # gain index of each pair's views (0: fixed at 1)
    gain_b: np.ndarray | None = None
    n_gains: int = 0

    def _split(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray | float, np.ndarray]:
        """The model's parameters, ``ρ = √(a_i / a_j)`` per pair (1 without gains), all gains."""
        n = self.model.n_params
        gains = np.r_[1.0, p[n:]]
        if not self.n_gains or self.gain_a is None or self.gain_b is None:
            return p[:n], 1.0, gains
        return p[:n], np.sqrt(gains[self.gain_a] / gains[self.gain_b]), gains

    def residuals(self, p: np.ndarray) -> np.ndarray:
        q, rho, _ = self._split(p)
        v = self.model.value(q, self.x_n, self.y_n)
        u = self.weight * (rho * self.c_a * v[self.b] - self.c_b * v[self.a] / rho)
        return u / np.sqrt(np.mean(v**2)) if self.scale_invariant else u

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        q, rho, gains = self._split(p)
        v, jv = self.model.value_and_jacobian(q, self.x_n, self.y_n)
        ca = np.broadcast_to(np.asarray(rho * self.c_a), self.c_a.shape)
        cb = np.broadcast_to(np.asarray(self.c_b / rho), self.c_b.shape)
        du = self.weight[:, None] * (ca[:, None] * jv[self.b] - cb[:, None] * jv[self.a])
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
        ds = np.r_[(v @ jv) / (v.size * s), np.zeros(du.shape[1] - q.size)]
        return (du - r[:, None] * ds[None, :]) / s

    def linear_start(self) -> np.ndarray:
        """Least squares of the (linear) residual in the first three parameters (and gains).

        View gains ``a = 1 + δ`` enter to first order as ``(δ_i − δ_j)(c_a + c_b) / 2``.
        """
        basis, tail = self.model.linear_start(self.x_n, self.y_n)
        design = self.weight[:, None] * (
            self.c_a[:, None] * basis[self.b] - self.c_b[:, None] * basis[self.a]
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
        k = basis.shape[1]
        return np.r_[coef[:k], tail, 1.0 + coef[k:]]


def pixel_grid(image_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Normalised pixel-centre coordinates, ``x_n`` of shape (1, W), ``y_n`` of shape (H, 1)."""
    h, w = image_shape
    x_n = ((np.arange(w, dtype=np.float64) + 0.5) / w)[None, :]
    y_n = ((np.arange(h, dtype=np.float64) + 0.5) / h)[:, None]
    return x_n, y_n


def _map_uncertainty(
    model: PairModel,
    p: np.ndarray,
    fun: np.ndarray,
    jac: np.ndarray,
    image_shape: tuple[int, int],
    cov: np.ndarray | None = None,
) -> float:
    """Mean first-order relative standard uncertainty of ``v`` over the image.

    ``Cov(p) ≈ σ² (JᵀJ)⁺`` with ``σ² = Σ r² / (P − n_params)``, propagated to
    ``v`` on a grid of at most 32 × 32 pixel centres (as the extended
    Goldman–Chen fit does).
    """
    h, w = image_shape
    n = model.n_params
    cov = (_parameter_covariance(fun, jac) if cov is None else cov)[:n, :n]  # marginal
    p = p[:n]
    xs = (np.unique(np.linspace(0, w - 1, min(w, 32)).round()) + 0.5) / w
    ys = (np.unique(np.linspace(0, h - 1, min(h, 32)).round()) + 0.5) / h
    gx, gy = np.meshgrid(xs, ys)
    v, g = model.value_and_jacobian(p, gx.ravel(), gy.ravel())
    var = np.einsum("ij,jk,ik->i", g, cov, g)
    return float(np.mean(np.sqrt(np.maximum(var, 0.0)) / np.abs(v)))


@dataclass(frozen=True)
class PairFitResult:
    """Result of :func:`fit_pair_model` (per channel arrays of length ``C``)."""

    params: np.ndarray  # (C, P)
    residual_rms: np.ndarray
    map_uncertainty: np.ndarray
    converged: np.ndarray
    message: str
    observations: PairObservations
    view_gains: np.ndarray | None = None  # (C, V): see VignettingFit.view_gains
    view_gain_std: np.ndarray | None = None

    def report(self, n_tracks_given: int) -> dict[str, Any]:
        """The step report stored in the camera."""
        obs = self.observations
        return {
            "n_tracks_given": int(n_tracks_given),
            "n_tracks": obs.n_tracks,
            "n_pairs": obs.n_pairs,
            "n_observations": obs.n_observations,
            "residual_rms": self.residual_rms,
            "map_uncertainty": self.map_uncertainty,
            "message": self.message,
            **view_gain_report(self.view_gains, self.view_gain_std),
        }


def fit_pair_model(
    model: PairModel,
    obs: PairObservations,
    image_shape: tuple[int, int],
    *,
    normalise: str = "track",
    scale_invariant: bool = True,
    max_uncertainty: float = 0.02,
    max_nfev: int = 2000,
    initial: np.ndarray | None = None,
    view_gains: bool = False,
    view_gain_sigma: float | None = None,
) -> PairFitResult:
    """Fit ``model`` per channel to the pair residuals by Levenberg–Marquardt.

    Each channel starts from the linear least-squares solution of the model's
    ``linear_start`` (unless ``initial``, shape ``(C, P)``, is given) and is
    solved by MINPACK's Levenberg–Marquardt with the analytic Jacobian. A
    channel is *converged* only if the solver met its tolerances, the fitted
    ``v`` is positive at every pixel centre, its maximum is at least 0.5 (no
    collapse towards ``v = 0``) and its mean relative first-order uncertainty is
    at most ``max_uncertainty``; ``message`` gives the reason for every other.
    With ``view_gains`` every view but the lowest-numbered one has a free gain
    (module notes), fitted per channel and returned in ``view_gains``;
    ``initial`` then holds the model's parameters only.
    """
    if normalise not in ("track", "none"):
        raise InputError(f"`normalise` must be 'track' or 'none', got {normalise!r}")
    if view_gains and obs.obs_view is None:
        raise InputError("`view_gains` needs observations that know their views")
    h, w = image_shape
    n_channels = obs.values.shape[1]
    grid_x, grid_y = pixel_grid((h, w))
    params = np.empty((n_channels, model.n_params))
    rms = np.empty(n_channels)
    uncertainty = np.full(n_channels, np.nan)
    converged = np.zeros(n_channels, dtype=bool)
    notes: list[str] = []
    gains = gain_std = None
    n_gains = 0
    gain_index = np.zeros(obs.n_observations, dtype=np.int64)
    present = np.zeros(1, dtype=np.int64)
    if view_gains and obs.obs_view is not None:
        present, gain_index = np.unique(obs.obs_view, return_inverse=True)
        n_gains = int(present.size - 1)
        gains = np.full((n_channels, int(present.max()) + 1), np.nan)
        gain_std = np.full_like(gains, np.nan)
    for ch in range(n_channels):
        c = obs.values[:, ch]
        if normalise == "track":
            track_mean = np.bincount(obs.obs_track, weights=c) / np.bincount(obs.obs_track)
            weight = 1.0 / track_mean[obs.pair_track]
        else:
            weight = np.ones(obs.n_pairs)
        problem = _Problem(
            model,
            obs.x_n,
            obs.y_n,
            obs.a,
            obs.b,
            c[obs.a],
            c[obs.b],
            weight,
            scale_invariant,
            gain_index[obs.a] if n_gains else None,
            gain_index[obs.b] if n_gains else None,
            n_gains,
        )
        p0 = problem.linear_start()
        if initial is not None:
            p0 = np.r_[initial[ch], p0[model.n_params :]]
        result, fun, cov = _solve_pairs(
            problem.residuals,
            problem.jacobian,
            p0,
            model.n_params,
            int(max_nfev),
            view_gain_sigma if n_gains else None,
        )
        params[ch] = result.x[: model.n_params]
        if gains is not None and gain_std is not None:
            gains[ch, present] = np.r_[1.0, result.x[model.n_params :]]
            gain_std[ch, present] = np.r_[
                0.0, np.sqrt(np.maximum(np.diag(cov)[model.n_params :], 0.0))
            ]
        rms[ch] = float(np.sqrt(np.mean(fun**2)))
        ok = bool(result.success) and bool(np.all(np.isfinite(result.x)))
        if not ok:
            notes.append(f"channel {ch}: did not converge ({result.message})")
        else:
            uncertainty[ch] = _map_uncertainty(model, result.x, fun, result.jac, (h, w), cov)
            v = model.value(result.x[: model.n_params], grid_x, grid_y)
            v_min, v_max = float(np.min(v)), float(np.max(v))
            if not v_min > 0:
                ok = False
                notes.append(
                    f"channel {ch}: fitted vignetting is not positive over the image "
                    f"(minimum {v_min:.3g}); it cannot be used for correction"
                )
            elif v_max < 0.5:
                ok = False
                notes.append(
                    f"channel {ch}: fitted vignetting is below 0.5 everywhere in the image "
                    f"(maximum {v_max:.3g}): the fit has collapsed towards v = 0"
                )
            elif v_max > MAX_FALLOFF * v_min:
                ok = False
                notes.append(
                    f"channel {ch}: fitted vignetting spans a factor {v_max / v_min:.3g} over "
                    f"the image (more than {MAX_FALLOFF:g}): the polynomial diverged, no lens "
                    "falls off so (check the response and the correspondences)"
                )
            elif not uncertainty[ch] <= max_uncertainty:
                ok = False
                notes.append(
                    f"channel {ch}: the views constrain the model poorly (map uncertainty "
                    f"{uncertainty[ch]:.1%} > {max_uncertainty:.1%}); spread the view "
                    "directions in both axes (pan and tilt) and use more points"
                )
        converged[ch] = ok
    status = "converged" if converged.all() else "NOT TRUSTWORTHY"
    message = (
        f"{status}: {model.name} fit of {n_channels} channel(s) from {obs.n_tracks} tracks, "
        f"{obs.n_pairs} pairs, {obs.n_observations} observations in {obs.n_views} views "
        f"(normalise={normalise!r}, scale_invariant={bool(scale_invariant)}"
        f"{', view gains' if n_gains else ''}); "
        f"{obs.dropped_note}; relative map uncertainty (1 sigma, image mean) "
        + ", ".join("n/a" if np.isnan(u) else f"{u:.2%}" for u in uncertainty)
    )
    if notes:
        message += "; " + "; ".join(notes)
    return PairFitResult(params, rms, uncertainty, converged, message, obs, gains, gain_std)


@dataclass(frozen=True)
class PairFitOptions:
    """Options shared by the vignetting fits from correspondences.

    Attributes
    ----------
    normalise : {"track", "none"}
        Pair residuals divided by their track's mean (default) or in value units.
    scale_invariant : bool
        Divide the residuals by the RMS of ``v`` (default), so that the fit
        gains nothing by shrinking ``v``.
    sample_radius : int
        Half-size of the window averaged at each correspondence.
    min_pairs : int
        Fewest usable pairs of observations.
    min_spread : float
        Fewest fraction of the width and of the height the observations span.
    max_uncertainty : float
        Largest accepted mean relative first-order uncertainty of the map.
    max_nfev : int
        Most evaluations of the residuals per channel.
    view_gains : bool or "auto"
        A free gain per view, fitted with the model (module notes); ``"auto"``
        (default) as :class:`~photoquant.vignetting.ExtendedGoldmanChenOptions`.
        These models fit gains and model jointly: a centred model
        (``"Goldman-Chen 2005"``) determines them, a free centre
        (``"Radial Polynomial"``) trades them for a ramp of ``v``.
    view_gain_sigma : float, optional
        Prior standard deviation of each gain about 1; ``None``: free gains.
    """

    normalise: str = "track"
    scale_invariant: bool = True
    sample_radius: int = 1
    min_pairs: int = 30
    min_spread: float = 0.25
    max_uncertainty: float = 0.02
    max_nfev: int = 2000
    view_gains: bool | str = "auto"
    view_gain_sigma: float | None = None

    def __post_init__(self) -> None:
        if self.normalise not in ("track", "none"):
            raise InputError(f"`normalise` must be 'track' or 'none', got {self.normalise!r}")
        if not isinstance(self.scale_invariant, bool):
            raise InputError(
                f"`scale_invariant` must be true or false, got {self.scale_invariant!r}"
            )
        check_view_gains_option(self.view_gains)
        if self.view_gain_sigma is not None:
            check_positive(self.view_gain_sigma, "view_gain_sigma")
        check_int(self.sample_radius, "sample_radius", 0, 64)
        check_int(self.min_pairs, "min_pairs", 1)
        check_int(self.max_nfev, "max_nfev", 1)
        check_positive(self.min_spread, "min_spread", allow_zero=True)
        if self.min_spread > 1:
            raise InputError(f"`min_spread` must be a number in [0, 1], got {self.min_spread!r}")
        check_positive(self.max_uncertainty, "max_uncertainty")


def sample_tracks(
    data: VignettingData, radius: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample every view at its correspondences: ``(values (M, C), xy, view, track)``."""
    from photoquant.correspondences import sample_image, tracks_to_observations

    n_views = len(data.uniform_views)
    view_idx, xy, track_idx = tracks_to_observations(data.tracks)
    if view_idx.size and (view_idx.min() < 0 or view_idx.max() >= n_views):
        raise InputError(
            f"a correspondence names view {int(view_idx.max())}, there are {n_views} views"
        )
    n_ch = data.uniform_views[0].shape[-1]
    values = np.full((view_idx.size, n_ch), np.nan)
    for v in range(n_views):
        sel = view_idx == v
        if np.any(sel):
            values[sel] = sample_image(data.uniform_views[v], xy[sel], radius=radius)
    return values, xy, view_idx, track_idx
