"""The sweep specification: a TOML file of fixed settings, axes and seeds.

:func:`load_spec` reads and checks a spec (``photoquant sweep SPEC.toml``)
and :func:`parse_spec` checks an already-parsed mapping; both return a frozen
:class:`SweepSpec` whose :meth:`SweepSpec.cells` is the cartesian product of
the axes times the seeds, each cell's configuration as plain data
(:func:`cell_config`) with its hash (:func:`cell_id`). Every value is checked before anything runs: an
unknown table, key or axis, a value of the wrong type, a method or profile
that is not registered, a camera that cannot be built, an empty grid — each
is one :class:`SweepSpecError` naming the key.

Format::

    [sweep]                      # fixed settings (any setting below) and the seeds
    preset = "ccd"               # a built-in preset or a pqsim.preset/1 file (relative to the spec)
    resolution = [160, 120]      # [W, H]
    seeds = [0, 1]               # a list of seeds, or a count n (seeds 0 .. n - 1)

    [axes]                       # setting -> list of values; cells are the cartesian product
    n_repeats = [1, 4]
    "noise.read_noise_e" = [2.0, 8.0]
    pipeline = ["photoquant", "paper"]

Settings (:data:`SETTINGS`), each usable fixed or as an axis:

* ``preset``; any field of a ``pqsim.preset/1`` preset by dotted path —
  ``"noise.read_noise_e"``, ``"balance.2"``, ``"vignetting_params.*.0"``
  (``*``: every item of a list, e.g. ``m1`` of every channel: the vignetting
  strength), ``"responses.*"`` (every channel's response record, e.g.
  ``{kind = "gamma", params = {gamma = 0.45}}``: the response family);
  the value must have the type of the preset's value there;
* the capture: ``n_repeats`` (N), ``n_exposures`` (K), ``exposure_range``
  (``[min_s, max_s]``, geometric), ``n_views`` (V), ``resolution``
  (``[W, H]``), ``bit_depth``;
* ``pipeline`` (a profile of :data:`photoquant.profiles.PROFILES`) and
  ``method``: the steps' methods over the profile, ``"STEP=NAME"`` or a
  table ``{STEP = NAME, ...}`` whose ``NAME`` may be a table
  ``{name = NAME, OPTION = VALUE, ...}``; any registered method, plug-ins
  included (:func:`photoquant.methods.load_plugins`);
* ``uncertainty``: ``true`` also scores the correction's stated uncertainty
  against the truth (the metrics ``uncertainty_z_spread``,
  ``uncertainty_within_68``, ``uncertainty_within_95``; off by default: it
  adds the uncertainty's computation to every cell);
* ``renderer``: ``"numpy"`` (the analytic scenes, default) or ``"mitsuba"``
  (:func:`pqsim.rendered_capture.write_rendered_capture_set`, ``pip install
  '.[render]'``), with ``spp``, ``illuminant`` and ``cache_dir`` (renders
  shared by every cell through the render cache; ``$PQSIM_CACHE`` or
  ``~/.cache/pqsim`` by default).

References
----------
.. [TOML] TOML v1.0.0, https://toml.io/en/v1.0.0 (read with :mod:`tomllib`).
"""

from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
import math
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from photoquant.errors import InputError, PhotoquantError
from photoquant.io.outputs import real_path

__all__ = [
    "CAPTURE_SETTINGS",
    "DEFAULTS",
    "SETTINGS",
    "SweepSpec",
    "SweepSpecError",
    "load_spec",
    "parse_spec",
    "method_label",
    "column_value",
    "CELL_FORMAT",
    "cell_config",
    "cell_id",
    "code_version",
    "source_digest",
]


class SweepSpecError(PhotoquantError):
    """A sweep specification is invalid (one line naming the key and the problem)."""


#: Capture settings (the rest of a cell's settings are the preset, its fields and the pipeline).
CAPTURE_SETTINGS = ("n_repeats", "n_exposures", "exposure_range", "n_views", "resolution")
#: Settings every cell has, with their defaults (``bit_depth``: the preset's own).
DEFAULTS: Mapping[str, Any] = {
    "preset": "ccd",
    "n_repeats": 4,
    "n_exposures": 8,
    "exposure_range": [0.001, 0.2],
    "n_views": 3,
    "resolution": [160, 120],
    "pipeline": "photoquant",
    "method": {},
    "renderer": "numpy",
    "spp": 16,
    "illuminant": "D65",
}
#: Named settings (besides dotted preset paths), fixed or as axes.
SETTINGS = (*DEFAULTS, "bit_depth", "uncertainty")
#: Keys of ``[sweep]`` that are not settings.
_SWEEP_ONLY = ("seeds", "cache_dir")
_RENDERERS = ("numpy", "mitsuba")
_MAX_CELLS = 100_000
_MAX_SPEC_BYTES = 1 << 20


def _fail(message: str) -> SweepSpecError:
    return SweepSpecError(message)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _label(value: Any) -> str:
    """A value as it is shown in messages and table columns (JSON for lists and tables)."""
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True)


def method_label(spec: Mapping[str, Any]) -> str:
    """The canonical text of a resolved ``method`` setting: ``"STEP=NAME; ..."`` ('' for none).

    >>> method_label({"response": {"name": "Robertson 2003"}})
    'response=Robertson 2003'
    """
    parts = []
    for step in sorted(spec):
        entry = dict(spec[step])
        name = entry.pop("name")
        parts.append(f"{step}={name}" + (f" {json.dumps(entry, sort_keys=True)}" if entry else ""))
    return "; ".join(parts)


# ------------------------------------------------------------------ value checks


def column_value(key: str, value: Any) -> Any:
    """A setting's value as its table column holds it (``"160x120"``, a method's label, JSON)."""
    if key == "resolution":
        return f"{value[0]}x{value[1]}"
    if key == "method":
        return method_label(value) or "default"
    if isinstance(value, list | dict):
        return json.dumps(value, sort_keys=True)
    return value


def _first_non_finite(value: Any, where: str) -> tuple[str, float] | None:
    """The path and value of the first number in ``value`` that is not finite (TOML's inf, nan)."""
    if isinstance(value, float) and not math.isfinite(value):
        return where, value
    if isinstance(value, Mapping):
        items: list[tuple[str, Any]] = [(f"{where}.{k}", v) for k, v in value.items()]
    elif isinstance(value, list):
        items = [(f"{where}[{i}]", v) for i, v in enumerate(value)]
    else:
        return None
    for path, item in items:
        found = _first_non_finite(item, path)
        if found is not None:
            return found
    return None


def _check_finite(table: Mapping[str, Any]) -> None:
    """Refuse a spec value that is not a finite number anywhere in ``table`` (one line)."""
    for key, value in table.items():
        found = _first_non_finite(value, str(key))
        if found is not None:
            raise _fail(f"`{found[0]}` must be a finite number, got {found[1]}")


def _check_int_value(key: str, v: Any, lo: int, hi: int | None = None) -> int:
    if not _is_int(v) or v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise _fail(f"`{key}` must be an integer {rng}, got {_label(v)}")
    return int(v)


def _check_method(key: str, v: Any) -> dict[str, dict[str, Any]]:
    """``"STEP=NAME"`` or ``{STEP = NAME | {name = NAME, OPTION = VALUE}}`` → step → {name, ...}."""
    from photoquant.methods import STEPS

    if isinstance(v, str):
        if v in ("", "default"):
            return {}
        step, sep, name = v.partition("=")
        if not sep or not step.strip() or not name.strip():
            raise _fail(f"`{key}`: {v!r} is not 'STEP=NAME' (e.g. 'response=Robertson 2003')")
        v = {step.strip(): name.strip()}
    if not isinstance(v, Mapping):
        raise _fail(f"`{key}` must be 'STEP=NAME' or a table {{STEP = NAME}}, got {_label(v)}")
    out: dict[str, dict[str, Any]] = {}
    for step, entry in v.items():
        if step not in STEPS:
            raise _fail(f"`{key}`: unknown step {step!r}; the steps are {', '.join(STEPS)}")
        if isinstance(entry, str):
            entry = {"name": entry}
        if not isinstance(entry, Mapping) or not isinstance(entry.get("name"), str):
            raise _fail(
                f"`{key}.{step}` must be a method name or a table {{name = NAME, OPTION = VALUE}}"
            )
        out[step] = dict(entry)
    return out


def _check_setting(key: str, v: Any) -> Any:
    """Check one named setting's value; returns it in canonical form."""
    if key in ("preset", "pipeline", "renderer", "illuminant"):
        if not isinstance(v, str) or not v:
            raise _fail(f"`{key}` must be a non-empty string, got {_label(v)}")
        if key == "renderer" and v not in _RENDERERS:
            raise _fail(f"`renderer` must be one of {', '.join(_RENDERERS)}, got {v!r}")
        if key == "pipeline":
            from photoquant.profiles import PROFILES

            if v not in PROFILES:
                raise _fail(f"`pipeline`: unknown profile {v!r}; valid: {', '.join(PROFILES)}")
        return v
    if key == "n_repeats":
        return _check_int_value(key, v, 1, 1000)
    if key == "n_views":
        return _check_int_value(key, v, 1, 20)
    if key == "n_exposures":
        return _check_int_value(key, v, 2, 100)
    if key == "spp":
        return _check_int_value(key, v, 1, 1 << 16)
    if key == "bit_depth":
        return _check_int_value(key, v, 8, 16)
    if key == "uncertainty":
        if not isinstance(v, bool):
            raise _fail(f"`uncertainty` must be true or false, got {_label(v)}")
        return v
    if key == "exposure_range":
        if (
            not isinstance(v, list)
            or len(v) != 2
            or not all(_is_number(t) and t > 0 for t in v)
            or not v[0] < v[1]
        ):
            raise _fail(
                f"`exposure_range` must be [min_s, max_s] with 0 < min_s < max_s, got {_label(v)}"
            )
        return [float(v[0]), float(v[1])]
    if key == "resolution":
        if not isinstance(v, list) or len(v) != 2 or not all(_is_int(s) for s in v):
            raise _fail(f"`resolution` must be [W, H] (integers), got {_label(v)}")
        if v[0] < 32 or v[1] < 24 or v[0] > 8192 or v[1] > 8192:
            raise _fail(f"`resolution` must be at least [32, 24] and at most 8192, got {_label(v)}")
        return [int(v[0]), int(v[1])]
    if key == "method":
        return _check_method(key, v)
    raise AssertionError(key)  # pragma: no cover - keys are checked before


# ------------------------------------------------------------------ preset paths


def _path_parts(key: str) -> list[str]:
    parts = key.split(".")
    if any(p == "" for p in parts):
        raise _fail(f"`{key}` is not a dotted path (an empty component)")
    return parts


def _same_kind(old: Any, new: Any) -> bool:
    if old is None:
        return True
    if isinstance(old, bool) or isinstance(new, bool):
        return isinstance(old, bool) and isinstance(new, bool)
    if _is_int(old):
        return _is_int(new)
    if isinstance(old, float):
        return _is_number(new)
    if isinstance(old, str):
        return isinstance(new, str)
    if isinstance(old, list | tuple):
        return isinstance(new, list)
    if isinstance(old, Mapping):
        return isinstance(new, Mapping)
    return False


def _kind_name(old: Any) -> str:
    if isinstance(old, bool):
        return "a boolean"
    if _is_int(old):
        return "an integer"
    if isinstance(old, float):
        return "a number"
    if isinstance(old, str):
        return "a string"
    if isinstance(old, list | tuple):
        return "a list"
    return "a table"


def set_path(fields: dict[str, Any], key: str, value: Any) -> None:
    """Set the preset field at dotted path ``key`` (``*``: every list item) to ``value``, in place.

    ``fields`` holds plain data (lists and dicts, as :func:`photoquant.utils.to_json_value`
    gives). The path must exist in ``fields`` (``noise.*`` may name any
    :class:`pqsim.synth_camera.sensor.SensorNoise` field) and ``value`` must
    have the type of the value it replaces; a table replacing a table sets
    the keys it names and keeps the others.

    Raises
    ------
    SweepSpecError
        For a path that does not exist or a value of another type.
    """
    import dataclasses

    from pqsim.synth_camera.sensor import SensorNoise

    parts = _path_parts(key)
    noise_defaults = {f.name: f.default for f in dataclasses.fields(SensorNoise)}
    noise_fields = set(noise_defaults)

    def walk(node: Any, i: int, where: str) -> None:
        part = parts[i]
        last = i == len(parts) - 1
        if isinstance(node, dict):
            if part not in node:
                if where == "noise" and part in noise_fields:
                    # a SensorNoise field the preset leaves at its default
                    node[part] = noise_defaults[part]
                else:
                    valid = sorted(set(node) | (noise_fields if where == "noise" else set()))
                    raise _fail(
                        f"unknown preset field `{key}`: {where or 'the preset'} has no "
                        f"{part!r} (valid: {', '.join(valid)})"
                    )
            keys: list[Any] = [part]
        elif isinstance(node, list):
            if part == "*":
                keys = list(range(len(node)))
            elif part.isdigit() and int(part) < len(node):
                keys = [int(part)]
            else:
                raise _fail(
                    f"unknown preset field `{key}`: {where} is a list of {len(node)}; "
                    f"use an index 0..{len(node) - 1} or *"
                )
        else:
            raise _fail(f"unknown preset field `{key}`: {where} is {_label(node)}, not a table")
        for k in keys:
            here = f"{where}.{k}" if where else str(k)
            if last:
                old = node[k]
                if not _same_kind(old, value):
                    raise _fail(f"`{key}` must be {_kind_name(old)}, got {_label(value)}")
                # a table sets the keys it names (``noise = {read_noise_e = 4.0}``)
                new = copy.deepcopy(value)
                node[k] = dict(old) | new if isinstance(old, Mapping) else new
            else:
                walk(node[k], i + 1, here)

    walk(fields, 0, "")


# ------------------------------------------------------------------ the spec


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep specification.

    Attributes
    ----------
    fixed : dict
        Every setting of every cell that is not an axis (defaults filled in),
        keys as in the spec (named settings and dotted preset paths).
    axes : dict
        Axis → tuple of values (in the spec's order; canonical form).
    seeds : tuple of int
        The seeds; every cell is run once per seed.
    cache_dir : str or None
        Render cache of the ``mitsuba`` renderer.
    base_dir : str
        Folder of the spec file (preset files are relative to it).
    preset_files : dict
        Preset file name → its fields (read once, so cells carry data, not paths).
    """

    fixed: Mapping[str, Any]
    axes: Mapping[str, tuple[Any, ...]]
    seeds: tuple[int, ...]
    cache_dir: str | None
    base_dir: str
    preset_files: Mapping[str, Mapping[str, Any]]

    @property
    def n_cells(self) -> int:
        """Number of cells: the product of the axes' lengths times the seeds."""
        n = len(self.seeds)
        for values in self.axes.values():
            n *= len(values)
        return n

    def settings(self) -> Iterator[dict[str, Any]]:
        """Each cell's settings (fixed + one value per axis), without the seed, in grid order."""
        names = list(self.axes)
        for combo in itertools.product(*(self.axes[a] for a in names)):
            yield dict(self.fixed) | dict(zip(names, combo, strict=True))

    def cells(self) -> Iterator[dict[str, Any]]:
        """Every cell's full configuration (:func:`cell_config`)."""
        for settings in self.settings():
            for seed in self.seeds:
                yield cell_config(self, settings, seed)

    def to_json(self) -> dict[str, Any]:
        """The spec's canonical content (what ``sweep.json`` records and compares)."""
        return {
            "fixed": dict(sorted(self.fixed.items())),
            "axes": {a: list(v) for a, v in self.axes.items()},
            "seeds": list(self.seeds),
            "cache_dir": self.cache_dir,
            "preset_files": {k: dict(v) for k, v in sorted(self.preset_files.items())},
        }

    def digest(self) -> str:
        """SHA-256 of :meth:`to_json` (hex)."""
        text = json.dumps(self.to_json(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a sweep specification file (TOML).

    Raises
    ------
    SweepSpecError
        If the file cannot be read, is not TOML, or is not a valid spec.
    """
    path = Path(path)
    try:
        if path.stat().st_size > _MAX_SPEC_BYTES:
            raise _fail(f"sweep spec {path} is larger than {_MAX_SPEC_BYTES} bytes")
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise _fail(f"cannot read the sweep spec {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise _fail(f"sweep spec {path} is not UTF-8 text") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _fail(f"sweep spec {path} is not valid TOML: {exc}") from None
    try:
        return parse_spec(doc, base_dir=real_path(path).parent)
    except SweepSpecError as exc:
        raise _fail(f"sweep spec {path}: {exc}") from None


def _preset_data(name: str, base_dir: Path, files: dict[str, Any]) -> dict[str, Any]:
    """The preset's fields as plain data (a file's read once, relative to the spec)."""
    from photoquant.utils import to_json_value
    from pqsim.synth_camera.presets import is_preset_file, preset_fields

    if is_preset_file(name):
        if name not in files:
            p = Path(name)
            try:
                files[name] = to_json_value(preset_fields(p if p.is_absolute() else base_dir / p))
            except InputError as exc:
                raise _fail(f"`preset`: {exc}") from None
        return copy.deepcopy(files[name])
    try:
        data: dict[str, Any] = to_json_value(preset_fields(name))
        return data
    except InputError as exc:
        raise _fail(f"`preset`: {exc}") from None


def parse_spec(doc: Mapping[str, Any], *, base_dir: str | Path = ".") -> SweepSpec:
    """Check a parsed spec (the TOML document as a mapping) and return a :class:`SweepSpec`.

    Every cell is built once here (its camera and its methods), so that a bad
    value is refused before any cell runs.
    """
    base_dir = Path(base_dir)
    unknown = sorted(set(doc) - {"sweep", "axes"})
    if unknown:
        raise _fail(f"unknown table(s) {', '.join(map(repr, unknown))}; valid: 'sweep', 'axes'")
    sweep = doc.get("sweep", {})
    axes_doc = doc.get("axes", {})
    if not isinstance(sweep, Mapping) or not isinstance(axes_doc, Mapping):
        raise _fail("`sweep` and `axes` must be tables")
    _check_finite(sweep)
    _check_finite(axes_doc)

    def check_key(key: str, table: str) -> None:
        if key in SETTINGS or (table == "sweep" and key in _SWEEP_ONLY):
            return
        if "." in key or key in _preset_top_fields():
            return  # a preset field, checked when the cameras are built
        valid = ", ".join([*SETTINGS, *(_SWEEP_ONLY if table == "sweep" else ())])
        what = "key" if table == "sweep" else "axis"
        raise _fail(
            f"unknown {what} `{key}` in [{table}]; valid: {valid}, or a preset field by "
            "dotted path (e.g. 'noise.read_noise_e')"
        )

    for key in sweep:
        check_key(str(key), "sweep")
    for key in axes_doc:
        check_key(str(key), "axes")
    both = sorted(set(sweep) & set(axes_doc))
    if both:
        raise _fail(f"`{both[0]}` is both a fixed setting ([sweep]) and an axis ([axes])")

    # seeds
    seeds_doc = sweep.get("seeds", [0])
    if _is_int(seeds_doc):
        if not 0 <= seeds_doc <= _MAX_CELLS:
            raise _fail(f"`seeds` as a count must be in [0, {_MAX_CELLS}], got {seeds_doc}")
        seeds_doc = list(range(seeds_doc))
    if not isinstance(seeds_doc, list) or not all(_is_int(s) and s >= 0 for s in seeds_doc):
        raise _fail(f"`seeds` must be a list of integers >= 0 or a count, got {_label(seeds_doc)}")
    if len(set(seeds_doc)) != len(seeds_doc):
        raise _fail("`seeds` has a repeated seed")
    cache_dir = sweep.get("cache_dir")
    if cache_dir is not None and (not isinstance(cache_dir, str) or not cache_dir):
        raise _fail(f"`cache_dir` must be a folder name, got {_label(cache_dir)}")
    if cache_dir is not None:
        p = Path(cache_dir).expanduser()
        cache_dir = str(p if p.is_absolute() else base_dir / p)

    def canonical(key: str, value: Any) -> Any:
        if key in SETTINGS:
            return _check_setting(key, value)
        if isinstance(value, list | dict):
            return json.loads(json.dumps(value))  # plain lists and dicts (TOML tables)
        return value

    fixed: dict[str, Any] = dict(DEFAULTS)
    for key, value in sweep.items():
        if key not in _SWEEP_ONLY:
            fixed[key] = canonical(key, value)
    axes: dict[str, tuple[Any, ...]] = {}
    for key, values in axes_doc.items():
        if not isinstance(values, list):
            raise _fail(f"axis `{key}` must be a list of values, got {_label(values)}")
        if not values:
            raise _fail(f"axis `{key}` has no values: the grid is empty")
        checked = [canonical(key, v) for v in values]
        labels = [_label(v) for v in checked]
        if len(set(labels)) != len(labels):
            dup = next(lab for lab in labels if labels.count(lab) > 1)
            raise _fail(f"axis `{key}` lists {dup!r} twice")
        axes[key] = tuple(checked)
    if not axes:
        raise _fail("the grid is empty: [axes] names no axis (add e.g. n_repeats = [1, 4])")
    if not seeds_doc:
        raise _fail("the grid is empty: `seeds` is empty")
    spec = SweepSpec(
        fixed=fixed,
        axes=axes,
        seeds=tuple(int(s) for s in seeds_doc),
        cache_dir=cache_dir,
        base_dir=str(base_dir),
        preset_files={},
    )
    if spec.n_cells > _MAX_CELLS:
        raise _fail(f"the grid has {spec.n_cells} cells, more than {_MAX_CELLS}")
    _check_cells(spec)
    return spec


def _preset_top_fields() -> set[str]:
    from pqsim.synth_camera.camera import SyntheticCamera
    from pqsim.synth_camera.presets import _NON_CAMERA_KEYS

    return set(SyntheticCamera.__dataclass_fields__) | set(_NON_CAMERA_KEYS)


def _check_cells(spec: SweepSpec) -> None:
    """Build every distinct camera and method set once; the first failure is the error."""
    from photoquant.calibration import resolve_steps
    from photoquant.methods import load_plugins

    try:
        load_plugins()
    except InputError as exc:
        raise _fail(str(exc)) from None
    files: dict[str, Any] = dict(spec.preset_files)
    cameras: set[str] = set()
    methods: set[tuple[str, str]] = set()
    renderers: set[str] = set()
    for settings in spec.settings():
        fields = camera_fields(settings, Path(spec.base_dir), files)
        key = json.dumps(fields, sort_keys=True)
        if key not in cameras:
            cameras.add(key)
            try:
                build_camera(fields)
            except (PhotoquantError, TypeError, ValueError) as exc:
                where = _describe(settings, spec)
                raise _fail(f"the camera of {where} cannot be built: {exc}") from None
        pm = (settings["pipeline"], method_label(settings["method"]))
        if pm not in methods:
            methods.add(pm)
            try:
                resolve_steps(pm[0], **method_specs(settings["method"]))
            except PhotoquantError as exc:
                raise _fail(f"`method` {pm[1]!r}: {exc}") from None
        renderers.add(settings["renderer"])
    if "mitsuba" in renderers:
        import importlib.util

        if importlib.util.find_spec("mitsuba") is None:
            raise _fail("`renderer` 'mitsuba' needs Mitsuba 3 (pip install '.[render]')")
    object.__setattr__(spec, "preset_files", files)


def _describe(settings: Mapping[str, Any], spec: SweepSpec) -> str:
    parts = [f"{a} = {_label(settings[a])}" for a in spec.axes]
    return "the cell " + ", ".join(parts) if parts else "the sweep"


def camera_fields(
    settings: Mapping[str, Any], base_dir: Path, files: dict[str, Any]
) -> dict[str, Any]:
    """The camera's preset fields (plain data) of a cell: the preset with its dotted settings."""
    fields = _preset_data(settings["preset"], base_dir, files)
    if "bit_depth" in settings:
        fields["bit_depth"] = settings["bit_depth"]
    for key in sorted(k for k in settings if k not in SETTINGS and not k.startswith("_")):
        set_path(fields, key, settings[key])
    return fields


def build_camera(fields: Mapping[str, Any]) -> Any:
    """A :class:`~pqsim.synth_camera.camera.SyntheticCamera` from preset fields (plain data)."""
    from pqsim.synth_camera.presets import _NON_CAMERA_KEYS, camera_from_preset

    camera = {k: v for k, v in fields.items() if k not in _NON_CAMERA_KEYS}
    noise = {k: v for k, v in dict(camera.get("noise") or {}).items() if v is not None}
    camera["noise"] = noise
    if isinstance(camera.get("vignetting_params"), list):
        camera["vignetting_params"] = tuple(tuple(r) for r in camera["vignetting_params"])
    if isinstance(camera.get("balance"), list):
        camera["balance"] = tuple(camera["balance"])
    return camera_from_preset("ccd", **camera)


def method_specs(method: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The per-step specs of :func:`photoquant.calibrate` for a checked ``method`` setting.

    >>> method_specs({"response": {"name": "Debevec 1997", "smoothness": 100.0}})
    {'response': ('Debevec 1997', {'smoothness': 100.0})}
    """
    out: dict[str, Any] = {}
    for step, entry in method.items():
        options = {k: v for k, v in entry.items() if k != "name"}
        out[step] = (entry["name"], options) if options else entry["name"]
    return out


# ------------------------------------------------------------------ cells

CELL_FORMAT = 1
"""Version of a cell's computation and rows; part of every cell's hash."""


def code_version() -> dict[str, str]:
    """The code version a cell's hash includes.

    photoquant's version, the cell format, the versions of numpy and scipy
    (the numbers depend on them) and a digest of the source of the three
    packages (:func:`source_digest`): a cell computed by other code is
    computed again, never reused, even when the version number did not move.
    """
    import numpy as np
    import scipy

    import photoquant

    return {
        "photoquant": photoquant.__version__,
        "cell_format": str(CELL_FORMAT),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "source": source_digest(),
    }


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 (16 hex digits) of the files of ``photoquant``, ``pqsim`` and ``validation``.

    Every file under the packages (code and shipped data, caches excluded),
    by path relative to its package and content, in sorted order.
    """
    import importlib

    digest = hashlib.sha256()
    for name in ("photoquant", "pqsim", "validation"):
        root = Path(importlib.import_module(name).__file__ or "").parent
        for path in sorted(root.rglob("*")):
            if not path.is_file() or "__pycache__" in path.parts or path.suffix == ".pyc":
                continue
            digest.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()[:16]


def cell_config(spec: Any, settings: Mapping[str, Any], seed: int) -> dict[str, Any]:
    """A cell's full configuration as plain data (what it computes depends on nothing else).

    Parameters
    ----------
    spec : SweepSpec
        The sweep (for the preset files, the spec's folder and the render cache).
    settings : mapping
        The cell's settings (:meth:`SweepSpec.settings`).
    seed : int
        The cell's seed.
    """
    files = dict(spec.preset_files)
    camera = camera_fields(settings, Path(spec.base_dir), files)
    config: dict[str, Any] = {
        "settings": json.loads(json.dumps(dict(settings), sort_keys=True)),
        "camera": camera,
        "seed": int(seed),
        "code": code_version(),
    }
    if settings["renderer"] == "mitsuba":
        config["cache_dir"] = spec.cache_dir
    config["cell_id"] = cell_id(config)
    return config


def cell_id(config: Mapping[str, Any]) -> str:
    """The hash of a cell's configuration and the code version (24 hex digits).

    The render cache folder is left out (it changes where renders are kept, not
    what they are).
    """
    content = {k: v for k, v in config.items() if k not in ("cell_id", "cache_dir")}
    text = json.dumps(content, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:24]
