"""Regression testing of the user's own pipeline: record a baseline, hold later versions to it.

``photoquant validate ... --write-baseline FILE`` runs a configuration over
several master seeds and writes a self-describing baseline
(``photoquant.validation-baseline/2``, :func:`validation.baseline.seal_baseline`):
the configuration (mode, profile, each step's method and options, the
presets — a user's preset file by its SHA-256 and content —, chart,
experiments), the seeds, the versions of photoquant, Python and its numeric
libraries, and per metric its value, spread, tolerance and direction.
``--check FILE`` refuses, before anything runs, a baseline whose
configuration differs from the run's (naming the difference), and notes
version differences without failing. :func:`check_against_baseline` does
the same from a user's test suite (``photoquant.testing`` reaches it
through an entry point) and raises an :class:`AssertionError` listing every
regression; :func:`write_junit` writes the comparison as a JUnit XML report.

What is compared
----------------
A run *applies* to a baseline when its conditions
(:meth:`validation.config.ValidationConfig.conditions`), profile, each
step's method and the options the user gave, the presets (by content),
the chart and the rendered-capture switch are the baseline's, and its
experiments and presets are among the baseline's (a subset leaves the
others' metrics "not run"). A method's *code* is what a regression check
exists to watch: the options a method resolves to (defaults included) and
the module that implements it are recorded, and a difference is a note.

The tolerances are those of :mod:`validation.baseline` (``K`` seed-to-seed
spreads, ``K`` chosen by :func:`validation.baseline.k_sigma_for` for the
number of seeds).

References
----------
.. [JUnit] The JUnit XML format as read by CI services (``testsuites`` /
   ``testsuite`` / ``testcase`` with ``failure`` and ``skipped``), e.g.
   https://github.com/testmoapp/junitxml.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from photoquant.io.outputs import Output, OutputKind, check_outputs, file_of_kind
from photoquant.profiles import DEFAULT_PROFILE
from validation.baseline import (
    BASELINE_FORMAT,
    DEFAULT_BASELINE,
    FULL_BASELINE,
    CheckResult,
    check_baseline_applies,
    check_results,
    k_sigma_for,
    load_baseline,
    make_baseline,
    seal_baseline,
    validate_baseline,
)
from validation.config import CONFIGS, ValidationConfig, ValidationError, get_config, preset_labels

__all__ = [
    "DEFAULT_SEEDS",
    "STORED_BASELINES",
    "RunConfiguration",
    "describe_configuration",
    "check_configuration",
    "record_baseline",
    "baseline_from_results",
    "run_check",
    "check_against_baseline",
    "junit_xml",
    "write_junit",
    "BASELINE_FILE",
    "JUNIT_REPORT",
]

DEFAULT_SEEDS: tuple[int, ...] = tuple(range(8))
"""The master seeds a baseline is recorded over by default (the first gives the values)."""

STORED_BASELINES: dict[str, Path] = {"quick": DEFAULT_BASELINE, "full": FULL_BASELINE}
"""The baselines shipped with the package, by mode (``--check`` without a file)."""

VERSIONED = ("photoquant", "numpy", "scipy", "opencv-python-headless", "python")
"""The versions a baseline records and ``--check`` compares (a difference is a note)."""

_CALIBRATE_KEY = {"correspondences": "correspondence_finder"}
"""Step → keyword of :func:`photoquant.calibrate` where they differ."""


def _baseline_file_problem(path: Path) -> str | None:
    """Why the existing file ``path`` is not a validation baseline (None: it is one)."""
    from photoquant.errors import PhotoquantError
    from photoquant.utils import load_json

    try:
        doc = load_json(Path(path), f"{path}")
    except (PhotoquantError, OSError):
        return "it is not a validation baseline (not a JSON file photoquant can read)"
    fmt = doc.get("format") if isinstance(doc, dict) else None
    if not isinstance(fmt, str) or fmt.split("/")[0] != BASELINE_FORMAT.split("/")[0]:
        return "it is not a validation baseline"
    return None


#: A baseline file (``validate --write-baseline``): replaced only if it is a baseline.
BASELINE_FILE = OutputKind("validation baseline", folder=False, problem=_baseline_file_problem)
#: A JUnit XML report (``validate --junit``): replaced only if it is a JUnit report.
JUNIT_REPORT = OutputKind(
    "JUnit XML report",
    folder=False,
    problem=file_of_kind(
        "JUnit XML report",
        lambda head: head.lstrip().startswith(b"<?xml") and b"<testsuite" in head,
    ),
)


def _json(value: Any) -> Any:
    from photoquant.utils import to_json_value

    return json.loads(json.dumps(to_json_value(value), allow_nan=False, default=repr))


# ---------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class RunConfiguration:
    """What ``photoquant validate`` runs: a mode and the user's choices on top of it.

    Parameters
    ----------
    mode : {"quick", "full", "tiny"}
        The built-in configuration (:data:`validation.config.CONFIGS`).
    profile : str, optional
        ``"photoquant"`` or ``"paper"`` (:mod:`photoquant.profiles`); the
        default profile when ``None``.
    methods : mapping
        Step → spec (:func:`photoquant.methods.resolve_method`): a method
        name, ``(name, {option: value})`` or a mapping of options for the
        profile's method; plug-ins' names included. Applied to every
        preset's calibration in the run.
    presets : sequence of str
        Built-in preset names or preset files (``pqsim.preset/1``, ``.json``)
        replacing the mode's ``ccd`` and ``cmos``; empty: the mode's.
    chart : {"analytic", "rendered"}, optional
        The ColorChecker's source (the mode's when ``None``).
    rendered_capture : bool
        Add the rendered-capture experiment.
    peers : bool
        Rank and score the peers' methods too
        (:attr:`~validation.config.ValidationConfig.peers`; the full mode does).
    experiments : sequence of str, optional
        Run only these (:data:`validation.experiments.EXPERIMENTS`).
    cache_dir : str, optional
        Render cache (not part of the configuration).
    """

    mode: str = "quick"
    profile: str | None = None
    methods: Mapping[str, Any] = field(default_factory=dict)
    presets: tuple[str, ...] = ()
    chart: str | None = None
    rendered_capture: bool = False
    peers: bool = False
    experiments: tuple[str, ...] | None = None
    cache_dir: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.methods, Mapping):
            raise ValidationError(
                f"`methods` must map steps to methods, got {type(self.methods).__name__}"
            )
        if isinstance(self.presets, str):
            object.__setattr__(self, "presets", (self.presets,))
        object.__setattr__(self, "presets", tuple(str(p) for p in self.presets))
        object.__setattr__(self, "methods", dict(self.methods))
        if self.experiments is not None:
            if isinstance(self.experiments, str):
                object.__setattr__(self, "experiments", (self.experiments,))
            object.__setattr__(self, "experiments", tuple(self.experiments))

    def validation_config(self) -> ValidationConfig:
        """The :class:`~validation.config.ValidationConfig` of this run.

        Every choice is checked here, before anything runs: an unknown mode,
        profile, step, method, option or preset is a one-line error.
        """
        from photoquant.errors import InputError
        from photoquant.methods import STEPS
        from photoquant.profiles import profile_steps

        config = get_config(self.mode)
        changes: dict[str, Any] = {}
        if self.chart is not None:
            changes["chart"] = self.chart
        if self.rendered_capture:
            changes["rendered_capture"] = True
        if self.peers:
            changes["peers"] = True
        if self.cache_dir is not None:
            changes["render_cache"] = str(Path(self.cache_dir).expanduser())
        kwargs: dict[str, Any] = dict(config.calibrate_kwargs)
        profile = self.profile if self.profile is not None else DEFAULT_PROFILE
        try:
            profile_steps(profile)
        except InputError as exc:
            raise ValidationError(str(exc)) from None
        if profile.lower() != DEFAULT_PROFILE:
            kwargs["profile"] = profile.lower()
        for step, spec in self.methods.items():
            if step not in STEPS:
                raise ValidationError(
                    f"unknown step {step!r} in `methods`; the steps are {', '.join(STEPS)}"
                )
            kwargs[_CALIBRATE_KEY.get(step, step)] = spec
        changes["calibrate_kwargs"] = kwargs
        if self.presets:
            names, files = preset_labels(self.presets)
            changes["presets"] = names
            changes["preset_files"] = files
            if config.sweep_preset not in names:
                changes["sweep_preset"] = names[0]
        config = config.replace(**changes)
        _resolved_steps(config)  # an unknown method or option fails now, with one line
        if self.experiments is not None:
            from validation.experiments import _select

            _select(self.experiments)
        return config


def _resolved_steps(config: ValidationConfig) -> dict[str, Any]:
    """Each step's method and options as :func:`photoquant.calibrate` will resolve them."""
    from photoquant.errors import InputError
    from photoquant.methods import STEPS, options_to_dict, resolve_method
    from photoquant.profiles import profile_steps
    from validation.experiments.shared import calibrate_arguments

    kwargs = calibrate_arguments(config, 0)
    profile = str(kwargs.get("profile", DEFAULT_PROFILE))
    out: dict[str, Any] = {}
    for step in STEPS:
        spec = kwargs.get(_CALIBRATE_KEY.get(step, step))
        try:
            method, options = resolve_method(step, spec, profile_steps(profile)[step])
        except InputError as exc:
            raise ValidationError(str(exc)) from None
        given: Any = spec
        if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str):
            given = {"method": spec[0], "options": dict(spec[1] or {})}
        elif isinstance(spec, str):
            given = {"method": spec, "options": {}}
        elif isinstance(spec, Mapping):
            given = {"options": dict(spec)}
        elif spec is not None:  # an options object
            given = {"method": method.name, "options": options_to_dict(spec)}
        out[step] = {
            "method": method.name,
            "given": _json(given),
            "resolved_options": _json(options_to_dict(options)),
            "module": method.function.__module__,
            "reference": method.reference,
        }
    return out


def _preset_description(config: ValidationConfig, label: str) -> dict[str, Any]:
    from pqsim.synth_camera.presets import preset_fields

    files = dict(config.preset_files)
    if label not in files:
        return {"name": label, "source": "built-in"}
    content = _json(preset_fields(files[label]))
    text = json.dumps(content, sort_keys=True, separators=(",", ":"))
    return {
        "name": label,
        "source": "file",
        "file": Path(files[label]).name,
        "sha256": hashlib.sha256(text.encode()).hexdigest(),
        "content": content,
    }


def describe_configuration(
    config: ValidationConfig, experiments: Sequence[str] | None = None
) -> dict[str, Any]:
    """The JSON description of a run that a format-2 baseline stores.

    Parameters
    ----------
    config : ValidationConfig
        The run's settings (:meth:`RunConfiguration.validation_config`).
    experiments : sequence of str, optional
        The experiments selected (all by default).
    """
    from photoquant.profiles import profile_setting
    from validation.experiments import _select

    profile = str(config.calibrate_kwargs.get("profile", DEFAULT_PROFILE))
    return _json(
        {
            "name": config.name,
            "conditions": config.conditions(),
            "profile": profile,
            "refine_exposures": config.calibrate_kwargs.get(
                "refine_exposures", profile_setting(profile, "refine_exposures")
            ),
            "steps": _resolved_steps(config),
            "presets": [_preset_description(config, p) for p in config.presets],
            "chart": config.chart,
            "rendered_capture": config.rendered_capture,
            "skip_vignetting": config.skip_vignetting,
            "experiments": _select(experiments),
        }
    )


_COMPARED = ("conditions", "profile", "refine_exposures", "chart", "rendered_capture")


def _first_difference(a: Any, b: Any, where: str = "") -> str:
    """A short path to the first place two JSON values differ, with both values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{where}.{k}" if where else k)
    text = f"{where}: baseline {json.dumps(b)[:60]}, this run {json.dumps(a)[:60]}"
    return text


def check_configuration(
    baseline: Mapping[str, Any],
    description: Mapping[str, Any],
    *,
    name: str = "baseline",
) -> list[str]:
    """Refuse a baseline that does not describe the run; return notes on what may differ.

    Parameters
    ----------
    baseline : mapping
        A validated baseline (:func:`validation.baseline.load_baseline`).
    description : mapping
        :func:`describe_configuration` of the run about to start.

    Returns
    -------
    list of str
        Notes: versions, resolved options or implementing modules that differ
        (a method's code may change; that is what the check watches).

    Raises
    ------
    ValidationError
        One line naming the first difference: conditions, profile, a step's
        method or given options, a preset's content, the chart, an
        experiment or a preset the baseline does not have.
    """
    if baseline.get("format") == BASELINE_FORMAT:  # format 1: conditions and the defaults only
        check_baseline_applies(baseline, description["conditions"], name=name)
        mode = str(description.get("name"))
        default = _resolved_steps(get_config(mode)) if mode in CONFIGS else {}
        what = [
            f"the {s} method"
            for s, d in description["steps"].items()
            if d["given"] != (default.get(s) or {}).get("given")
        ]
        if description["profile"] != DEFAULT_PROFILE:
            what.append(f"profile {description['profile']}")
        what += [f"preset {p['name']}" for p in description["presets"] if p["source"] != "built-in"]
        if what:
            raise ValidationError(
                f"{name} (format 1) describes the default pipeline only, not "
                f"{', '.join(what)}: record a baseline of your own with --write-baseline"
            )
        return []
    ref = baseline["configuration"]
    head = f"{name} was recorded for another configuration"
    ref_presets = {p.get("name"): p for p in ref.get("presets") or [] if isinstance(p, dict)}
    for p in description["presets"]:
        theirs = ref_presets.get(p["name"])
        if theirs is None:
            raise ValidationError(
                f"{head}: preset {p['name']!r} is not in the baseline "
                f"(it has {', '.join(map(str, ref_presets)) or 'none'})"
            )
        if (theirs.get("source"), theirs.get("sha256")) != (p["source"], p.get("sha256")):
            diff = _first_difference(p.get("content"), theirs.get("content"))
            raise ValidationError(f"{head}: preset {p['name']!r} differs ({diff})")
    from validation.experiments import OPT_IN, REPORTED_ONLY

    # opt-in experiments (robustness) and reported-only ones are never checked: a baseline
    # need not have them
    extra = [
        e
        for e in description["experiments"]
        if e not in (ref.get("experiments") or []) and e not in OPT_IN and e not in REPORTED_ONLY
    ]
    if extra:
        raise ValidationError(f"{head}: experiment(s) {', '.join(extra)} are not in the baseline")
    ref_steps = ref.get("steps") or {}
    notes = []
    for step, mine in description["steps"].items():
        if step not in ref_steps and not mine.get("given"):
            # a step newer than the baseline (e.g. glare), left at its default: the run
            # is the recorded configuration plus a step the recording code did not have
            notes.append(
                f"note: the {step} step is newer than the baseline; its default "
                f"{mine.get('method')!r} runs"
            )
            continue
        theirs = ref_steps.get(step) or {}
        for part in ("method", "given"):
            if mine.get(part) != theirs.get(part):
                label = "method" if part == "method" else "options given"
                raise ValidationError(
                    f"{head}: {step} {label}: baseline {json.dumps(theirs.get(part))[:60]}, "
                    f"this run {json.dumps(mine.get(part))[:60]}"
                )
    for key in _COMPARED:
        if description.get(key) != ref.get(key):
            raise ValidationError(
                f"{head}: {_first_difference(description.get(key), ref.get(key), key)}"
            )
    for step, mine in description["steps"].items():
        if step not in ref_steps:
            continue
        theirs = ref_steps.get(step) or {}
        if mine["resolved_options"] != theirs.get("resolved_options"):
            notes.append(
                f"note: {step} method {mine['method']!r} resolves to other options than when "
                f"the baseline was recorded ({_first_difference(mine['resolved_options'], theirs.get('resolved_options'))})"
            )
        if mine["module"] != theirs.get("module"):
            notes.append(
                f"note: {step} method {mine['method']!r} is implemented in {mine['module']} "
                f"(baseline: {theirs.get('module')})"
            )
    return notes


def current_versions() -> dict[str, str | None]:
    """The versions a baseline records (:data:`VERSIONED`, with every library's)."""
    import platform

    from validation.experiments import package_versions

    out = dict(package_versions())
    out["python"] = platform.python_version()
    return out


def version_notes(baseline: Mapping[str, Any]) -> list[str]:
    """One note per versioned package whose version differs from the baseline's."""
    ref = baseline.get("versions") or {}
    if not isinstance(ref, dict):
        return []
    now = current_versions()
    return [
        f"note: {dist} {now.get(dist)} (baseline recorded with {ref.get(dist)})"
        for dist in VERSIONED
        if dist in ref and ref.get(dist) != now.get(dist)
    ]


# ---------------------------------------------------------------------------- record, check


Progress = Callable[[str], None]


def _quiet(_message: str) -> None:
    pass


def record_baseline(
    configuration: RunConfiguration | None = None,
    *,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    output: str | Path | None = None,
    overwrite: bool = False,
    progress: Progress | None = None,
    runs: list[Any] | None = None,
) -> dict[str, Any]:
    """Run ``configuration`` over ``seeds`` and return (and write) a format-2 baseline.

    Parameters
    ----------
    configuration : RunConfiguration
        What to run (the quick default when ``None``).
    seeds : sequence of int
        At least two distinct master seeds; the first gives the values, all
        give the spread (tolerance ``k_sigma_for(len(seeds))`` spreads).
    output : path, optional
        Write the baseline here (atomically; an existing file only with ``overwrite``).
    progress : callable, optional
        Receives progress messages (silent by default).
    runs : list, optional
        Receives each seed's :class:`~validation.experiments.ValidationRun`.
    """
    from photoquant.io import write_text_atomic
    from validation.experiments import run_validation
    from validation.report import results_json

    configuration = configuration or RunConfiguration()
    seeds = [int(s) for s in seeds]
    if len(seeds) < 2 or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValidationError(
            f"a baseline needs at least two distinct non-negative seeds, got {seeds}"
        )
    if output is not None:
        check_outputs([Output(Path(output), BASELINE_FILE, "output")], [], overwrite=overwrite)
    config = configuration.validation_config()
    say = progress or _quiet
    results = []
    for s in seeds:
        t0 = time.perf_counter()
        run = run_validation(config, s, experiments=configuration.experiments, progress=say)
        results.append(json.loads(results_json(run)))
        if runs is not None:
            runs.append(run)
        say(f"baseline: seed {s} done in {time.perf_counter() - t0:.0f} s")
    doc = baseline_from_results(results, config, configuration.experiments)
    if output is not None:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(
            output,
            json.dumps(doc, indent=1, allow_nan=False) + "\n",
            overwrite=overwrite,
            replaceable=BASELINE_FILE.problem,
        )
    return doc


def baseline_from_results(
    results: Sequence[Mapping[str, Any]],
    config: ValidationConfig,
    experiments: Sequence[str] | None = None,
) -> dict[str, Any]:
    """A sealed format-2 baseline from the ``results.json`` dicts of runs with different seeds.

    What :func:`record_baseline` does after its runs; runs made separately
    (in parallel, each ``photoquant validate --seed S --json``) give the same
    baseline. The first run gives the values; the tolerance is
    ``k_sigma_for(len(results))`` spreads. The runs must share ``config``'s
    conditions.
    """
    seeds = [r.get("seed") for r in results]
    if len(set(seeds)) != len(seeds):
        raise ValidationError(f"the runs of a baseline need distinct seeds, got {seeds}")
    base = make_baseline(results, k_sigma=k_sigma_for(len(results)))
    if base["conditions"] != _json(config.conditions()):
        raise ValidationError("the runs were not made with this configuration's conditions")
    base["versions"] = current_versions()
    base["tolerance_rule"]["n_seeds"] = len(results)
    base["tolerance_rule"]["k_sigma_rule"] = (
        "2.5 * sqrt((n - 1) / chi2.ppf(1 - p8, n - 1)), p8 = chi2.sf(1.75, 7): the false-alarm "
        "rate of 5 spreads over 8 seeds (validation.baseline.k_sigma_for)"
    )
    return seal_baseline(base, describe_configuration(config, experiments))


def resolve_baseline(
    baseline: str | Path | Mapping[str, Any] | None, mode: str = "quick"
) -> tuple[str, dict[str, Any]]:
    """``(name, baseline)`` from a file, ``"default"``/``None`` (the stored one) or a mapping."""
    if baseline is None or (isinstance(baseline, str) and baseline == "default"):
        if mode not in STORED_BASELINES:
            raise ValidationError(
                f"no stored baseline for the {mode} configuration (stored: "
                f"{', '.join(STORED_BASELINES)}); give a baseline file"
            )
        path = STORED_BASELINES[mode]
        if not path.is_file():
            raise ValidationError(
                f"no baseline of the {mode} configuration is stored with this photoquant "
                f"({path.name}); record one with photoquant validate --{mode} --write-baseline FILE"
            )
        return str(path), load_baseline(path)
    if isinstance(baseline, Mapping):
        doc = json.loads(json.dumps(dict(baseline), allow_nan=False))
        return "baseline", validate_baseline(doc)
    return str(baseline), load_baseline(baseline)


@dataclass
class Prepared:
    """A checked run about to start: its settings, description and the baseline's notes."""

    config: ValidationConfig
    description: dict[str, Any]
    name: str
    baseline: dict[str, Any]
    notes: list[str] = dataclasses.field(default_factory=list)


def prepare_check(
    configuration: RunConfiguration, baseline: str | Path | Mapping[str, Any] | None
) -> Prepared:
    """Load the baseline and refuse it, before anything runs, if it does not describe the run."""
    config = configuration.validation_config()
    description = describe_configuration(config, configuration.experiments)
    name, doc = resolve_baseline(baseline, configuration.mode)
    label = name if name.startswith("baseline") else f"baseline {name}"
    notes = check_configuration(doc, description, name=label)
    return Prepared(config, description, name, doc, notes + version_notes(doc))


def run_check(
    configuration: RunConfiguration,
    baseline: str | Path | Mapping[str, Any] | None = None,
    *,
    seed: int | None = None,
    progress: Progress | None = None,
) -> tuple[CheckResult, dict[str, Any], dict[str, Any]]:
    """Run ``configuration`` and compare it with ``baseline``.

    Returns ``(check, results.json dict, baseline)``. ``seed``: the
    baseline's own (its first) by default, which reproduces its values
    exactly unless something changed.
    """
    from validation.experiments import run_validation
    from validation.report import results_json

    prep = prepare_check(configuration, baseline)
    s = int(prep.baseline.get("seed", 0)) if seed is None else int(seed)
    run = run_validation(
        prep.config, s, experiments=configuration.experiments, progress=progress or _quiet
    )
    results = json.loads(results_json(run))
    check = check_results(results, prep.baseline, name=prep.name)
    check.notes = list(prep.notes)
    return check, results, prep.baseline


def check_against_baseline(
    baseline: str | Path | Mapping[str, Any] | None = None,
    *,
    seed: int | None = None,
    junit: str | Path | None = None,
    **configuration: Any,
) -> CheckResult:
    """Run a configuration, compare it with a recorded baseline, fail naming every regression.

    For a user's own test suite (``photoquant.testing.check_against_baseline``)::

        def test_my_method_holds_its_baseline():
            check_against_baseline("tests/my_method.baseline.json",
                                   methods={"response": "My Method"})

    Parameters
    ----------
    baseline : path, mapping or None
        A baseline file (``photoquant validate --write-baseline``), a loaded
        one, or ``None`` for the stored baseline of ``mode``.
    seed : int, optional
        Master seed (the baseline's own by default).
    junit : path, optional
        Also write a JUnit XML report there.
    **configuration
        The fields of :class:`RunConfiguration`: ``mode``, ``profile``,
        ``methods``, ``presets``, ``chart``, ``rendered_capture``, ``peers``,
        ``experiments``, ``cache_dir``.

    Returns
    -------
    CheckResult
        When no metric regressed.

    Raises
    ------
    AssertionError
        Listing every regressed or missing metric (value, baseline, tolerance).
    ValidationError
        When the baseline is not one, or does not describe the configuration
        (before anything runs).
    """
    try:
        run_configuration = RunConfiguration(**configuration)
    except TypeError as exc:
        fields = ", ".join(f.name for f in dataclasses.fields(RunConfiguration))
        raise ValidationError(f"check_against_baseline: {exc}; the fields are {fields}") from None
    check, results, doc = run_check(run_configuration, baseline, seed=seed)
    if junit is not None:
        write_junit(junit, results, check, doc, overwrite=True)
    if not check.ok:
        raise AssertionError(check.summary())
    return check


# ---------------------------------------------------------------------------- JUnit


def junit_xml(results: Mapping[str, Any], check: CheckResult, baseline: Mapping[str, Any]) -> str:
    """A JUnit XML report of a check: one test case per metric.

    Every metric of the baseline is a test case (``failure`` when it
    regressed or is missing, ``skipped`` when its experiment or preset was
    not run); the run's metrics that are never compared (timings, reported
    figures) and those the baseline lacks are ``skipped`` test cases.
    """
    failed = {f.key: f for f in check.regressions}
    metrics = results.get("metrics", {})
    info = results.get("metric_info", {})
    cases: list[ET.Element] = []
    for key in sorted(set(baseline["metrics"]) | set(metrics)):
        case = ET.Element(
            "testcase",
            {"classname": f"photoquant.validate.{key.split('.')[0]}", "name": key, "time": "0"},
        )
        if key in failed:
            f = failed[key]
            kind = "missing" if f.kind == "missing" else "regression"
            ET.SubElement(case, "failure", {"message": f.message(), "type": kind}).text = (
                f"value {f.value!r}, baseline {f.baseline!r}, tolerance {f.tolerance!r}, "
                f"{f.better} is better"
            )
        elif key not in baseline["metrics"]:
            checked = (info.get(key) or {}).get("check", True)
            why = "not in the baseline" if checked else "reported, never compared (timing)"
            ET.SubElement(case, "skipped", {"message": why})
        elif key not in metrics:
            ET.SubElement(case, "skipped", {"message": "not run"})
        cases.append(case)
    n_fail = sum(1 for c in cases if c.find("failure") is not None)
    n_skip = sum(1 for c in cases if c.find("skipped") is not None)
    suite = ET.Element(
        "testsuite",
        {
            "name": f"photoquant validate {results.get('config', {}).get('name', '')}".strip(),
            "tests": str(len(cases)),
            "failures": str(n_fail),
            "errors": "0",
            "skipped": str(n_skip),
            "time": f"{float(results.get('elapsed_s') or 0.0):.3f}",
        },
    )
    props = ET.SubElement(suite, "properties")
    for pname, value in (
        ("baseline", check.baseline),
        ("seed", str(results.get("seed"))),
        *[("note", n) for n in check.notes],
    ):
        ET.SubElement(props, "property", {"name": pname, "value": str(value)})
    suite.extend(cases)
    root = ET.Element(
        "testsuites", {"tests": str(len(cases)), "failures": str(n_fail), "errors": "0"}
    )
    root.append(suite)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, "unicode") + "\n"


def write_junit(
    path: str | Path,
    results: Mapping[str, Any],
    check: CheckResult,
    baseline: Mapping[str, Any],
    *,
    overwrite: bool = False,
) -> Path:
    """Write :func:`junit_xml` to ``path`` atomically.

    An existing file is replaced only with ``overwrite``, and only if it is a
    JUnit XML report (:data:`JUNIT_REPORT`); missing folders are created.
    """
    from photoquant.io import write_text_atomic

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(
        p,
        junit_xml(results, check, baseline),
        overwrite=overwrite,
        replaceable=JUNIT_REPORT.problem,
    )
    return p
