"""Render true camera photoquantities with Mitsuba 3, with an on-disk cache.

This module is the only place that sets the Mitsuba variant (Mitsuba keeps
it as global state [1]_). Scene dicts come from :mod:`pqsim.scenes` in plain
data form and are converted by :func:`to_mitsuba_dict` just before loading.

A spectral variant with a ``specfilm`` whose bands are the camera's spectral
sensitivities yields, per pixel and channel, the Monte-Carlo estimate of the
photoquantity :math:`l_{p\\lambda} = \\int r_\\lambda(x)\\,l_p(x)\\,dx` (paper
§3.2.3, §3.3) [1]_.

Public objects
--------------
- :func:`choose_variant`, :data:`DEFAULT_VARIANT`
- :func:`render_photoquantity`, :class:`RenderInfo`
- :func:`render_aov`
- :func:`to_mitsuba_dict`, :func:`scene_key`

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022,
   https://mitsuba.readthedocs.io — variants, ``mi.render(scene, seed, spp)``,
   ``specfilm``, ``aov`` integrator, logging and progress (``mi.Appender``).
.. [2] OpenEXR, https://openexr.com (float32 storage of the cached images).
"""

from __future__ import annotations

import contextlib
import copy
import functools
import glob
import hashlib
import importlib.util
import json
import logging
import math
import os
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import ImageReadError, InputError
from photoquant.utils import check_int

__all__ = [
    "DEFAULT_VARIANT",
    "LLVM_VARIANTS",
    "RenderInfo",
    "choose_variant",
    "render_photoquantity",
    "render_aov",
    "to_mitsuba_dict",
    "scene_key",
    "check_multijitter_spp",
    "default_cache_dir",
    "mitsuba_available",
]

_log = logging.getLogger(__name__)

#: The variant used unless an LLVM one is probed working.
DEFAULT_VARIANT = "scalar_spectral"
#: LLVM (vectorised, JIT-compiled) spectral variants, by preference.
LLVM_VARIANTS: tuple[str, ...] = ("llvm_ad_spectral", "llvm_spectral")
#: Environment variable forcing the variant (e.g. ``scalar_spectral``).
VARIANT_ENV = "PQSIM_MITSUBA_VARIANT"
#: Bumped whenever the rendering rules change, to invalidate cached images.
_CACHE_SCHEMA = 1


def mitsuba_available() -> bool:
    """Whether Mitsuba 3 can be imported (``pip install 'photoquant[render]'``), without importing it."""
    return importlib.util.find_spec("mitsuba") is not None


def default_cache_dir() -> Path:
    """The render cache: ``$PQSIM_CACHE`` if set, else ``~/.cache/pqsim``."""
    env = os.environ.get("PQSIM_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "pqsim"


def _mitsuba() -> Any:
    try:
        import mitsuba
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("rendering needs Mitsuba 3: pip install 'photoquant[render]'") from exc
    return mitsuba


# ----------------------------------------------------------------------------- variants

_PROBE_SCRIPT = """
import mitsuba as mi
mi.set_variant({variant!r})
scene = mi.load_dict({{
    "type": "scene",
    "integrator": {{"type": "path", "max_depth": 2}},
    "sensor": {{"type": "perspective",
                "film": {{"type": "specfilm", "width": 4, "height": 4,
                          "band0": {{"type": "irregular", "wavelengths": "400, 700",
                                    "values": "1, 1"}}}}}},
    "emitter": {{"type": "constant"}},
}})
img = mi.render(scene, spp=4, seed=0)
import numpy as np
assert np.isfinite(np.array(img)).all()
print("ok")
"""


def _llvm_library_candidates() -> list[str | None]:
    """``DRJIT_LIBLLVM_PATH`` if set, else recent system libLLVM files, then Dr.Jit's default."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env:
        return [env]
    found: list[str] = []
    for pattern in (
        "/usr/lib/x86_64-linux-gnu/libLLVM.so.*",
        "/usr/lib/aarch64-linux-gnu/libLLVM.so.*",
        "/usr/lib/x86_64-linux-gnu/libLLVM-*.so",
        "/usr/lib/llvm-*/lib/libLLVM*.so*",
        "/usr/lib64/libLLVM*.so*",
        "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    ):
        found.extend(glob.glob(pattern))

    def version(path: str) -> tuple[int, ...]:
        digits = "".join(c if c.isdigit() else " " for c in os.path.basename(path)).split()
        return tuple(int(d) for d in digits[:2]) or (0,)

    # Newest first; Dr.Jit's own search (None) last, as it may find an old LLVM.
    newest_first = sorted(set(found), key=version, reverse=True)
    return [*newest_first, None]


def _probe(variant: str, libllvm: str | None, timeout_s: float) -> bool | None:
    """Render a 4×4 image in a subprocess; a crash (e.g. an abort in LLVM) cannot hurt us.
    ``None`` where it ran out of time (or could not start)."""
    env = dict(os.environ)
    if libllvm is not None:
        env["DRJIT_LIBLLVM_PATH"] = libllvm
    try:
        res = subprocess.run(  # noqa: S603 - fixed interpreter and script
            [sys.executable, "-c", _PROBE_SCRIPT.format(variant=variant)],
            env=env,
            capture_output=True,
            timeout=timeout_s,
            text=True,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return res.returncode == 0 and res.stdout.strip().endswith("ok")


PROBES_FILE = "variant-probes.json"
"""The verdicts of the LLVM probes, kept in :func:`default_cache_dir` (format
``pqsim.variant-probes/1``): a probe's answer for a variant and a library holds
until the library file, Mitsuba, Dr.Jit or the interpreter changes."""

_PROBES_FORMAT = "pqsim.variant-probes/1"


def _probe_key(variant: str, lib: str | None, candidates: Sequence[str | None]) -> str:
    """What a probe's verdict depends on: the variant, the library (its size and time,
    or, for Dr.Jit's own search, those of every library it could find), Mitsuba's and
    Dr.Jit's versions and the interpreter."""
    from importlib.metadata import PackageNotFoundError, version

    def stamp(path: str) -> str:
        try:
            st = os.stat(path)
        except OSError:
            return f"{path}:missing"
        return f"{path}:{st.st_size}:{st.st_mtime_ns}"

    libs = [lib] if lib is not None else [c for c in candidates if c is not None]
    versions = []
    for package in ("mitsuba", "drjit"):
        try:
            versions.append(f"{package} {version(package)}")
        except PackageNotFoundError:
            versions.append(f"{package} ?")
    return "|".join([variant, str(lib), *map(stamp, libs), *versions, sys.executable])


def _read_probes(path: Path) -> dict[str, bool]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get("format") != _PROBES_FORMAT:
        return {}
    verdicts = data.get("verdicts")
    if not isinstance(verdicts, dict):
        return {}
    return {k: v for k, v in verdicts.items() if isinstance(k, str) and isinstance(v, bool)}


def _write_probes(path: Path, verdicts: dict[str, bool]) -> None:
    """Kept where the cache can be written (atomically); nothing is lost but the time of
    probing again where it cannot."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"format": _PROBES_FORMAT, "verdicts": verdicts}, indent=1))
        os.replace(tmp, path)
    except OSError:
        _log.debug("could not keep the variant probes in %s", path)


@functools.cache
def _choose_variant_cached(allow_llvm: bool, timeout_s: float) -> tuple[str, str | None]:
    mi = _mitsuba()
    available = set(mi.variants())
    if allow_llvm:
        path = default_cache_dir() / PROBES_FILE
        kept = _read_probes(path)
        candidates = _llvm_library_candidates()
        for variant in LLVM_VARIANTS:
            if variant not in available:
                continue
            for lib in candidates:
                key = _probe_key(variant, lib, candidates)
                works = kept.get(key)
                if works is None:
                    works = _probe(variant, lib, timeout_s)
                    if works is not None:  # a probe that ran out of time is asked again
                        kept = {**_read_probes(path), key: works}
                        _write_probes(path, kept)
                if works:
                    return variant, lib
    if DEFAULT_VARIANT not in available:
        raise RuntimeError(f"Mitsuba has no {DEFAULT_VARIANT!r} variant (has {sorted(available)})")
    return DEFAULT_VARIANT, None


def choose_variant(*, allow_llvm: bool = True, probe_timeout_s: float = 30.0) -> str:
    """Return the Mitsuba variant to render with.

    ``$PQSIM_MITSUBA_VARIANT`` wins when set. Otherwise an LLVM spectral
    variant (:data:`LLVM_VARIANTS`) is used only when a subprocess manages to
    render a tiny image with it — with ``$DRJIT_LIBLLVM_PATH`` if set, else with
    each recent ``libLLVM`` found on the system (an old system LLVM makes
    Dr.Jit abort the process); the library that worked is then exported in
    ``DRJIT_LIBLLVM_PATH`` for this process. In every other case the result is
    :data:`DEFAULT_VARIANT` (``scalar_spectral``). The choice is made once per
    process, and each probe's verdict is kept on disk (:data:`PROBES_FILE`), so
    that the next process does not probe again (a probe took 0.1–0.2 s, and a
    machine with a system LLVM has several libraries to try): a changed library,
    Mitsuba, Dr.Jit or interpreter is probed anew, and so is a probe that ran
    out of time.

    Parameters
    ----------
    allow_llvm : bool
        Whether LLVM variants may be probed and chosen.
    probe_timeout_s : float
        Time limit of each probe subprocess (a 4×4 render: a second or two where
        the library works).

    Returns
    -------
    str
        A spectral variant name.
    """
    forced = os.environ.get(VARIANT_ENV)
    if forced:
        return _check_variant(forced, f"${VARIANT_ENV}")
    variant, lib = _choose_variant_cached(bool(allow_llvm), float(probe_timeout_s))
    if lib is not None and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        os.environ["DRJIT_LIBLLVM_PATH"] = lib
    return variant


def _check_variant(variant: Any, name: str = "variant") -> str:
    mi = _mitsuba()
    if not isinstance(variant, str) or variant not in mi.variants():
        raise InputError(f"`{name}` must be one of {sorted(mi.variants())}, got {variant!r}")
    if "spectral" not in variant or "polarized" in variant:
        raise InputError(f"`{name}` must be an unpolarised spectral variant, got {variant!r}")
    return variant


def _activate(variant: str) -> Any:
    """Set the Mitsuba variant — the only ``set_variant`` call of the project."""
    mi = _mitsuba()
    if mi.variant() != variant:
        mi.set_variant(variant)
    return mi


# ----------------------------------------------------------------------------- scene dicts


def to_mitsuba_dict(scene: Mapping[str, Any], variant: str | None = None) -> dict[str, Any]:
    """Convert a plain-data scene dict into one :func:`mitsuba.load_dict` accepts.

    Every ``to_world`` given as a 4×4 nested list or array becomes a
    ``mi.ScalarTransform4f``; everything else is copied unchanged.

    Parameters
    ----------
    scene : mapping
        Scene dict from :mod:`pqsim.scenes`.
    variant : str, optional
        Variant to activate first (default: :func:`choose_variant`).
    """
    mi = _activate(_check_variant(variant) if variant is not None else choose_variant())

    def convert(obj: Any, key: str | None = None) -> Any:
        if isinstance(obj, Mapping):
            return {k: convert(v, k) for k, v in obj.items()}
        if key == "to_world" and isinstance(obj, list | tuple | np.ndarray):
            m = np.asarray(obj, dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise InputError(f"`to_world` must be a finite 4x4 matrix, got shape {m.shape}")
            return mi.ScalarTransform4f(m)
        return obj

    return convert(scene)


def _canonical(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _canonical(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_canonical(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _canonical(obj.tolist())
    if isinstance(obj, bool | str) or obj is None:
        return obj
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        x = float(obj)
        if not math.isfinite(x):
            raise InputError(f"`scene` contains a non-finite number {x!r}")
        return x
    raise InputError(
        f"`scene` must be plain data (dict, list, str, number, bool), found {type(obj).__name__}"
    )


def scene_key(scene: Mapping[str, Any], *, spp: int, seed: int, variant: str) -> str:
    """Hash identifying a render: canonical scene, spp, seed, variant and Mitsuba version.

    The scene, with its sampler's ``sample_count`` set to ``spp`` as
    :func:`render_photoquantity` does, is serialised as JSON with sorted keys
    (so dict order does not matter) and hashed with SHA-256 together with the
    render settings, the Mitsuba version and a schema number of this module.
    """
    mi = _mitsuba()
    payload = {
        "schema": _CACHE_SCHEMA,
        "scene": _canonical(_with_spp(scene, int(spp))),
        "spp": int(spp),
        "seed": int(seed),
        "variant": str(variant),
        "mitsuba": str(mi.__version__),
    }
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _check_scene(scene: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    if not isinstance(scene, Mapping) or scene.get("type") != "scene":
        raise InputError("`scene` must be a Mitsuba scene dict with 'type': 'scene'")
    sensors = [v for v in scene.values() if isinstance(v, Mapping) and "film" in v]
    if len(sensors) != 1:
        raise InputError(f"`scene` must hold exactly one sensor with a film, found {len(sensors)}")
    sensor = sensors[0]
    film = sensor["film"]
    if not isinstance(film, Mapping):
        raise InputError("`scene` sensor's film must be a dict")
    return dict(sensor), dict(film)


def _film_channels(film: Mapping[str, Any]) -> tuple[str, ...]:
    """Output channel names of a ``specfilm``, in Mitsuba's (alphabetical) order."""
    bands = sorted(k for k, v in film.items() if isinstance(v, Mapping) and k != "rfilter")
    names = []
    for b in bands:
        head, _, tail = b.partition("_")
        names.append(tail if head.startswith("band") and tail else b)
    return tuple(names)


def _check_spp_seed(spp: Any, seed: Any) -> tuple[int, int]:
    """``spp`` in [1, 2**20] and ``seed`` in [0, 2**32) as ints."""
    return check_int(spp, "spp", 1, 1 << 20), check_int(seed, "seed", 0, (1 << 32) - 1)


def _with_spp(scene: Mapping[str, Any], spp: int) -> dict[str, Any]:
    """Deep copy of ``scene`` whose sampler has ``spp`` samples."""
    out = copy.deepcopy(dict(scene))
    for val in out.values():
        if isinstance(val, dict) and "film" in val:
            sampler = dict(val.get("sampler") or {"type": "independent"})
            sampler["sample_count"] = spp
            val["sampler"] = sampler
    return out


def _sample_count_error(spp: int, actual: int) -> InputError:
    from pqsim.reproject import multijitter_count

    below = max((n for n in range(1, spp) if multijitter_count(n) == n), default=None)
    nearest = f"{below} or {actual}" if below else f"{actual}"
    return InputError(
        f"`spp` = {spp} is not a sample count the scene's sampler accepts; it would "
        f"render {actual} samples. Multi-jittered samplers take r * m samples with "
        f"r = floor(sqrt(spp)) and m in [r, r + 2] (e.g. 16, 20, 24, 64); use {nearest}."
    )


def check_multijitter_spp(spp: int) -> int:
    """``spp`` if Mitsuba's ``multijitter`` sampler renders exactly that many samples.

    Raises
    ------
    InputError
        Naming the count it would render instead and the nearest accepted ones.
    """
    from pqsim.reproject import multijitter_count

    actual = multijitter_count(spp)
    if actual != spp:
        raise _sample_count_error(spp, actual)
    return spp


def _precheck_sample_count(scene: Mapping[str, Any], spp: int) -> None:
    """Refuse a ``multijitter`` count before Mitsuba loads the scene (and warns)."""
    for val in scene.values():
        if isinstance(val, dict) and "film" in val:
            if (val.get("sampler") or {}).get("type") == "multijitter":
                check_multijitter_spp(spp)


def _check_sample_count(mi_scene: Any, spp: int) -> None:
    """Refuse an ``spp`` the sampler would silently round (e.g. ``multijitter``: 32 → 35)."""
    sampler = mi_scene.sensors()[0].sampler()
    actual = int(sampler.sample_count())
    if actual != spp:
        raise _sample_count_error(spp, actual)


# ----------------------------------------------------------------------------- progress


@contextlib.contextmanager
def _mitsuba_log(progress: bool, description: str = "render") -> Iterator[None]:
    """Route Mitsuba's log to :mod:`logging` (warnings) and its progress to tqdm.

    Mitsuba's own appender prints to the terminal; while rendering it is
    replaced by one that forwards warnings and errors to the ``pqsim.render``
    logger and, when ``progress`` is true, drives a tqdm bar [1]_. The logger
    is restored afterwards.
    """
    mi = _mitsuba()
    bar: Any = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=100, desc=description, unit="%", leave=False)

    class _Appender(mi.Appender):  # type: ignore[misc, name-defined]
        def append(self, level: Any, text: str) -> None:
            if level >= mi.LogLevel.Warn:
                _log.warning("mitsuba: %s", text)

        def log_progress(self, fraction: float, *_details: Any) -> None:
            # Mitsuba passes (progress, name, formatted, eta, ptr).
            if bar is not None:
                bar.n = min(100, int(round(100 * float(fraction))))
                bar.refresh()

    logger = mi.logger()
    old_level = logger.log_level()
    old_appenders = [logger.appender(i) for i in range(logger.appender_count())]
    logger.clear_appenders()
    logger.add_appender(_Appender())
    # Progress is reported at the Info level only.
    logger.set_log_level(mi.LogLevel.Info if progress else mi.LogLevel.Warn)
    try:
        yield
    finally:
        logger.set_log_level(old_level)
        logger.clear_appenders()
        for a in old_appenders:
            logger.add_appender(a)
        if bar is not None:
            bar.n = 100
            bar.close()


# ----------------------------------------------------------------------------- EXR cache


def _read_cached(
    path: Path, channels: Sequence[str], shape: tuple[int, int]
) -> NDArray[np.float32] | None:
    """The cached image in ``channels`` order, or None (with a log line) if unusable."""
    from photoquant.io import read_exr

    try:
        image, names = read_exr(path)
    except ImageReadError as exc:
        _log.warning("unreadable render cache file, rendering again: %s", exc)
        return None
    if set(names) != set(channels) or image.shape[:2] != shape:
        _log.warning("render cache file %s does not match its request; rendering again", path)
        return None
    order = [names.index(c) for c in channels]
    return np.ascontiguousarray(image[..., order], dtype=np.float32)


# ----------------------------------------------------------------------------- rendering


def _emitter_order(mi_scene: Any) -> list[tuple]:
    """A sortable key per emitter, in the scene's order: shapeless first, then by bounding box."""
    keys = []
    for emitter in mi_scene.emitters():
        shape = emitter.get_shape()
        if shape is None:
            keys.append((0, type(emitter).__name__, (), ()))
        else:
            box = shape.bbox()
            keys.append((1, "", tuple(box.min), tuple(box.max)))
    return keys


def _load_canonical(mi: Any, mitsuba_dict: dict[str, Any], max_loads: int = 256) -> Any:
    """Load a scene whose emitters are in one canonical order.

    Mitsuba 3.9 may list a scene's area emitters in a different order from
    one load to the next, and emitter sampling, hence the Monte-Carlo noise of
    a render with a fixed seed, follows that order. Loading takes about a
    millisecond, so the scene is reloaded until its emitters come in sorted
    order (at most ``max_loads`` times; otherwise the last load is used and a
    warning is logged: the render is then correct but not bit-reproducible).
    """
    for _ in range(max_loads):
        mi_scene = mi.load_dict(mitsuba_dict)
        order = _emitter_order(mi_scene)
        if order == sorted(order):
            return mi_scene
    _log.warning("emitters of the scene never loaded in canonical order; render not reproducible")
    return mi_scene


@dataclass(frozen=True)
class RenderInfo:
    """What :func:`render_photoquantity` did.

    Attributes
    ----------
    key : str
        Cache key (:func:`scene_key`).
    cache_hit : bool
        Whether the image came from the cache (nothing was rendered).
    cache_path : Path or None
        The cache file, when a cache folder was given.
    variant : str
        Mitsuba variant.
    spp, seed : int
        Samples per pixel and seed.
    channels : tuple of str
        Channel names, in the order of the last axis.
    seconds : float
        Wall time of the call.
    """

    key: str
    cache_hit: bool
    cache_path: Path | None
    variant: str
    spp: int
    seed: int
    channels: tuple[str, ...]
    seconds: float


def render_photoquantity(
    scene: Mapping[str, Any],
    *,
    spp: int,
    seed: int,
    variant: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
    return_info: bool = False,
) -> NDArray[np.float32] | tuple[NDArray[np.float32], RenderInfo]:
    """Render the true camera photoquantity image of a scene.

    Parameters
    ----------
    scene : mapping
        Plain-data scene dict (:mod:`pqsim.scenes`) whose sensor has a
        ``specfilm`` (one band per camera channel).
    spp : int
        Samples per pixel (overrides the scene's sampler count).
    seed : int
        Sampler seed in [0, 2**32); the same seed, spp, variant and scene give
        a bit-identical image (scalar variants; see Notes).
    variant : str, optional
        Mitsuba spectral variant; default :func:`choose_variant`.
    cache_dir : path-like, optional
        Folder of cached renders (created if missing). The image is stored as
        a float32 OpenEXR file named by :func:`scene_key`; an identical later
        request reads it and renders nothing [2]_. The file is written
        atomically (temporary file, then :func:`os.replace`).
    progress : bool
        Show a progress bar (Mitsuba's progress, forwarded to tqdm).
    return_info : bool
        Also return a :class:`RenderInfo`.

    Returns
    -------
    ndarray, float32, shape (H, W, C)
        Photoquantity per pixel and channel, channels in the order of the
        camera's sensitivities. With ``return_info``, ``(image, info)``.

    Raises
    ------
    InputError
        If an argument is invalid.
    RuntimeError
        If the render contains NaN or infinite values.

    Notes
    -----
    Each pixel is the box-filtered mean over its footprint (``rfilter`` box),
    recorded in float32. In scalar variants blocks are rendered independently
    and written to disjoint pixels, so the result does not depend on thread
    scheduling. LLVM variants accumulate samples with atomic additions whose
    order may vary, so repeated renders may differ in the last bits.
    """
    t0 = time.perf_counter()
    spp, seed = _check_spp_seed(spp, seed)
    _, film = _check_scene(scene)
    if film.get("type") != "specfilm":
        raise InputError(f"`scene` sensor must have a 'specfilm', got {film.get('type')!r}")
    channels = _film_channels(film)
    variant = _check_variant(variant) if variant is not None else choose_variant()
    prepared = _with_spp(scene, spp)
    _precheck_sample_count(prepared, spp)
    key = scene_key(prepared, spp=spp, seed=seed, variant=variant)
    width, height = int(film.get("width", 768)), int(film.get("height", 576))

    path: Path | None = None
    if cache_dir is not None:
        folder = Path(cache_dir)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{key}.exr"
        if path.exists():
            image = _read_cached(path, channels, (height, width))
            if image is not None:
                _log.info("render cache hit %s", path)
                info = RenderInfo(
                    key, True, path, variant, spp, seed, channels, time.perf_counter() - t0
                )
                return (image, info) if return_info else image

    mi = _activate(variant)
    with _mitsuba_log(progress, f"render {width}x{height} @{spp}spp"):
        mi_scene = _load_canonical(mi, to_mitsuba_dict(prepared, variant))
        _check_sample_count(mi_scene, spp)
        tensor = mi.render(mi_scene, spp=spp, seed=seed)
    image = np.array(tensor, dtype=np.float32, copy=True)
    if image.ndim != 3 or image.shape[2] != len(channels):
        raise RuntimeError(
            f"Mitsuba returned shape {image.shape}, expected {len(channels)} channels"
        )
    if not np.all(np.isfinite(image)):
        raise RuntimeError("the render contains NaN or infinite values")
    if path is not None:
        from photoquant.io import write_exr

        meta = {
            "pqsim_key": key,
            "pqsim_spp": str(spp),
            "pqsim_seed": str(seed),
            "pqsim_variant": variant,
            "pqsim_mitsuba": str(mi.__version__),
        }
        write_exr(path, image, channels, meta)  # atomic: temporary file + os.replace
    info = RenderInfo(key, False, path, variant, spp, seed, channels, time.perf_counter() - t0)
    return (image, info) if return_info else image


_AOV_CHANNELS = {
    "position": 3,
    "geo_normal": 3,
    "sh_normal": 3,
    "depth": 1,
    "shape_index": 1,
    "prim_index": 1,
    "uv": 2,
}


def render_aov(
    scene: Mapping[str, Any],
    aovs: Sequence[str] = ("position",),
    *,
    spp: int = 16,
    seed: int = 0,
    variant: str | None = None,
) -> dict[str, NDArray[np.float32]]:
    """Render geometric arbitrary output variables (AOVs) of a scene.

    The scene's integrator is replaced by Mitsuba's ``aov`` integrator and its
    film by an ``hdrfilm`` of the same size with a box filter [1]_, so each
    value is the mean over the pixel footprint (e.g. the mean visible position).

    Parameters
    ----------
    scene : mapping
        Plain-data scene dict.
    aovs : sequence of str
        Among ``position``, ``geo_normal``, ``sh_normal``, ``depth``,
        ``shape_index``, ``prim_index``, ``uv``.
    spp, seed : int
        Samples per pixel and seed.
    variant : str, optional
        Spectral variant (default :func:`choose_variant`).

    Returns
    -------
    dict of str to ndarray
        Each AOV as ``(H, W, n)`` float32.
    """
    spp, seed = _check_spp_seed(spp, seed)
    _, film = _check_scene(scene)
    names = list(aovs)
    if not names or any(a not in _AOV_CHANNELS for a in names):
        raise InputError(
            f"`aovs` must be a non-empty subset of {sorted(_AOV_CHANNELS)}, got {aovs!r}"
        )
    variant = _check_variant(variant) if variant is not None else choose_variant()
    prepared = _with_spp(scene, spp)
    _precheck_sample_count(prepared, spp)
    prepared["integrator"] = {"type": "aov", "aovs": ",".join(f"{a}:{a}" for a in names)}
    for val in prepared.values():
        if isinstance(val, dict) and "film" in val:
            val["film"] = {
                "type": "hdrfilm",
                "width": int(film.get("width", 768)),
                "height": int(film.get("height", 576)),
                "pixel_format": "rgb",
                "component_format": "float32",
                "rfilter": {"type": "box"},
            }
    mi = _activate(variant)
    with _mitsuba_log(False):
        mi_scene = _load_canonical(mi, to_mitsuba_dict(prepared, variant))
        _check_sample_count(mi_scene, spp)
        out = np.array(mi.render(mi_scene, spp=spp, seed=seed), dtype=np.float32)
    # hdrfilm in "rgb" mode writes R, G, B (of the null radiance) first, then AOVs.
    result: dict[str, NDArray[np.float32]] = {}
    start = out.shape[2] - sum(_AOV_CHANNELS[a] for a in names)
    for a in names:
        n = _AOV_CHANNELS[a]
        result[a] = out[..., start : start + n]
        start += n
    return result
