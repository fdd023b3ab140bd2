"""Robustness to pairs of disturbances: every two of the sensor and output disturbances.

The rows of :mod:`validation.experiments.robustness` are each disturbance
alone, a typical set, and all together; a real camera has several at once,
and two that each pass alone can fail together (a check meant for one
reading the other's data). This experiment runs every pair of
:data:`~validation.experiments.robustness.SENSOR_GROUPS` at the same levels
(:data:`~validation.experiments.robustness.PAIRS`: 36 rows per preset) through
the default pipeline, and reports each recovered quantity against the truth
as the robustness table does, a refusal as a row. It runs only when named
(``photoquant validate --experiments robustness_pairs``): 36 calibrations
per preset.

References
----------
.. [McCann2007] J. J. McCann, A. Rizzi, "Camera and visual veiling glare in
   HDR images", J. SID 15(9), 2007.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021): typical sensor levels.
"""

from __future__ import annotations

from pathlib import Path

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult
from validation.experiments.robustness import PAIRS
from validation.experiments.robustness import run as run_rows
from validation.experiments.shared import Shared

__all__ = ["TITLE", "run"]

TITLE = "Robustness to pairs of real-camera disturbances"


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Calibrate each preset clean and with every pair of disturbances (module notes)."""
    return run_rows(
        config,
        seed,
        workdir,
        shared=shared,
        disturbances=PAIRS,
        key="robustness_pairs",
        title=TITLE,
    )
