"""Command line interface: ``photoquant calibrate | correct | characterise | info | methods`` (+ plug-ins).

``validate``, ``demo`` and ``compare`` are added by the ``validation`` package
through the entry-point group ``photoquant.commands``: photoquant itself
never imports the simulator or its consumers.

Every failure caused by the input ends with a non-zero exit status and one
line on standard error saying why; nothing already on disk is overwritten
unless ``--overwrite`` is given, and every output is written atomically.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from photoquant._version import __version__
from photoquant.errors import InputError, PhotoquantError

__all__ = ["main", "build_parser"]

EXIT_INPUT = 2
EXIT_IO = 1
UNCERTAINTY_LAYER = "sigma_ln"
"""EXR layer of ``photoquant correct --uncertainty``: the standard uncertainty of ``ln l``
from the frames' noise."""
CALIBRATION_UNCERTAINTY_LAYER = "sigma_calibration_ln"
"""EXR layer of ``photoquant correct --uncertainty``: the standard uncertainty of ``ln l``
from the calibration's stated statistical errors (response, sensor LUT, vignetting)."""
TOTAL_UNCERTAINTY_LAYER = "sigma_total_ln"
"""EXR layer of ``photoquant correct --uncertainty``: noise and calibration combined."""


def _log(args: argparse.Namespace, message: str) -> None:
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr, flush=True)


def _step_logger(
    args: argparse.Namespace,
) -> tuple[Callable[[str], None], Callable[[], None]]:
    state: dict[str, Any] = {"t": None, "name": None}

    def step(name: str) -> None:
        now = time.perf_counter()
        if state["name"] is not None:
            _log(args, f"  {state['name']}: {now - state['t']:.2f} s")
        state["t"], state["name"] = now, name
        _log(args, f"photoquant: {name} ...")

    def done() -> None:
        if state["name"] is not None:
            _log(args, f"  {state['name']}: {time.perf_counter() - state['t']:.2f} s")

    return step, done


def _fmt(values: Any) -> str:
    """A number as ``a``, numbers as ``[a, b, c]``; anything else (an untrusted camera's
    report) as its repr."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        return repr(values)[:80]
    if arr.ndim == 0:
        return f"{float(arr):.4g}"
    return "[" + ", ".join(f"{v:.4g}" for v in arr.ravel()) + "]"


def _median_and_p95(sigma: np.ndarray) -> str:
    """``median M, 95th percentile P`` of an uncertainty layer's finite values (``nan``
    where it has none)."""
    finite = sigma[np.isfinite(sigma)]
    median = np.median(finite) if finite.size else float("nan")
    p95 = np.percentile(finite, 95) if finite.size else float("nan")
    return f"median {median:.3g}, 95th percentile {p95:.3g}"


def _parse_value(text: str) -> Any:
    """A command-line option value: JSON when it parses (numbers, true/false, lists), else text."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def step_specs(args: argparse.Namespace) -> dict[str, Any]:
    """Per-step specs for :func:`photoquant.calibrate` from ``--method``, ``--option`` and shortcuts."""
    from photoquant.methods import STEPS

    names: dict[str, str] = {}
    options: dict[str, dict[str, Any]] = {}
    for item in args.method or []:
        step, sep, name = item.partition("=")
        if not sep or step not in STEPS or not name:
            raise InputError(
                f"--method takes STEP=NAME with STEP one of {', '.join(STEPS)}, got {item!r}"
            )
        names[step] = name
    for item in args.option or []:
        key, sep, value = item.partition("=")
        step, dot, name = key.partition(".")
        if not sep or not dot or step not in STEPS or not name:
            raise InputError(
                f"--option takes STEP.NAME=VALUE with STEP one of {', '.join(STEPS)}, got {item!r}"
            )
        options.setdefault(step, {})[name] = _parse_value(value)
    shortcuts = {
        ("response", "smoothness"): args.smoothness,
        ("response", "n_samples"): args.samples,
        ("merge", "weighting"): args.merge_weighting,
        ("balance", "stage"): args.balance_stage,
    }
    for (step, name), value in shortcuts.items():
        if value is not None:
            options.setdefault(step, {}).setdefault(name, value)
    if args.merge_method is not None:
        names.setdefault("merge", args.merge_method)
    specs: dict[str, Any] = {}
    for step in STEPS:
        if step in names:
            specs[step] = (names[step], options.get(step, {}))
        elif step in options:
            specs[step] = options[step]
    if "correspondences" in specs:
        specs["correspondence_finder"] = specs.pop("correspondences")
    return specs


def _exr_on_every_cpu(
    command: Callable[[argparse.Namespace], int],
) -> Callable[[argparse.Namespace], int]:
    """The command with OpenEXR's thread pool at every CPU while it runs
    (:func:`photoquant.io.images.exr_threads`; the pool emptied again after it)."""

    @functools.wraps(command)
    def run(args: argparse.Namespace) -> int:
        from photoquant.io.images import exr_threads

        with exr_threads():
            return command(args)

    return run


@_exr_on_every_cpu
def _cmd_calibrate(args: argparse.Namespace) -> int:
    from photoquant.calibration import calibrate_manifest
    from photoquant.io.manifest import load_manifest
    from photoquant.io.outputs import CAMERA, Output, check_outputs, manifest_inputs

    out = Path(args.output)
    try:  # read once, for the outputs' check and the calibration
        manifest = load_manifest(args.manifest, allow_outside=args.allow_outside)
    except (PhotoquantError, OSError, RecursionError):
        manifest = None  # reported by calibrate_manifest, after the outputs' check
    check_outputs(
        [Output(out, CAMERA)],
        manifest_inputs(args.manifest, allow_outside=args.allow_outside, loaded=manifest),
        overwrite=args.overwrite,
    )
    specs = step_specs(args)
    step, done = _step_logger(args)
    step("loading frames")
    model = calibrate_manifest(
        args.manifest if manifest is None else manifest,
        allow_outside=args.allow_outside,
        progress_bars=not args.quiet,
        profile=args.profile,
        seed=args.seed,
        progress=step,
        refine_exposures=args.refine_exposures,
        dark_subtraction=args.dark_subtraction,
        **specs,
    )
    done()
    model.save(out, overwrite=args.overwrite)
    _print_summary(model, out)
    return 0


def _section(report: dict[str, Any], key: str) -> dict[str, Any]:
    value = report.get(key)
    return value if isinstance(value, dict) else {}


def _uncertainty_summary(model: Any) -> dict[str, Any]:
    """The calibrated parameters' standard uncertainties, where the steps state them
    (``ln`` units; the response's median and largest over its measured levels)."""
    out: dict[str, Any] = {}
    std = model.response.log_inverse_std()
    if std is not None:
        medians, largest = [], []
        for ch in range(std.shape[0]):
            inside = (model.response.levels >= model.response.valid_min[ch]) & (
                model.response.levels < model.response.saturation_level[ch]
            )
            s = std[ch][inside] if inside.any() else std[ch]
            medians.append(float(np.median(s)))
            largest.append(float(np.max(s)))
        out["response_log_std"] = {"median": medians, "largest": largest}
    lut_variance = model.sensor_lut.log_variance
    if lut_variance is not None:
        flat = lut_variance.reshape(-1, lut_variance.shape[-1]).astype(np.float64)
        out["sensor_lut_log_std_median"] = np.sqrt(np.median(flat, axis=0)).tolist()
    cov = getattr(model.vignetting, "param_covariance", None)
    if cov is not None:
        out["vignetting_param_std"] = np.sqrt(
            np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None)
        ).tolist()
    if model.balance.log_variance is not None:
        out["balance_log_std"] = np.sqrt(model.balance.log_variance).tolist()
    return out


def _selection_line(record: Any) -> str | None:
    """The response model's selection (``report["response"]["selection"]``) in one line:
    the choice, the rule, and every candidate's held-out score; ``None`` where the
    record is absent or unreadable (a camera's report is untrusted)."""
    if not isinstance(record, dict) or not isinstance(record.get("chosen"), dict):
        return None

    def label(entry: Any) -> str:
        from photoquant.response_selection import CandidateScore

        if not isinstance(entry, dict):
            return "?"
        options = entry.get("options")
        name = str(entry.get("method", "?"))[:60]
        opts = options if isinstance(options, dict) else {}
        return CandidateScore(name, opts, math.nan, math.nan, 0).label

    def score(entry: Any) -> str:
        if not isinstance(entry, dict):
            return "?"
        value, se = entry.get("score_dn"), entry.get("difference_se_dn")
        if entry.get("error") is not None or not isinstance(value, int | float):
            return "failed"
        spread = f" ± {se:.2g}" if isinstance(se, int | float) and se > 0 else ""
        return f"{value:.3g}{spread} DN"

    candidates = record.get("candidates")
    scored = (
        "; ".join(f"{label(c)} {score(c)}" for c in candidates)
        if isinstance(candidates, list) and candidates
        else "none scored"
    )
    return (
        f"response model chosen: {label(record['chosen'])}, by the {record.get('rule', '?')} "
        f"rule (held-out systematic error, ± its standard error against the best: {scored})"
    )


def _print_summary(model: Any, where: Path | None = None) -> None:
    """What a camera holds, from its models and (defensively) its report."""
    rep = model.report if isinstance(model.report, dict) else {}
    lines = []
    if where is not None:
        lines.append(f"camera written to {printable(where)}")
    h, w = model.image_shape
    lines.append(f"image {w}x{h}, {model.bit_depth}-bit, channels {' '.join(model.channels)}")
    profile = model.parameters.get("profile")
    if isinstance(profile, str):
        lines.append(f"profile: {profile}")
    lines.append("methods: " + ", ".join(f"{k} {m.method}" for k, m in model.steps().items()))
    resp = _section(rep, "response")
    line = f"response: saturation {_fmt(model.response.saturation_level)}"
    line += f", valid from {_fmt(model.response.valid_min)}"
    if "n_samples" in resp:
        line += f", samples {_fmt(resp['n_samples'])}"
    if "residual_rms" in resp:
        line += f", residual rms (ln) {_fmt(resp['residual_rms'])}"
    refined = resp.get("refined_in_values")
    if isinstance(refined, np.ndarray):
        refined = refined.tolist()
    if isinstance(refined, list):
        names = [c for c, r in zip(model.channels, refined, strict=False) if r is True]
        if names:
            line += f", refined in the values ({' '.join(names)})"
    lines.append(line)
    selection = _selection_line(resp.get("selection"))
    if selection is not None:
        lines.append(selection)
    stated = _uncertainty_summary(model)
    if "response_log_std" in stated:
        pairs = zip(*stated["response_log_std"].values(), strict=True)
        how = resp.get("covariance")
        lines.append(
            "response uncertainty: std of g (ln, median/largest over the measured levels, "
            f"relative to {model.response.covariance_reference or 'mid-range'}"
            + (f"; {how}" if isinstance(how, str) else "")
            + ") "
            + " ".join(f"{m:.2g}/{x:.2g}" for m, x in pairs)
        )
    line = f"balance: {_fmt(model.balance.factors)}"
    if "balance_log_std" in stated:
        what = "white chart's noise"
        if "uncorrected_bias_log" in _section(rep, "balance"):
            what += " and the linearised reading's bias against the uniformised"
        line += f", uncertainty of ln a ({what}) {_fmt(stated['balance_log_std'])}"
    lines.append(line)
    noise = model.parameters.get("noise")
    if isinstance(noise, dict) and "gain_dn_per_e" in noise:
        lines.append(
            f"noise: gain {_fmt(noise.get('gain_dn_per_e'))} DN/e-, read noise "
            f"{_fmt(noise.get('read_noise_dn'))} DN (photon transfer of view 0's repeats, "
            "on the response's linear scale)"
        )
    lut = _section(rep, "sensor_lut")
    if "prnu_std" in lut:
        line = f"sensor LUT: PRNU std {_fmt(lut['prnu_std'])}, flagged {lut.get('n_flagged')}"
        if "sensor_lut_log_std_median" in stated:
            line += f", noise of u (ln, median) {_fmt(stated['sensor_lut_log_std_median'])}"
        lines.append(line)
    vig = _section(rep, "vignetting")
    if "n_tracks" in vig:
        line = (
            f"vignetting: {vig.get('n_tracks')} correspondences used of "
            f"{vig.get('n_tracks_given')} ({vig.get('correspondence_source')}), "
            f"{vig.get('n_pairs')} pairs, residual rms {_fmt(vig.get('residual_rms'))}"
        )
        if "uncorrected_bias_rms" in vig:
            line += (
                ", uncorrected bias against the default fit (ln v, rms) "
                f"{_fmt(vig['uncorrected_bias_rms'])}, in its uncertainty"
            )
        lines.append(line)
    params = getattr(model.vignetting, "params", None)
    if (
        isinstance(params, np.ndarray)
        and params.ndim == 2
        and params.shape[0] == len(model.channels)
    ):
        param_std = stated.get("vignetting_param_std")
        for ch, (name, row) in enumerate(zip(model.channels, params, strict=True)):
            line = f"  {name}: {model.vignetting.method} {_fmt(row)}"
            if param_std is not None:
                line += f" ± {_fmt(param_std[ch])}"
            lines.append(line)
    if not model.glare.is_identity:  # the glare step (photoquant.glare)
        fit = _section(rep, "glare")
        lines.append(
            f"glare: fraction {_fmt(model.glare.fraction)}, width {_fmt(model.glare.width_px)} px"
            f" (Moffat beta {model.glare.beta:g}), fit rms (ln) {_fmt(fit.get('rms_log_residual'))}"
        )
    from photoquant.adequacy import ModelAdequacy

    adequacy = ModelAdequacy.from_dict(rep.get("model_adequacy"))
    if adequacy is not None:
        lines.append(f"model adequacy: {adequacy.describe()}")
    exposures = _section(rep, "exposures")
    stacks = [("view " + str(i), e) for i, e in enumerate(exposures.get("views") or [])]
    if isinstance(exposures.get("irradiance"), dict):
        stacks.append(("irradiance", exposures["irradiance"]))
    for name, e in stacks:
        if isinstance(e, dict) and "exposure_s" in e:
            lines.append(f"exposures {name}: {_exposure_line(e)}")
    notes = rep.get("notes", [])
    for note in notes if isinstance(notes, list) else []:
        lines.append(f"note: {note}")
    timings = _section(rep, "timings_s")
    if timings:
        lines.append(
            "time: " + ", ".join(f"{k.replace('_', ' ')} {_fmt(v)} s" for k, v in timings.items())
        )
    print("\n".join(lines))


def _exposure_line(record: dict[str, Any]) -> str:
    """Refined exposure times beside the nominal ones, in ms: ``nominal -> refined ± std``."""
    try:
        nominal = np.asarray(record["nominal_s"], dtype=float)
        refined = np.asarray(record["exposure_s"], dtype=float)
        std = np.asarray(
            [np.nan if v is None else v for v in record.get("log_std", [])], dtype=float
        )
    except (KeyError, TypeError, ValueError):
        return "(unreadable record)"
    parts = []
    for k, (t0, t1) in enumerate(zip(nominal, refined, strict=False)):
        err = f" ± {100 * std[k]:.2f} %" if k < std.size and np.isfinite(std[k]) else ""
        parts.append(f"{1e3 * t0:.4g} -> {1e3 * t1:.4g}{err}")
    return "ms nominal -> refined: " + ", ".join(parts)


def printable(path: Any) -> str:
    """A path as text that any terminal encoding can print (undecodable bytes escaped)."""
    text = str(path)
    encoding = getattr(sys.stdout, "encoding", None) or "utf-8"
    return text.encode(encoding, "backslashreplace").decode(encoding, "replace")


@_exr_on_every_cpu
def _cmd_correct(args: argparse.Namespace) -> int:
    from photoquant.correction import correct_manifest
    from photoquant.io.atomic import atomic_output_file
    from photoquant.io.images import write_exr
    from photoquant.io.outputs import (
        EXR_IMAGE,
        Output,
        camera_inputs,
        check_outputs,
        manifest_inputs,
    )
    from photoquant.model import load_camera

    out = Path(args.output)
    check_outputs(
        [Output(out, EXR_IMAGE)],
        manifest_inputs(args.manifest, allow_outside=args.allow_outside)
        + camera_inputs(args.camera),
        overwrite=args.overwrite,
    )
    if out.suffix.lower() != ".exr":
        raise PhotoquantError(f"the output must be an OpenEXR file (.exr), got {out}")
    t0 = time.perf_counter()
    model = load_camera(args.camera)
    result = correct_manifest(
        args.manifest,
        model,
        allow_outside=args.allow_outside,
        progress_bars=not args.quiet,
        refine_exposures=args.refine_exposures,
        dark_subtraction=args.dark_subtraction,
        uncertainty=args.uncertainty,
    )
    image, names = result.photoquantity, list(model.channels)
    description = f"photoquantity l = exp(merge)/(u*v), v{__version__}; NaN = no valid exposure"
    if result.log_sigma_noise is not None:
        image = np.concatenate([image, result.log_sigma_noise], axis=-1)
        names += [f"{UNCERTAINTY_LAYER}.{c}" for c in model.channels]
        description += (
            f"; {UNCERTAINTY_LAYER}.*: standard uncertainty of ln l from the frames' noise"
        )
    calibration = result.log_sigma_calibration
    if calibration is not None:
        total = result.log_sigma  # never None here: the calibration's components are in it
        image = np.concatenate([image, calibration, calibration if total is None else total], -1)
        names += [f"{CALIBRATION_UNCERTAINTY_LAYER}.{c}" for c in model.channels]
        names += [f"{TOTAL_UNCERTAINTY_LAYER}.{c}" for c in model.channels]
        description += (
            f"; {CALIBRATION_UNCERTAINTY_LAYER}.*: standard uncertainty of ln l from the "
            "calibration's statistical errors (response, sensor LUT, vignetting; common to "
            "every scene); "
            f"{TOTAL_UNCERTAINTY_LAYER}.*: both combined, with the refined exposure times' "
            "and the merge weighting's stated bias where there are"
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    # no replace without the flag, and only of an OpenEXR image
    with atomic_output_file(out, overwrite=args.overwrite, replaceable=EXR_IMAGE.problem) as tmp:
        write_exr(tmp, image, channels=names, metadata={"photoquant": description})
    finite = result.photoquantity[~result.mask]
    print(
        f"photoquantity written to {out}: {result.photoquantity.shape[1]}x"
        f"{result.photoquantity.shape[0]}, flagged {int(result.mask.any(axis=-1).sum())} pixels "
        f"({int(result.all_saturated.any(axis=-1).sum())} saturated, "
        f"{int(result.all_dark.any(axis=-1).sum())} dark), range "
        f"[{finite.min() if finite.size else float('nan'):.4g}, "
        f"{finite.max() if finite.size else float('nan'):.4g}], "
        f"{time.perf_counter() - t0:.2f} s"
    )
    if result.log_sigma_noise is not None and result.noise is not None:
        print(
            f"uncertainty of ln l from noise ({result.noise.source} gain and read noise): "
            f"{_median_and_p95(result.log_sigma_noise)}, "
            f"channels {UNCERTAINTY_LAYER}.* in {out.name}"
        )
    if calibration is not None:
        named = [
            name
            for name, part in (
                ("response", result.log_sigma_response),
                ("sensor LUT", result.log_sigma_sensor_lut),
                ("vignetting", result.log_sigma_vignetting),
                ("balance", result.log_sigma_balance),
            )
            if part is not None
        ]
        parts = ", ".join(named[:-1]) + (" and " if len(named) > 1 else "") + named[-1]
        print(
            f"uncertainty of ln l from the calibration ({parts}): "
            f"{_median_and_p95(calibration)}, "
            f"channels {CALIBRATION_UNCERTAINTY_LAYER}.*, combined with the noise in "
            f"{TOTAL_UNCERTAINTY_LAYER}.* in {out.name}"
        )
    if result.log_sigma_exposure is not None:
        sigma = result.log_sigma_exposure[np.isfinite(result.log_sigma_exposure)]
        print(
            "uncertainty of ln l from the refined exposure times: "
            f"median {np.median(sigma) if sigma.size else float('nan'):.3g} "
            f"(in {TOTAL_UNCERTAINTY_LAYER}.*)"
        )
    if result.log_sigma_weighting is not None:
        print(
            "uncertainty of ln l from the merge weighting's bias against the default "
            f"weighting: {_median_and_p95(result.log_sigma_weighting)} "
            f"(in {TOTAL_UNCERTAINTY_LAYER}.*)"
        )
    if result.exposures is not None:
        print(f"scene exposures: {_exposure_line(result.exposures.as_dict())}")
    for note in result.notes:
        print(f"note: {note}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from photoquant.model import load_camera

    model = load_camera(args.camera)
    if args.json:
        data = model.to_json_dict()
        print(
            json.dumps(
                {k: data[k] for k in ("parameters", "report")}
                | {"steps": {k: v["method"] for k, v in data["steps"].items()}}
                | {"uncertainty": _uncertainty_summary(model)},
                indent=1,
            )
        )
    else:
        _print_summary(model)
    return 0


def _cmd_methods(args: argparse.Namespace) -> int:
    import dataclasses

    from photoquant.methods import STEPS, registry
    from photoquant.profiles import PROFILES

    out: dict[str, Any] = {}
    for step in STEPS:
        out[step] = {}
        for name, method in registry(step).items():
            opts = {}
            if method.options is not None:
                opts = {
                    f.name: method.options().__dict__[f.name]
                    for f in dataclasses.fields(method.options)
                }
            out[step][name] = {
                "options": opts,
                "reference": method.reference,
                "module": method.function.__module__,
                "in profiles": [p for p, steps in PROFILES.items() if steps[step][0] == name],
            }
    if args.json:
        print(json.dumps(out, indent=1, default=str))
        return 0
    for step, methods in out.items():
        print(f"{step}:")
        for name, info in methods.items():
            tag = f" (profiles: {', '.join(info['in profiles'])})" if info["in profiles"] else ""
            print(f"  {name}{tag} — {info['module']}")
            if info["reference"].startswith("peer ("):  # a peer says whether it is installed
                print(f"    {info['reference']}")
            if info["options"]:
                print("    options: " + ", ".join(f"{k}={v!r}" for k, v in info["options"].items()))
    return 0


def _crossval_options(items: list[str] | None) -> dict[str, Any]:
    """``--option NAME=VALUE`` of ``crossval``: options of the response method."""
    options: dict[str, Any] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise InputError(f"--option takes NAME=VALUE, got {item!r}")
        options[name] = _parse_value(value)
    return options


def _cmd_crossval(args: argparse.Namespace) -> int:
    from photoquant.crossval import crossval_manifest

    result = crossval_manifest(
        args.manifest,
        args.method,
        roi=args.roi,
        allow_outside=args.allow_outside,
        seed=args.seed,
        profile=args.profile,
        options=_crossval_options(args.option),
        calibration_only=args.calibration_only,
    )
    print(json.dumps(result.to_json(), indent=1) if args.json else result.format_table())
    return 0


def _cmd_characterise(args: argparse.Namespace) -> int:
    from photoquant.characterise import CHARACTERISATION_REPORT, characterise_manifest
    from photoquant.io.outputs import Output, camera_inputs, check_outputs, manifest_inputs
    from photoquant.model import load_camera

    out = Path(args.output)
    inputs = manifest_inputs(args.manifest, allow_outside=args.allow_outside)
    check_outputs(
        [Output(out, CHARACTERISATION_REPORT)],
        [*inputs, *camera_inputs(args.camera)],
        overwrite=args.overwrite,
    )
    camera = load_camera(args.camera)
    char = characterise_manifest(args.manifest, camera, allow_outside=args.allow_outside)
    char.save(out, overwrite=args.overwrite, camera=camera)
    for key in ("gain", "read_noise_e", "full_well_e", "dsnu_e", "prnu"):
        q = char.quantities.get(key)
        if q is not None:
            _log(args, f"  {key}: {_fmt(q.value)} ± {_fmt(q.uncertainty)} {q.unit}")
    _log(args, f"photoquant: characterisation written to {out}")
    return 0


COMMAND_ENTRY_POINTS = "photoquant.commands"
"""Entry-point group of sub-commands other distributions add (``validate``,
``demo`` and ``compare`` come from the ``validation`` package this way):
each names a callable ``register(subparsers)`` that adds its sub-parser and
sets ``func``."""


def _add_plugin_commands(sub: Any) -> None:
    from importlib import metadata

    for ep in sorted(metadata.entry_points(group=COMMAND_ENTRY_POINTS), key=lambda e: e.name):
        try:
            register = ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plug-in must not break the CLI
            print(
                f"photoquant: warning: command {ep.name!r} could not load: {exc}", file=sys.stderr
            )
            continue
        register(sub)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``photoquant`` command."""
    parser = argparse.ArgumentParser(
        prog="photoquant",
        description="Radiometric camera calibration and photoquantity measurement.",
    )
    parser.add_argument("--version", action="version", version=f"photoquant {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for add_command in (
        _add_calibrate,
        _add_correct,
        _add_info,
        _add_methods,
        _add_crossval,
        _add_characterise,
    ):
        add_command(sub)
    _add_plugin_commands(sub)
    return parser


def _add_calibrate(sub: Any) -> None:
    """``photoquant calibrate``: a capture manifest to a camera folder."""
    from photoquant.profiles import DEFAULT_PROFILE, PROFILES
    from photoquant.weighting import WEIGHTING_FUNCTIONS

    cal = sub.add_parser("calibrate", help="calibrate a camera from a capture manifest")
    cal.add_argument("manifest", help="capture manifest (photoquant.captures/1 JSON)")
    cal.add_argument("-o", "--output", required=True, help="camera folder to write")
    cal.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        default=DEFAULT_PROFILE,
        help="the methods and options of every step: the paper's, or photoquant's (default)",
    )
    cal.add_argument(
        "--method",
        action="append",
        metavar="STEP=NAME",
        help="the method of a step (repeatable; `photoquant methods` lists them), "
        "e.g. --method vignetting=None",
    )
    cal.add_argument(
        "--option",
        action="append",
        metavar="STEP.NAME=VALUE",
        help="an option of a step's method (repeatable; VALUE is JSON or text), "
        "e.g. --option response.smoothness=300",
    )
    cal.add_argument("--smoothness", type=float, help="same as --option response.smoothness=B")
    cal.add_argument("--samples", type=int, help="same as --option response.n_samples=N")
    cal.add_argument(
        "--balance-stage",
        choices=["uniformised", "linearised"],
        help="same as --option balance.stage=S: read the white chart after (photoquant) or "
        "before (paper) the LUT and vignetting",
    )
    cal.add_argument(
        "--merge-weighting",
        choices=sorted(WEIGHTING_FUNCTIONS),
        help="same as --option merge.weighting=W (hat is the paper's exactly)",
    )
    cal.add_argument("--merge-method", help="same as --method merge=NAME")
    cal.add_argument("--seed", type=int, default=0, help="seed of the sample selection")
    cal.set_defaults(func=_cmd_calibrate)
    _add_capture_options(cal)


def _add_correct(sub: Any) -> None:
    """``photoquant correct``: a manifest's scene to an OpenEXR photoquantity."""
    cor = sub.add_parser("correct", help="measure the photoquantity of a manifest's scene")
    cor.add_argument("manifest", help="capture manifest with `scene` frames")
    cor.add_argument("--camera", required=True, help="camera folder from `photoquant calibrate`")
    cor.add_argument("-o", "--output", required=True, help="OpenEXR file to write (R, G, B)")
    cor.add_argument(
        "--uncertainty",
        dest="uncertainty",
        action="store_true",
        default="auto",
        help=f"require the standard uncertainty of ln l (an error where it cannot be "
        f"stated); by default it is written wherever it can be: from the frames' noise "
        f"(channels {UNCERTAINTY_LAYER}.R, ...) and, where the camera's fits state their "
        f"covariance, from the calibration's statistical errors "
        f"({CALIBRATION_UNCERTAINTY_LAYER}.R, ...; both combined: "
        f"{TOTAL_UNCERTAINTY_LAYER}.R, ...)",
    )
    cor.add_argument(
        "--no-uncertainty",
        dest="uncertainty",
        action="store_false",
        help="write the photoquantity alone (R, G, B)",
    )
    cor.set_defaults(func=_cmd_correct)
    _add_capture_options(cor)


def _add_capture_options(p: argparse.ArgumentParser) -> None:
    """The options ``calibrate`` and ``correct`` share: output, paths, progress, exposure
    refinement and dark subtraction."""
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument(
        "--allow-outside",
        action="store_true",
        help="allow manifest paths outside the manifest's folder",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    p.add_argument(
        "--refine-exposures",
        dest="refine_exposures",
        action="store_true",
        default=None,
        help="re-estimate the frames' exposure times from the data (photoquant.exposure; "
        "the photoquant profile's default, not the paper profile's)",
    )
    p.add_argument(
        "--no-refine-exposures",
        dest="refine_exposures",
        action="store_false",
        help="keep the frames' nominal exposure times",
    )
    p.add_argument(
        "--dark-subtraction",
        dest="dark_subtraction",
        action="store_true",
        default=None,
        help="subtract the manifest's `dark` frames pixel by pixel (photoquant.darkframe); "
        "default: the manifest's `dark_subtraction`",
    )
    p.add_argument(
        "--no-dark-subtraction",
        dest="dark_subtraction",
        action="store_false",
        help="use the `dark` frames' mean as the black level only",
    )


def _add_info(sub: Any) -> None:
    """``photoquant info``: describe a camera folder."""
    info = sub.add_parser("info", help="describe a calibrated camera")
    info.add_argument("camera", help="camera folder")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(func=_cmd_info)


def _add_methods(sub: Any) -> None:
    """``photoquant methods``: every step's methods and options."""
    meth = sub.add_parser("methods", help="list the methods of every step and their options")
    meth.add_argument("--json", action="store_true", help="machine-readable output")
    meth.set_defaults(func=_cmd_methods)


def _add_crossval(sub: Any) -> None:
    """``photoquant crossval``: leave-one-exposure-out cross-validation of a response method."""
    from photoquant.profiles import DEFAULT_PROFILE, PROFILES

    xval = sub.add_parser(
        "crossval",
        help="leave-one-exposure-out cross-validation on views[0] of a manifest: calibrate on "
        "K - 1 frames, correct them, predict the held-out one",
    )
    xval.add_argument("manifest", help="capture manifest (photoquant.captures/1 JSON)")
    xval.add_argument(
        "--method",
        default="Debevec 1997",
        help="a response method (calibrate's default pipeline) or a peer: 'opencv' "
        "(default: Debevec 1997)",
    )
    xval.add_argument("--json", action="store_true", help="machine-readable output")
    xval.add_argument(
        "--roi",
        type=int,
        nargs=4,
        metavar=("X0", "Y0", "X1", "Y1"),
        help="score only this box (end exclusive); default: the manifest's crossval_roi",
    )
    xval.add_argument("--seed", type=int, default=0, help="seed of the sample selection")
    xval.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        default=DEFAULT_PROFILE,
        help="the calibration profile the response method runs in (default photoquant)",
    )
    xval.add_argument(
        "--option",
        action="append",
        metavar="NAME=VALUE",
        help="an option of the response method (repeatable; VALUE is JSON or text), "
        "e.g. --option wide_steps=none",
    )
    xval.add_argument(
        "--calibration-only",
        action="store_true",
        help="predict from the calibration's own merge, not from `correct` of the same frames "
        "with the calibrated camera (the default, the path users run): scores the response "
        "and merge alone",
    )
    xval.add_argument(
        "--allow-outside", action="store_true", help="allow paths outside the manifest's folder"
    )
    xval.set_defaults(func=_cmd_crossval)


def _add_characterise(sub: Any) -> None:
    """``photoquant characterise``: an EMVA-1288-style noise report of a camera."""
    char = sub.add_parser(
        "characterise",
        help="EMVA-1288-style noise report of a calibrated camera (gain, read noise, full "
        "well, DSNU, PRNU) from its capture manifest, through its recovered response",
    )
    char.add_argument("manifest", help="the capture manifest the camera was calibrated from")
    char.add_argument("--camera", required=True, help="camera folder from `photoquant calibrate`")
    char.add_argument("-o", "--output", required=True, help="report folder to write")
    char.add_argument("--overwrite", action="store_true", help="replace an existing report")
    char.add_argument(
        "--allow-outside", action="store_true", help="allow paths outside the manifest's folder"
    )
    char.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    char.set_defaults(func=_cmd_characterise)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``photoquant`` command; returns the exit status.

    ``argv`` None: the process's own arguments, as the installed command
    runs; the process is then the command's, and its memory advice is set
    for a command's work (:func:`photoquant._environ.prefer_small_pages`).
    """
    from photoquant._environ import check_environment, prefer_small_pages
    from photoquant._signals import Terminated, handle_signals
    from photoquant._stdio import safe_stdio
    from photoquant.io.atomic import remove_live_temporaries

    safe_stdio()  # a strict locale must not turn a file name into a traceback
    if argv is None:
        prefer_small_pages()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        check_environment()  # a bad variable is one line now, not a failure per frame or cell
        with handle_signals():  # SIGTERM / Ctrl-C: clean exit, temporaries removed
            return int(args.func(args) or 0)
    except PhotoquantError as exc:
        print(f"photoquant: error: {printable(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except OSError as exc:
        print(f"photoquant: error: {printable(exc)}", file=sys.stderr)
        return EXIT_IO
    except KeyboardInterrupt:
        remove_live_temporaries()
        print("photoquant: interrupted", file=sys.stderr)
        return 130
    except Terminated as exc:
        remove_live_temporaries()
        print("photoquant: terminated", file=sys.stderr)
        return 128 + exc.signum


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
