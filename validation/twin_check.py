"""Is a camera's simulator twin faithful to it? The real bracket beside the twin's own shot of it.

A twin (:mod:`pqsim.twin`) is built from one camera's calibration and
characterisation. :func:`twin_check` puts it to the test on a bracket the
camera shot:

1. the bracket is corrected with the camera (``photoquant correct``'s
   defaults): its photoquantity is the scene;
2. the twin shoots that scene at the bracket's exposure times, with as many
   repeats (:func:`pqsim.twin.capture_camera_scene`), so its values lie
   where the camera's did;
3. both brackets are cross-validated the same way (leave one exposure out,
   the default pipeline, :func:`photoquant.crossval.crossval_stack`, the
   manifest's ``crossval_roi``): a faithful twin predicts its held-out frames
   about as well as the camera's own frames are predicted. The check asks for
   a ratio within :data:`FAITHFUL_RATIO` either way;
4. the twin's bracket is cross-validated once more with the twin's *true*
   response in place of the recovered one (the same merge, correction and
   scoring). The default pipeline's error over it
   (:attr:`TwinCheck.response_cost`) is what estimating the response from the
   bracket costs the prediction on this camera: well above 1, the response
   estimate is what limits it; near 1, the noise and the scene do. It can
   fall below 1: the held-out values are predicted from the other frames'
   noisy merge, and eq. 7's fit, which regresses towards the mean where the
   values are noisy, can predict noisy values better than the truth does
   (measured on Memorial's twin: 0.95);
5. on the twin's bracket the truth is known: each response method is fitted
   (one view, the calibration's defaults otherwise) and its ``g`` scored
   against the twin's true response — which method to use for this camera,
   on its own scene, with a truth the real bracket cannot give. The twin's
   true response is the camera's estimate: where the twin states how far it
   may lie from the camera's own (``measurement.response_sd_ln``, from a
   camera calibrated with the exposure jackknife's covariance), methods
   whose scores are within twice that of the best are reported as tied
   with it (:attr:`TwinCheck.resolution_ln`): this twin cannot order them.

What no twin carries shows as a ratio above 1: a subject that moved between
the frames, frames out of register, a tone curve that is not one global
response per channel (the cross-validation's model-adequacy measure names
these); the twin's noise is the characterisation's, so a camera whose noise
was not fixed by its captures (no repeats, no dark or flat frames) gives a
looser twin.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError

__all__ = [
    "DEFAULT_METHODS",
    "FAITHFUL_RATIO",
    "MethodOnTwin",
    "TwinCheck",
    "format_twin_check",
    "twin_check",
    "twin_check_json",
]

FAITHFUL_RATIO = 1.5
"""The twin is faithful where its cross-validation error is within this factor of the
real bracket's, either way."""

DEFAULT_METHODS = ("Debevec 1997", "Robertson 2003", "Mitsunaga-Nayar 1999", "EMoR 2004", "Gamma")
"""The response methods scored on the twin by default (photoquant's own; any registered
method or peer may be named)."""


@dataclass(frozen=True)
class MethodOnTwin:
    """One response method fitted to the twin's bracket and scored against its truth.

    Attributes
    ----------
    method : str
        The response method.
    g_rms_ln : float or None
        RMS of ``g − g_true`` (after the gauge, hat-weighted levels above the
        fit's lowest trusted level), the worst channel; ``None`` where it failed.
    status : str
        ``"ok"``, or why the method failed on this bracket (one line).
    """

    method: str
    g_rms_ln: float | None
    status: str = "ok"


@dataclass(frozen=True)
class TwinCheck:
    """The real bracket and the twin's shot of it, cross-validated side by side.

    Attributes
    ----------
    real, twin : CrossvalResult
        Leave-one-exposure-out on the camera's bracket and on the twin's.
    twin_truth : CrossvalResult
        Leave-one-exposure-out on the twin's bracket with the twin's true
        response in place of the recovered one.
    camera_unit : float
        The camera's photoquantity of 1 in the twin's unit (from the twin).
    seed : int
        The twin's noise seed.
    methods : tuple of MethodOnTwin
        The response methods scored against the twin's truth, best first.
    resolution_ln : float or None
        Twice the twin's stated ``response_sd_ln`` (its largest channel's): the
        smallest difference of ``g`` scores this twin can tell apart; ``None``
        where the twin states none.
    """

    real: Any
    twin: Any
    twin_truth: Any
    camera_unit: float
    seed: int
    methods: tuple[MethodOnTwin, ...]
    resolution_ln: float | None = None

    @property
    def tied_with_best(self) -> tuple[str, ...]:
        """The methods other than the best whose ``g`` score is within
        :attr:`resolution_ln` of the best's (empty where the twin states no resolution)."""
        scored = [m for m in self.methods if m.g_rms_ln is not None]
        if self.resolution_ln is None or not scored:
            return ()
        best = scored[0].g_rms_ln
        assert best is not None
        return tuple(
            m.method
            for m in scored[1:]
            if m.g_rms_ln is not None and m.g_rms_ln - best < self.resolution_ln
        )

    @property
    def ratio(self) -> float:
        """The twin's cross-validation error over the real bracket's."""
        real = self.real.overall_mae_dn
        return float(self.twin.overall_mae_dn / real) if real > 0 else math.nan

    @property
    def response_cost(self) -> float:
        """The twin's cross-validation error with the recovered response over the
        error with its true response: what estimating the response from the bracket
        costs the prediction on this camera (module notes, step 4)."""
        truth = self.twin_truth.overall_mae_dn
        return float(self.twin.overall_mae_dn / truth) if truth > 0 else math.nan

    @property
    def faithful(self) -> bool:
        """Whether :attr:`ratio` is within :data:`FAITHFUL_RATIO` either way."""
        return bool(1.0 / FAITHFUL_RATIO <= self.ratio <= FAITHFUL_RATIO)


def _score_on_truth(stack: Any, truth: Any, method: str, seed: int) -> MethodOnTwin:
    """``method``'s ``g`` from the twin's bracket against the twin's true response."""
    from photoquant.calibration import calibrate
    from photoquant.errors import PhotoquantError
    from validation.experiments.response import response_weights
    from validation.metrics import response_error

    try:
        model = calibrate([stack], response=method, seed=seed)
    except PhotoquantError as exc:
        return MethodOnTwin(method, None, str(exc).splitlines()[0])
    levels = model.response.levels
    worst = 0.0
    for ch in range(stack.n_channels):
        g_true = truth.camera.inverse_response_ln(levels, ch)
        rms, _ = response_error(
            model.response.log_inverse_response[ch], g_true, response_weights(model, ch)
        )
        worst = max(worst, rms)
    return MethodOnTwin(method, worst)


def twin_check(
    manifest: Any,
    camera: Any,
    twin: str | os.PathLike[str],
    *,
    methods: Sequence[str] = DEFAULT_METHODS,
    seed: int = 0,
    allow_outside: bool = False,
    progress: Callable[[str], None] | None = None,
) -> TwinCheck:
    """Cross-validate a bracket and the twin's shot of it; score methods on the twin's truth.

    Parameters
    ----------
    manifest : path or CaptureManifest
        The camera's capture manifest; its ``views[0]`` is the bracket (module notes).
    camera : path or CameraModel
        The camera the twin was built from.
    twin : path
        The twin's preset file (``pqsim preset --from-camera``).
    methods : sequence of str
        Response methods to score against the twin's truth (:data:`DEFAULT_METHODS`);
        an empty sequence scores none.
    seed : int
        The twin's noise seed (the same seed, the same twin bracket and scores).
    allow_outside : bool
        Let the manifest name frames outside its folder.
    progress : callable, optional
        Called with a line as each stage starts.

    Returns
    -------
    TwinCheck

    Raises
    ------
    InputError
        If the camera is not the bracket's (another image size or channels), the twin
        not the camera's (another bit depth) or without ``camera_unit``, or a method is
        unknown.
    """
    from photoquant.correction import correct
    from photoquant.crossval import crossval_stack, parse_roi
    from photoquant.io import CaptureManifest, load_manifest, load_stack
    from photoquant.model import CameraModel, load_camera
    from photoquant.response import RESPONSE_METHODS
    from pqsim.twin import capture_camera_scene, load_twin, twin_response_sd
    from validation.truth_model import camera_model_from_truth

    say = progress or (lambda _line: None)
    names = [RESPONSE_METHODS[m].name for m in methods]
    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    model = camera if isinstance(camera, CameraModel) else load_camera(camera)
    stack = load_stack(manifest.views[0], manifest)
    if stack.image_shape != model.image_shape or stack.channels != tuple(model.channels):
        raise InputError(
            f"the camera is {model.image_shape[1]}x{model.image_shape[0]} "
            f"{'/'.join(model.channels)}, the bracket {stack.image_shape[1]}x"
            f"{stack.image_shape[0]} {'/'.join(stack.channels)}: not this bracket's camera"
        )
    roi = None
    if manifest.extra.get("crossval_roi") is not None:
        roi = parse_roi(
            manifest.extra["crossval_roi"],
            stack.image_shape,
            where=f"manifest {manifest.path}: crossval_roi",
        )
    twin_camera, unit = load_twin(twin)
    if twin_camera.bit_depth != stack.bit_depth:
        raise InputError(
            f"the twin {twin} has {twin_camera.bit_depth}-bit values, the bracket "
            f"{stack.bit_depth}-bit: not this camera's twin"
        )
    say("twin-check: correcting the bracket with the camera")
    scene = correct(stack, model, uncertainty=False).photoquantity
    say("twin-check: the twin shoots the corrected scene at the bracket's exposure times")
    capture = capture_camera_scene(twin, scene, stack.exposure_s, stack.n_repeats, rng=seed)
    twin_stack = capture.to_stack()
    say("twin-check: cross-validating the camera's bracket")
    real = crossval_stack(stack, roi=roi)
    say("twin-check: cross-validating the twin's bracket")
    twin_cv = crossval_stack(twin_stack, roi=roi)
    say("twin-check: cross-validating the twin's bracket with its true response")
    # the twin's true response, trusted over the camera's range: the levels the camera's
    # fit left below `valid_min` weigh nothing in the merge either way
    true_response = camera_model_from_truth(capture.truth.camera).response
    if model.response.valid_min is not None:
        true_response = dataclasses.replace(
            true_response, valid_min=np.array(model.response.valid_min, dtype=np.float64)
        )
    truth_cv = crossval_stack(twin_stack, true_response, roi=roi)
    scored = []
    for name in names:
        say(f"twin-check: {name} against the twin's truth")
        scored.append(_score_on_truth(twin_stack, capture.truth, name, seed))
    scored.sort(key=lambda m: (m.g_rms_ln is None, m.g_rms_ln or 0.0))
    sd = twin_response_sd(twin)
    resolution = None if sd is None else 2.0 * sd
    return TwinCheck(real, twin_cv, truth_cv, unit, seed, tuple(scored), resolution)


def twin_check_json(result: TwinCheck) -> dict[str, Any]:
    """The check as plain JSON data (format ``photoquant.twin-check/1``)."""
    return {
        "format": "photoquant.twin-check/1",
        "real": result.real.to_json(),
        "twin": result.twin.to_json(),
        "twin_true_response": result.twin_truth.to_json(),
        "ratio": result.ratio,
        "response_cost": result.response_cost,
        "faithful": result.faithful,
        "faithful_ratio": FAITHFUL_RATIO,
        "camera_unit": result.camera_unit,
        "seed": result.seed,
        "methods": [
            {"method": m.method, "g_rms_ln": m.g_rms_ln, "status": m.status} for m in result.methods
        ],
        "resolution_ln": result.resolution_ln,
        "tied_with_best": list(result.tied_with_best),
    }


def format_twin_check(result: TwinCheck) -> str:
    """The check as text: the two cross-validations, the verdict and the methods' table."""
    real, twin = result.real.overall_mae_dn, result.twin.overall_mae_dn
    truth = result.twin_truth.overall_mae_dn
    verdict = "faithful" if result.faithful else "not faithful"
    lines = [
        "leave one exposure out (default pipeline), mean |error| of the held-out values:",
        f"  the camera's bracket   {real:10.3f} DN",
        f"  the twin's bracket     {twin:10.3f} DN (seed {result.seed})",
        f"  ratio {result.ratio:.2f}: {verdict} (within {FAITHFUL_RATIO:g}x either way)",
    ]
    if result.ratio > FAITHFUL_RATIO:
        lines.append(
            "  the real frames hold what the twin does not: movement, registration, a tone "
            "curve that is not one global response, or noise the characterisation missed"
        )
    elif result.ratio < 1.0 / FAITHFUL_RATIO:
        lines.append(
            "  the twin is noisier than the camera: its noise was read from data that hold "
            "more than sensor noise (characterise with repeats, dark or flat frames)"
        )
    lines += [
        "",
        "the twin's bracket with its true response in place of the recovered one:",
        f"  {truth:.3f} DN: estimating the response from the bracket costs "
        f"{result.response_cost:.3f}x",
    ]
    if result.methods:
        lines += ["", "response methods on the twin's bracket, against its true response:"]
        width = max(len(m.method) for m in result.methods)
        tied = set(result.tied_with_best)
        for rank, m in enumerate(result.methods, 1):
            score = "failed: " + m.status if m.g_rms_ln is None else f"g rms {m.g_rms_ln:.4f} ln"
            mark = "  tied with the best" if m.method in tied else ""
            lines.append(f"  {rank}. {m.method:<{width}}  {score}{mark}")
        if result.resolution_ln is None:
            lines.append(
                "  (the twin states no uncertainty of its true response: close scores may "
                "not order the methods on the camera)"
            )
        else:
            lines.append(
                f"  (a score within {result.resolution_ln:.4f} ln of the best is not told apart "
                "from it: twice the twin's stated uncertainty of its true response)"
            )
    return "\n".join(lines)
