"""photoquant: radiometric camera calibration and photoquantity measurement.

Calibrate a camera once (response per channel, colour balance, sensor
non-uniformity, vignetting) and then measure the photoquantity of any static
scene from a few exposures, following the photoquantity paper (its full
reference: the documentation's *How to cite* page)::

    import photoquant as pq

    m = pq.load_manifest("capture/capture.json")
    model = pq.calibrate_manifest(m)                      # profile="photoquant" (or "paper")
    model.save("camera")
    result = pq.correct(pq.load_stack(m.scene, m), pq.load_camera("camera"))

Every step is a plug-in: :data:`REGISTRIES` holds one registry per step
(:data:`STEPS`), :func:`register_method` adds a method at run time and the
entry-point group ``photoquant.methods`` adds those of other distributions.

The names below are loaded on first use, so that ``import photoquant.io``
(the file formats, which the simulator uses) does not load the methods.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from photoquant._version import __version__

_EXPORTS: dict[str, str] = {
    # pipeline
    "calibrate": "photoquant.calibration",
    "calibrate_manifest": "photoquant.calibration",
    "CalibrationResult": "photoquant.calibration",
    "CalibrationIntermediates": "photoquant.calibration",
    "resolve_steps": "photoquant.calibration",
    "fit_sensor_lut": "photoquant.calibration",
    "find_correspondences": "photoquant.calibration",
    "fit_vignetting_step": "photoquant.calibration",
    "fit_balance": "photoquant.calibration",
    "fit_glare_step": "photoquant.calibration",
    "correct": "photoquant.correction",
    "correct_manifest": "photoquant.correction",
    "Correction": "photoquant.correction",
    "fit_response": "photoquant.response",
    "characterise_dark_frames": "photoquant.darkframe",
    "subtract_dark_frames": "photoquant.darkframe",
    # data and models
    "ExposureStack": "photoquant.stack",
    "CameraModel": "photoquant.model",
    "load_camera": "photoquant.model",
    "ResponseModel": "photoquant.response",
    "MergeModel": "photoquant.merge",
    "MergeResult": "photoquant.merge",
    "BalanceModel": "photoquant.balance",
    "BalanceData": "photoquant.balance",
    "SensorLUTModel": "photoquant.sensor_lut",
    "VignettingModel": "photoquant.vignetting",
    "VignettingData": "photoquant.vignetting",
    "ExtendedGoldmanChenVignetting": "photoquant.vignetting",
    "GlareModel": "photoquant.glare",
    "GlareData": "photoquant.glare",
    "DarkFrameModel": "photoquant.darkframe",
    "load_manifest": "photoquant.io",
    "load_stack": "photoquant.io",
    "read_exr": "photoquant.io",
    "write_exr": "photoquant.io",
    # registries and plug-ins
    "STEPS": "photoquant.methods",
    "REGISTRIES": "photoquant.methods",
    "Method": "photoquant.methods",
    "StepFit": "photoquant.methods",
    "register_method": "photoquant.methods",
    "registry": "photoquant.methods",
    "RESPONSE_METHODS": "photoquant.response",
    "MERGE_METHODS": "photoquant.merge",
    "BALANCE_METHODS": "photoquant.balance",
    "SENSOR_LUT_METHODS": "photoquant.sensor_lut",
    "VIGNETTING_METHODS": "photoquant.vignetting",
    "CORRESPONDENCE_METHODS": "photoquant.correspondences",
    "GLARE_METHODS": "photoquant.glare",
    "WEIGHTING_FUNCTIONS": "photoquant.weighting",
    "PROFILES": "photoquant.profiles",
    "DEVIATIONS": "photoquant.profiles",
    "PhotoquantError": "photoquant.errors",
}

__all__ = ["__version__", *_EXPORTS]

# The lazy exports as type checkers see them (never executed). Kept in step with
# _EXPORTS by tests/photoquant/test_public_api.py; `X as X` marks a re-export.
if TYPE_CHECKING:
    # isort: off
    from photoquant.darkframe import (
        DarkFrameModel as DarkFrameModel,
        characterise_dark_frames as characterise_dark_frames,
        subtract_dark_frames as subtract_dark_frames,
    )
    from photoquant.balance import (
        BalanceModel as BalanceModel,
        BalanceData as BalanceData,
        BALANCE_METHODS as BALANCE_METHODS,
    )
    from photoquant.calibration import (
        calibrate as calibrate,
        calibrate_manifest as calibrate_manifest,
        CalibrationResult as CalibrationResult,
        CalibrationIntermediates as CalibrationIntermediates,
        resolve_steps as resolve_steps,
        fit_sensor_lut as fit_sensor_lut,
        find_correspondences as find_correspondences,
        fit_vignetting_step as fit_vignetting_step,
        fit_balance as fit_balance,
        fit_glare_step as fit_glare_step,
    )
    from photoquant.correction import (
        correct as correct,
        correct_manifest as correct_manifest,
        Correction as Correction,
    )
    from photoquant.correspondences import (
        CORRESPONDENCE_METHODS as CORRESPONDENCE_METHODS,
    )
    from photoquant.errors import (
        PhotoquantError as PhotoquantError,
    )
    from photoquant.sensor_lut import (
        SensorLUTModel as SensorLUTModel,
        SENSOR_LUT_METHODS as SENSOR_LUT_METHODS,
    )
    from photoquant.glare import (
        GlareModel as GlareModel,
        GlareData as GlareData,
        GLARE_METHODS as GLARE_METHODS,
    )
    from photoquant.io import (
        load_manifest as load_manifest,
        load_stack as load_stack,
        read_exr as read_exr,
        write_exr as write_exr,
    )
    from photoquant.merge import (
        MergeModel as MergeModel,
        MergeResult as MergeResult,
        MERGE_METHODS as MERGE_METHODS,
    )
    from photoquant.methods import (
        STEPS as STEPS,
        REGISTRIES as REGISTRIES,
        Method as Method,
        StepFit as StepFit,
        register_method as register_method,
        registry as registry,
    )
    from photoquant.model import (
        CameraModel as CameraModel,
        load_camera as load_camera,
    )
    from photoquant.profiles import (
        PROFILES as PROFILES,
        DEVIATIONS as DEVIATIONS,
    )
    from photoquant.response import (
        fit_response as fit_response,
        ResponseModel as ResponseModel,
        RESPONSE_METHODS as RESPONSE_METHODS,
    )
    from photoquant.stack import (
        ExposureStack as ExposureStack,
    )
    from photoquant.vignetting import (
        VignettingModel as VignettingModel,
        VignettingData as VignettingData,
        ExtendedGoldmanChenVignetting as ExtendedGoldmanChenVignetting,
        VIGNETTING_METHODS as VIGNETTING_METHODS,
    )
    from photoquant.weighting import (
        WEIGHTING_FUNCTIONS as WEIGHTING_FUNCTIONS,
    )
    # isort: on


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'photoquant' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
