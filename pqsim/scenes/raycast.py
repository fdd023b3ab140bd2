"""Shapes of a scene, each one source for its Mitsuba dict and its numpy ray casting.

A scene's shapes are ``_Prim`` objects — Mitsuba ``rectangle``, ``cube`` or
``sphere`` under an affine ``to_world`` — built by ``_rectangle``, ``_box``
and ``_sphere``. Each gives both the plain-data Mitsuba shape dict
(``_Prim.to_dict``, with its diffuse BSDF or area emitter) and an exact numpy
ray intersection (``_Prim.intersect``), so the correspondences and regions of
interest the factories compute by ray casting (``_cast``: the first shape hit
along each ray; ``_corners``: a rectangle's corners) see the very geometry
Mitsuba renders.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pqsim import spectral
from pqsim.scenes.geometry import _EPS, _frame, _rot_y
from pqsim.spectral import Spectrum

__all__: list[str] = []


@dataclass(frozen=True, eq=False)
class _Prim:
    """A shape placed in a scene: Mitsuba dict and numpy ray intersection from one source.

    ``kind`` is Mitsuba's ``rectangle`` ([-1, 1]² in the local xy plane, normal
    +z), ``cube`` ([-1, 1]³) or ``sphere`` (unit sphere), all mapped by
    ``to_world`` (affine, 4×4).
    """

    name: str
    kind: Literal["rectangle", "cube", "sphere"]
    to_world: NDArray
    reflectance: Spectrum | None = None
    radiance: Spectrum | None = None
    radiance_scale: float = 1.0
    sampling_weight: float = 1.0
    inverse: NDArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inverse", np.linalg.inv(self.to_world))

    @property
    def diffuse(self) -> bool:
        return self.radiance is None and self.reflectance is not None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"type": self.kind, "to_world": self.to_world.tolist()}
        if self.radiance is not None:
            d["emitter"] = {
                "type": "area",
                "radiance": self.radiance.to_mitsuba(self.radiance_scale),
                # Relative probability of picking this emitter for next-event
                # estimation (Mitsuba samples emitters by these weights).
                "sampling_weight": float(self.sampling_weight),
            }
            d["bsdf"] = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}}
        else:
            refl = (
                self.reflectance
                if self.reflectance is not None
                else spectral.constant_spectrum(0.5)
            )
            d["bsdf"] = {"type": "diffuse", "reflectance": refl.to_mitsuba()}
        return d

    def intersect(self, origin: NDArray, dirs: NDArray) -> NDArray:
        """Ray parameter ``t`` of the first hit (``inf`` when missed), shape (N,)."""
        A, b = self.inverse[:3, :3], self.inverse[:3, 3]
        o = A @ np.asarray(origin, float) + b
        d = dirs @ A.T
        t = np.full(d.shape[0], np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.kind == "rectangle":
                tt = -o[2] / d[:, 2]
                p = o[None, :2] + tt[:, None] * d[:, :2]
                ok = (tt > _EPS) & np.all(np.abs(p) <= 1.0, axis=1)
                t[ok] = tt[ok]
            elif self.kind == "cube":
                t1 = (-1.0 - o[None, :]) / d
                t2 = (1.0 - o[None, :]) / d
                tn = np.nanmax(np.minimum(t1, t2), axis=1)
                tf = np.nanmin(np.maximum(t1, t2), axis=1)
                ok = (tn <= tf) & (tf > _EPS)
                tt = np.where(tn > _EPS, tn, tf)
                t[ok] = tt[ok]
            else:
                a = np.sum(d * d, axis=1)
                bq = 2.0 * d @ o
                c = float(o @ o) - 1.0
                disc = bq * bq - 4 * a * c
                ok = disc >= 0
                sq = np.sqrt(np.where(ok, disc, 0.0))
                t0 = (-bq - sq) / (2 * a)
                t1s = (-bq + sq) / (2 * a)
                tt = np.where(t0 > _EPS, t0, t1s)
                ok &= tt > _EPS
                t[ok] = tt[ok]
        return t


def _rectangle(name: str, center, u_half, v_half, **kw) -> _Prim:
    u = np.asarray(u_half, float)
    v = np.asarray(v_half, float)
    n = np.cross(u, v)
    n /= np.linalg.norm(n)
    return _Prim(name, "rectangle", _frame(center, u, v, n), **kw)


def _box(name: str, center, half_extents, yaw_deg: float = 0.0, **kw) -> _Prim:
    R = _rot_y(math.radians(yaw_deg))
    hx, hy, hz = half_extents
    return _Prim(name, "cube", _frame(center, R[:, 0] * hx, R[:, 1] * hy, R[:, 2] * hz), **kw)


def _sphere(name: str, center, radius: float, **kw) -> _Prim:
    r = float(radius)
    return _Prim(name, "sphere", _frame(center, (r, 0, 0), (0, r, 0), (0, 0, r)), **kw)


def _cast(prims: Sequence[_Prim], origin: NDArray, dirs: NDArray) -> tuple[NDArray, NDArray]:
    """Index of the first prim hit along each ray (-1 = none) and its ``t``."""
    ts = np.stack([p.intersect(origin, dirs) for p in prims], axis=0)
    idx = np.argmin(ts, axis=0)
    t = ts[idx, np.arange(dirs.shape[0])]
    idx = np.where(np.isfinite(t), idx, -1)
    return idx, t


def _corners(prim: _Prim) -> NDArray[np.float64]:
    """World corners of a rectangle prim, in order around it."""
    local = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], dtype=float)
    return (local @ prim.to_world.T)[:, :3]
