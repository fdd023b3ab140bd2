"""Method registries: every calibration step is a plug-in.

Each step of the pipeline (:data:`STEPS`) has a registry of methods. A method
is a :class:`Method`: a name, the function that runs it, the dataclass of its
options and, for the steps whose result is stored in a camera, the frozen
model class that :func:`photoquant.load_camera` rebuilds from
``{"method", "params"}``. The pattern is colour-hdri's and colour's
(characterise → frozen model → apply, ``*_METHODS`` registries, a dispatcher
that names the valid methods when given a wrong one).

========================  ===================================================
step                      function signature (see each step's module)
========================  ===================================================
``"response"``            ``fit(stack, options, rng) -> StepFit[ResponseModel]``
``"merge"``               ``merge(stack, response, options) -> MergeResult``
``"balance"``             ``fit(data: BalanceData, options) -> StepFit[BalanceModel]``
``"sensor_lut"``          ``fit(linear, mask, options) -> StepFit[SensorLUTModel]``
``"vignetting"``          ``fit(data: VignettingData, options) -> StepFit[VignettingModel]``
``"correspondences"``     ``find(uniform_views, options) -> list of tracks``
``"glare"``               ``fit(data: GlareData, options) -> StepFit[GlareModel]``
========================  ===================================================

Methods from other distributions are registered through the entry-point
group ``photoquant.methods``: each entry point names a callable that is
called once with no argument and registers its methods with
:func:`register_method` (or returns a :class:`Method` or a list of them). At
run time, :func:`register_method` adds one directly. A name already taken in
a step is an error, never a silent override.

A method is chosen by a *spec*: a name (``"Debevec 1997"``), a pair
``(name, {option: value})``, a mapping of options for the profile's method
of that step, or an options dataclass instance (whose class names its method).
"""

from __future__ import annotations

import dataclasses
import importlib
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Generic, TypeVar

from photoquant.errors import InputError

__all__ = [
    "STEPS",
    "ENTRY_POINT_GROUP",
    "Method",
    "MethodRegistry",
    "StepFit",
    "REGISTRIES",
    "register_method",
    "registry",
    "resolve_method",
    "report_notes",
    "options_from_mapping",
    "load_plugins",
]

STEPS: tuple[str, ...] = (
    "response",
    "merge",
    "balance",
    "sensor_lut",
    "vignetting",
    "correspondences",
    "glare",
)
"""The calibration steps, in the order :func:`photoquant.calibration` runs them
(the balance is estimated last but listed where the paper puts it)."""

MODEL_STEPS: tuple[str, ...] = (
    "response",
    "merge",
    "balance",
    "sensor_lut",
    "vignetting",
    "glare",
)
"""The steps whose result a :class:`~photoquant.model.CameraModel` stores."""

OPTIONAL_MODEL_STEPS: tuple[str, ...] = ("glare",)
"""Model steps a camera file may lack (written before the step existed): they load
as their identity."""

ENTRY_POINT_GROUP = "photoquant.methods"
"""Entry-point group through which other distributions register methods."""

M = TypeVar("M")

_NEEDS = frozenset({"tracks", "flat_field"})

DEFAULT_NEEDS: dict[str, frozenset[str]] = {"vignetting": frozenset({"tracks"})}
"""What a method of a step needs unless it says otherwise (:attr:`Method.needs`)."""


@dataclass(frozen=True)
class StepFit(Generic[M]):
    """What a step's fit returns: the frozen model and a JSON-able report.

    Attributes
    ----------
    model
        The step's model (e.g. :class:`photoquant.response.ResponseModel`).
    report : dict
        Diagnostics (counts, residuals, messages), stored in the camera's report.
    """

    model: M
    report: dict[str, Any] = field(default_factory=dict)


def report_notes(report: Mapping[str, Any], key: str = "notes") -> tuple[str, ...]:
    """The lines a step's report holds for the user under ``key`` (a response method's
    ``"notes"``, the vignetting fit's ``"warnings"``: a list, or one string as one line;
    none by default).

    >>> report_notes({"notes": "one line"}), report_notes({"notes": ["a", "b"]})
    (('one line',), ('a', 'b'))
    """
    notes = report.get(key, ())
    if isinstance(notes, str):
        return (notes,)
    if not isinstance(notes, list | tuple):
        raise InputError(
            f"a step's report `{key}` must be a string or a list of strings, got {notes!r}"
        )
    return tuple(str(n) for n in notes)


@dataclass(frozen=True)
class Method:
    """One method of one step.

    Attributes
    ----------
    step : str
        One of :data:`STEPS`.
    name : str
        The name users select it by (case-insensitive), e.g. ``"Debevec 1997"``.
    function : callable
        Runs the method, with the signature of its step (module docstring).
    options : type, optional
        A dataclass of the method's options; every field has a default.
        ``None``: the method takes no options.
    model : type, optional
        The model class it produces, with ``from_params(params, images)``;
        ``None`` when the step's shared model class is used (the loader then
        asks the step's default model class).
    reference : str
        The paper or source it implements.
    needs : frozenset of str, optional
        The inputs it cannot run without, for :func:`photoquant.calibrate` to
        provide, check or skip: ``"tracks"`` (correspondences across two or
        more views) or ``"flat_field"`` (a flat-field capture). By default the
        step's usual inputs (:data:`DEFAULT_NEEDS`: tracks for vignetting).
    """

    step: str
    name: str
    function: Callable[..., Any]
    options: type | None = None
    model: type | None = None
    reference: str = ""
    needs: frozenset[str] | None = None

    def __post_init__(self) -> None:
        if self.step not in STEPS:
            raise InputError(f"unknown step {self.step!r}; the steps are {', '.join(STEPS)}")
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputError(f"a method's name must be a non-empty string, got {self.name!r}")
        if not callable(self.function):
            raise InputError(f"method {self.name!r}: `function` must be callable")
        if self.options is not None and not dataclasses.is_dataclass(self.options):
            raise InputError(f"method {self.name!r}: `options` must be a dataclass type")
        needs = DEFAULT_NEEDS.get(self.step, frozenset()) if self.needs is None else self.needs
        unknown = set(needs) - _NEEDS
        if unknown:
            raise InputError(
                f"method {self.name!r}: unknown `needs` {sorted(unknown)}; known: {sorted(_NEEDS)}"
            )
        object.__setattr__(self, "needs", frozenset(needs))

    def default_options(self) -> Any:
        """An instance of the options dataclass with every default (``None`` without one)."""
        return None if self.options is None else self.options()


class MethodRegistry(Mapping[str, Method]):
    """The methods of one step, looked up by name, case-insensitively.

    Iteration gives the canonical names in registration order. Entry-point
    plug-ins are loaded on first use (:func:`load_plugins`).
    """

    def __init__(self, step: str) -> None:
        self.step = step
        self._methods: dict[str, Method] = {}

    def _key(self, name: str) -> str | None:
        load_plugins()
        if not isinstance(name, str):
            return None
        if name in self._methods:
            return name
        folded = name.casefold().strip()
        for key in self._methods:
            if key.casefold() == folded:
                return key
        return None

    def __getitem__(self, name: str) -> Method:
        key = self._key(name)
        if key is None:
            raise InputError(
                f"unknown {self.step} method {name!r}; valid methods are: "
                + ", ".join(sorted(self))
            )
        return self._methods[key]

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self._key(name) is not None

    def __iter__(self) -> Iterator[str]:
        load_plugins()
        return iter(list(self._methods))

    def __len__(self) -> int:
        load_plugins()
        return len(self._methods)

    def add(self, method: Method, *, replace: bool = False) -> Method:
        """Register ``method``; a name already taken (case-insensitively) is an error."""
        if method.step != self.step:
            raise InputError(
                f"method {method.name!r} is for step {method.step!r}, not {self.step!r}"
            )
        taken = next((k for k in self._methods if k.casefold() == method.name.casefold()), None)
        if taken is not None and not replace:
            raise InputError(
                f"a {self.step} method named {taken!r} is already registered "
                f"({self._methods[taken].function.__module__}); choose another name"
            )
        if taken is not None:
            del self._methods[taken]
        self._methods[method.name] = method
        return method

    def remove(self, name: str) -> None:
        """Unregister a method (for tests and interactive use)."""
        key = self._key(name)
        if key is None:
            raise InputError(f"no {self.step} method named {name!r} is registered")
        del self._methods[key]

    def __repr__(self) -> str:
        return f"MethodRegistry({self.step!r}, {list(self._methods)})"


REGISTRIES: dict[str, MethodRegistry] = {step: MethodRegistry(step) for step in STEPS}
"""One registry per step. The built-in methods are added by the step modules
when :mod:`photoquant` is imported."""


def registry(step: str) -> MethodRegistry:
    """The registry of ``step`` (one of :data:`STEPS`)."""
    if step not in REGISTRIES:
        raise InputError(f"unknown step {step!r}; the steps are {', '.join(STEPS)}")
    return REGISTRIES[step]


def register_method(
    step: str,
    name: str,
    function: Callable[..., Any],
    *,
    options: type | None = None,
    model: type | None = None,
    reference: str = "",
    needs: frozenset[str] | set[str] | tuple[str, ...] | None = None,
    replace: bool = False,
) -> Method:
    """Register a method of ``step`` under ``name``; returns the :class:`Method`.

    Parameters
    ----------
    step : str
        One of :data:`STEPS`.
    name : str
        The name to select it by; must not be taken already (unless ``replace``).
    function : callable
        The method, with the step's signature (see the module docstring).
    options : dataclass type, optional
        Its options (every field with a default).
    model : type, optional
        The model class it returns, if not the step's shared one; it must
        provide ``from_params(params, images)`` so that a saved camera loads.
    reference : str
        Citation of what it implements.
    needs : set of str, optional
        Inputs it cannot run without (:attr:`Method.needs`; the step's usual
        ones by default).
    replace : bool
        Replace a method of the same name instead of raising.

    Examples
    --------
    >>> import photoquant as pq
    >>> def fit_flat(data, options):
    ...     import numpy as np
    ...     return pq.StepFit(pq.BalanceModel("Flat", np.ones(data.linearised.shape[-1])))
    >>> _ = pq.register_method("balance", "Flat", fit_flat)
    >>> "flat" in pq.registry("balance")
    True
    >>> pq.registry("balance").remove("Flat")
    """
    return registry(step).add(
        Method(
            step,
            name,
            function,
            options=options,
            model=model,
            reference=reference,
            needs=None if needs is None else frozenset(needs),
        ),
        replace=replace,
    )


_BUILTIN_MODULES = (
    "photoquant.response",
    "photoquant.merge",
    "photoquant.response_selection",
    "photoquant.balance",
    "photoquant.sensor_lut",
    "photoquant.vignetting",
    "photoquant.correspondences",
    "photoquant.glare",
    "photoquant.peers",
)
"""Modules whose import registers the built-in methods (loaded before any plug-in)."""

_PLUGINS_LOCK = threading.RLock()
_PLUGINS_STATE: dict[str, Any] = {"loaded": False, "loading": False, "errors": []}


def load_plugins(*, reload: bool = False) -> list[str]:
    """Load the methods of the ``photoquant.methods`` entry points (once).

    Each entry point is called (a callable) or used as it is (a
    :class:`Method` or a sequence of them). Returns the names of the entry
    points loaded. A plug-in that fails to load raises :class:`InputError`
    naming it and its distribution.
    """
    with _PLUGINS_LOCK:
        if (_PLUGINS_STATE["loaded"] and not reload) or _PLUGINS_STATE["loading"]:
            return []
        _PLUGINS_STATE["loading"] = True
        loaded: list[str] = []
        try:
            for module in _BUILTIN_MODULES:  # the built-in methods register themselves
                importlib.import_module(module)
            for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
                dist = getattr(ep.dist, "name", "?")
                try:
                    obj = ep.load()
                    result = obj() if callable(obj) and not isinstance(obj, Method) else obj
                    for method in _as_methods(result):
                        # the same Method again (a reload) is no collision; any
                        # other method under a taken name is an error naming both
                        if REGISTRIES[method.step]._methods.get(method.name) != method:
                            REGISTRIES[method.step].add(method)
                except InputError as exc:
                    raise InputError(f"plug-in {ep.name!r} ({dist}): {exc}") from None
                except Exception as exc:  # noqa: BLE001 - a third-party plug-in can fail anyhow
                    raise InputError(
                        f"plug-in {ep.name!r} ({dist}) failed to load: {type(exc).__name__}: {exc}"
                    ) from None
                loaded.append(ep.name)
            _PLUGINS_STATE["loaded"] = True
        finally:
            _PLUGINS_STATE["loading"] = False
        return loaded


def _as_methods(result: Any) -> list[Method]:
    if result is None:
        return []
    if isinstance(result, Method):
        return [result]
    if isinstance(result, Sequence) and all(isinstance(m, Method) for m in result):
        return list(result)
    raise InputError(
        "an entry point must register its methods and return None, or return Method objects; "
        f"got {type(result).__name__}"
    )


# ---------------------------------------------------------------------------
# Specs → (method, options)
# ---------------------------------------------------------------------------


def options_from_mapping(method: Method, values: Mapping[str, Any]) -> Any:
    """Build ``method``'s options from a mapping; unknown names are an error naming them."""
    if not isinstance(values, Mapping):
        raise InputError(
            f"the options of {method.step} method {method.name!r} must be a mapping, "
            f"got {type(values).__name__}"
        )
    if method.options is None:
        if values:
            raise InputError(
                f"{method.step} method {method.name!r} takes no options, got {sorted(values)}"
            )
        return None
    names = {f.name for f in dataclasses.fields(method.options)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise InputError(
            f"{method.step} method {method.name!r} has no option(s) {', '.join(unknown)}; "
            f"its options are: {', '.join(sorted(names)) or 'none'}"
        )
    try:
        return method.options(**dict(values))
    except InputError as exc:
        raise InputError(f"{method.step} method {method.name!r}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{method.step} method {method.name!r}: bad option: {exc}") from None


def options_to_dict(options: Any) -> dict[str, Any]:
    """The fields of an options dataclass as a plain dict (``{}`` for ``None``)."""
    if options is None:
        return {}
    return {f.name: getattr(options, f.name) for f in dataclasses.fields(options)}


def resolve_method(
    step: str, spec: Any, default: tuple[str, Mapping[str, Any]]
) -> tuple[Method, Any]:
    """Turn a step spec into ``(Method, options)``.

    Parameters
    ----------
    step : str
        One of :data:`STEPS`.
    spec : None, str, (str, mapping), mapping or options instance
        ``None``: ``default`` as it is; a name: that method with its default
        options; ``(name, options)``; a mapping: options for ``default``'s
        method, merged over ``default``'s options; an options dataclass
        instance: the method whose ``options`` class it is; a ``(Method,
        options)`` pair already resolved is returned as it is.
    default : (str, mapping)
        The profile's method and options for this step.

    Examples
    --------
    >>> from photoquant.methods import resolve_method
    >>> method, options = resolve_method("merge", {"weighting": "hat"}, ("Debevec 1997", {}))
    >>> method.name, options.weighting, options.exclude_below_valid_min
    ('Debevec 1997', 'hat', True)
    >>> resolve_method("merge", "Nope", ("Debevec 1997", {}))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    photoquant.errors.InputError: unknown merge method 'Nope'; valid methods are: Debevec 1997, ...
    """
    reg = registry(step)
    default_name, default_options = default
    if spec is None:
        method = reg[default_name]
        return method, options_from_mapping(method, default_options)
    if isinstance(spec, str):
        method = reg[spec]
        # a profile's options stay when the user names the profile's own method
        same = method.name == reg[default_name].name
        return method, options_from_mapping(method, default_options if same else {})
    if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], Method):
        if spec[0].step != step:
            raise InputError(f"method {spec[0].name!r} is for step {spec[0].step!r}, not {step!r}")
        return spec  # already resolved (by resolve_steps)
    if isinstance(spec, tuple):
        if len(spec) != 2 or not isinstance(spec[0], str):
            raise InputError(
                f"the {step} spec must be a name or (name, options), got a tuple of {len(spec)}"
            )
        method = reg[spec[0]]
        base = dict(default_options) if method.name == reg[default_name].name else {}
        return method, options_from_mapping(method, base | dict(spec[1] or {}))
    if isinstance(spec, Mapping):
        method = reg[default_name]
        return method, options_from_mapping(method, dict(default_options) | dict(spec))
    if dataclasses.is_dataclass(spec) and not isinstance(spec, type):
        for method in reg.values():
            if method.options is type(spec):
                return method, spec
        raise InputError(
            f"no {step} method takes options of type {type(spec).__name__}; "
            f"valid methods are: {', '.join(reg)}"
        )
    raise InputError(
        f"the {step} spec must be a method name, (name, options), a mapping of options or an "
        f"options object, got {type(spec).__name__}"
    )
