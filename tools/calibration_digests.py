"""Digests of calibrations over every branch of ``calibrate``: a refactoring's bit-level guard.

The digests are the sha256 of every array of the camera model (and of the
intermediates the steps pass each other), and of its parameters and report
less the timings, for small pqsim captures that take every branch of the
calibration: one view; three views whose times are jittered (the joint
exposure refinement applied); a flat field; a glare capture with dark frames
(``calibrate_manifest``); the paper profile; ``refine_exposures`` off and on;
the response's model selection. Floating-point results differ between
NumPy, SciPy, Numba and Python versions and machines: compare digests
recorded in the same environment only.

Before a change meant to keep every bit, record; after it, compare::

    python tools/calibration_digests.py record /tmp/before.json
    python tools/calibration_digests.py compare /tmp/before.json
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import platform
import sys
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

import photoquant as pq

SHAPE = (48, 64)


def _environment() -> dict[str, str]:
    import numba
    import scipy

    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
    }


def _leaves(obj: Any, path: str, out: dict[str, str]) -> None:
    """Every array (hashed) and every plain value (as JSON) of ``obj``, by path.

    A mapping's keys are recorded in their order; the values of ``timings_s`` are left out
    (its keys are kept)."""
    if isinstance(obj, np.ndarray):
        data = np.ascontiguousarray(obj)
        head = f"{data.dtype.str}{data.shape}".encode()
        out[path] = hashlib.sha256(head + data.tobytes()).hexdigest()
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out[f"{path}.__class__"] = type(obj).__name__
        for field in dataclasses.fields(obj):
            _leaves(getattr(obj, field.name), f"{path}.{field.name}", out)
    elif isinstance(obj, dict):
        out[f"{path}.__keys__"] = json.dumps([str(key) for key in obj])  # their order too
        for key in sorted(obj, key=str):
            if key != "timings_s":
                _leaves(obj[key], f"{path}[{key!r}]", out)
    elif isinstance(obj, (list, tuple)):
        out[f"{path}.__len__"] = str(len(obj))
        for i, item in enumerate(obj):
            _leaves(item, f"{path}[{i}]", out)
    elif isinstance(obj, (np.generic, float, int, str, bool)) or obj is None:
        value = obj.item() if isinstance(obj, np.generic) else obj
        out[path] = f"{type(obj).__name__}:{json.dumps(value)}"
    else:
        raise TypeError(f"{path}: cannot digest a {type(obj).__name__}")


def digest(result: Any) -> str:
    """One sha256 of a :class:`~photoquant.calibration.CalibrationResult` (or a model)."""
    leaves: dict[str, str] = {}
    _leaves(result, "", leaves)
    return hashlib.sha256(json.dumps(leaves, sort_keys=True).encode()).hexdigest()


@cache
def _jittered(n_views: int, shape: tuple[int, int] = SHAPE) -> Any:
    from benchmarks.bench_exposure_refinement import jittered_set

    return jittered_set(0, shape, n_repeats=2, n_views=n_views, max_tracks=400)


@cache
def _flat_field() -> Any:
    """A uniformly lit target through the optics, at the views' nominal times (jittered)."""
    from pqsim.analytic import scene_irradiance

    data = _jittered(3)
    irr = data.irradiance
    times = irr.exposure_s * (1 + 0.03 * np.random.default_rng(7).standard_normal(irr.n_exposures))
    cap = data.camera.capture(scene_irradiance(SHAPE, 1.0, 0.0, channels=3), times, 2, 8)
    return pq.ExposureStack(
        cap.frames, irr.exposure_s, bit_depth=irr.bit_depth, channels=irr.channels
    )


def _views(
    n_views: int, *, given_tracks: bool = True, shape: tuple[int, int] = SHAPE, **kwargs: Any
) -> Callable[[Any], Any]:
    def run(_tmp: Any) -> Any:
        data = _jittered(n_views, shape)
        options = {"irradiance": data.irradiance, "white_roi": data.white_roi, **kwargs}
        said: list[str] = []
        result = pq.calibrate(
            data.views,
            correspondences=data.tracks if given_tracks and n_views > 1 else None,
            progress=said.append,
            return_intermediates=True,
            **options,
        )
        return result, said

    return run


def _glare_set(**kwargs: Any) -> Callable[[Path], Any]:
    def run(tmp: Path) -> Any:
        from pqsim.capture_set import write_capture_set
        from pqsim.synth_camera.presets import camera_from_preset
        from validation.experiments.robustness import _EXPOSURE, _GLARE

        camera = camera_from_preset("ccd", disturbances=dict(_EXPOSURE), **_GLARE)
        manifest = write_capture_set(
            tmp / "set",
            camera,
            shape=SHAPE,
            scene="lamp",
            glare={"level": 30.0},
            dark_frames=4,
            n_repeats=2,
            seed=0,
        )
        said: list[str] = []
        result = pq.calibrate_manifest(
            manifest, progress=said.append, return_intermediates=True, **kwargs
        )
        return result, said

    return run


CASES: dict[str, Callable[[Any], Any]] = {
    "one view": _views(1),
    "three jittered views": _views(3),
    "three views, refinement asked": _views(3, refine_exposures=True),
    "three views, no refinement": _views(3, refine_exposures=False),
    "three views, flat field": lambda tmp: _views(3, flat_field=_flat_field())(tmp),
    "three views, flat-field vignetting": lambda tmp: _views(
        3, flat_field=_flat_field(), vignetting="Flat Field"
    )(tmp),
    "found tracks, no irradiance, no white chart": _views(
        3, given_tracks=False, shape=(96, 128), irradiance=None, white_roi=None
    ),
    "paper profile": _views(3, profile="paper"),
    "response model selection": _views(1, response="Hold-out Selection"),
    "glare capture and dark frames": _glare_set(),
    "glare capture, refinement asked": _glare_set(refine_exposures=True),
}


def _record(tmp: Path) -> dict[str, Any]:
    return {
        "environment": _environment(),
        "digests": {
            name: digest(case(tmp / str(i))) for i, (name, case) in enumerate(CASES.items())
        },
    }


def main(argv: list[str]) -> int:
    """``record PATH`` or ``compare PATH`` (exit status 1 when a digest differs)."""
    import tempfile

    if len(argv) != 2 or argv[0] not in ("record", "compare"):
        print(__doc__.split("::")[-1], file=sys.stderr)
        return 2
    path = Path(argv[1])
    with tempfile.TemporaryDirectory() as folder:
        record = _record(Path(folder))
    if argv[0] == "record":
        path.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
        return 0
    stored = json.loads(path.read_text(encoding="utf-8"))
    if stored["environment"] != record["environment"]:
        print(f"recorded in {stored['environment']}, this is {record['environment']}")
        return 2
    changed = [n for n, d in record["digests"].items() if stored["digests"].get(n) != d]
    print("changed: " + ", ".join(changed) if changed else "every digest identical")
    return 1 if changed else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))
