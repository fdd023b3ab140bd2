"""The synthetic camera: a numpy forward model of eq. 1 of the photoquantity paper.

``c_pkλn = a_λ · f_λ(u_pλ · v_pλ · t_k · l_pλ) + b_pkλn``: response curves
(:mod:`.responses`), sensor noise (:mod:`.sensor`), vignetting and PRNU
(:mod:`.optics`), real-camera disturbances (:mod:`.disturbances`, :mod:`.cfa`),
the camera (:mod:`.camera`), its ground truth
(:mod:`.truth`) and presets (:mod:`.presets`).

This package implements its own physics and never imports photoquant's method
modules, only its input checks, errors and I/O formats.
"""

from pqsim.synth_camera.camera import Capture, SyntheticCamera, as_generator
from pqsim.synth_camera.disturbances import SensorDisturbances
from pqsim.synth_camera.optics import (
    prnu_field,
    vignetting_cos4,
    vignetting_extended_goldman_chen,
)
from pqsim.synth_camera.presets import CAMERA_PRESETS, camera_from_preset
from pqsim.synth_camera.responses import (
    RESPONSE_MODELS,
    ResponseCurve,
    load_response_table,
    response_gamma,
    response_linear,
    response_s_curve,
    response_table,
)
from pqsim.synth_camera.sensor import SensorNoise
from pqsim.synth_camera.truth import (
    TRUTH_FORMAT,
    CameraTruth,
    CaptureTruth,
    TruthSet,
    load_truth,
    save_truth,
)

__all__ = [
    "CAMERA_PRESETS",
    "RESPONSE_MODELS",
    "TRUTH_FORMAT",
    "CameraTruth",
    "Capture",
    "CaptureTruth",
    "ResponseCurve",
    "SensorDisturbances",
    "SensorNoise",
    "SyntheticCamera",
    "TruthSet",
    "as_generator",
    "camera_from_preset",
    "load_response_table",
    "load_truth",
    "prnu_field",
    "response_gamma",
    "response_linear",
    "response_s_curve",
    "response_table",
    "save_truth",
    "vignetting_cos4",
    "vignetting_extended_goldman_chen",
]
