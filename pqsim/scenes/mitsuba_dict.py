"""Plain-data Mitsuba 3 scene dicts: the scene, its sampler and perspective sensors.

A scene dict is exactly what :func:`mitsuba.load_dict` takes [1]_, except that
every ``to_world`` is a 4×4 nested list (row-major) instead of a
``mi.ScalarTransform4f``; :func:`pqsim.render.to_mitsuba_dict` converts it.
Keeping the dicts plain data lets them be built, hashed (the render cache key,
:func:`pqsim.render.scene_key`) and tested without Mitsuba, and keeps the
Mitsuba variant set in one place.

Private builders used by the scene factories: ``_scene_dict`` (``path``
integrator, optional constant environment, extra emitters and the shapes of
:mod:`pqsim.scenes.raycast`), ``_sampler`` (``multijitter``),
``_perspective_sensor`` and ``_offset_perspective_sensor`` (another film size,
field of view and principal point, for :class:`~pqsim.scenes.WideView`).

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022, https://mitsuba.readthedocs.io
   (scene dicts, ``perspective``/``orthographic`` sensors, ``specfilm``,
   ``path`` integrator, ``multijitter`` sampler).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

from numpy.typing import NDArray

from photoquant.errors import InputError
from pqsim.scenes.geometry import _mitsuba_camera_matrix
from pqsim.scenes.raycast import _Prim
from pqsim.spectral import CameraSensitivities, Spectrum

__all__: list[str] = []


def _scene_dict(
    *,
    sensor: dict[str, Any],
    prims: Sequence[_Prim],
    max_depth: int,
    environment: Spectrum | None = None,
    environment_scale: float = 1.0,
    environment_weight: float = 1.0,
    extra_emitters: dict[str, Any] | None = None,
) -> dict[str, Any]:
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": {
            "type": "path",
            "max_depth": int(max_depth),
            # Russian roulette only past max_depth: no roulette noise.
            "rr_depth": int(max_depth) + 1,
            "hide_emitters": False,
        },
        "sensor": sensor,
    }
    if environment is not None:
        scene["environment"] = {
            "type": "constant",
            "radiance": environment.to_mitsuba(environment_scale),
            "sampling_weight": float(environment_weight),
        }
    for key, val in (extra_emitters or {}).items():
        scene[key] = val
    for p in prims:
        if p.name in scene:
            raise InputError(f"duplicate scene object name {p.name!r}")
        scene[p.name] = p.to_dict()
    return scene


def _sampler(spp: int) -> dict[str, Any]:
    # Multi-jittered (stratified) samples: ~5x less noise than independent
    # samples at equal cost on these diffuse scenes (measured).
    return {"type": "multijitter", "sample_count": int(spp)}


def _perspective_sensor(
    cam: CameraSensitivities, R_cv: NDArray, origin, width: int, height: int, fov: float, spp: int
) -> dict[str, Any]:
    return {
        "type": "perspective",
        "fov": float(fov),
        "fov_axis": "x",
        "near_clip": 0.01,
        "far_clip": 100.0,
        "to_world": _mitsuba_camera_matrix(R_cv, origin),
        "sampler": _sampler(spp),
        "film": cam.specfilm(width, height),
    }


def _offset_perspective_sensor(
    sensor: dict[str, Any], width: int, height: int, fov: float, offset: tuple[float, float]
) -> dict[str, Any]:
    """Copy of a :func:`_perspective_sensor` with another film size, fov and principal point.

    Mitsuba's ``perspective`` sensor maps the film position ``p`` (in [0, 1]²,
    ``y`` down) to the ray its centred twin sends through ``p + offset``, with
    ``offset = (principal_point_offset_x, principal_point_offset_y)`` in
    fractions of the film size, while ``fov`` (``fov_axis = "x"``) keeps
    defining the focal length ``f = (W/2) / tan(fov/2)`` from the film width
    alone [1]_: the principal point is at ``(W (1/2 − offset_x), H (1/2 − offset_y))``
    pixels (verified against ``Sensor.sample_ray`` in Mitsuba 3.9).
    """
    out = copy.deepcopy(sensor)
    out["fov"] = float(fov)
    out["fov_axis"] = "x"
    out["principal_point_offset_x"] = float(offset[0])
    out["principal_point_offset_y"] = float(offset[1])
    out["film"]["width"] = int(width)
    out["film"]["height"] = int(height)
    return out
