"""Real cameras' twins, each checked on the camera's own bracket (``../shared/data/real``,
skipped when absent): calibrated with the defaults, characterised from that one bracket,
the twin written, then :func:`validation.twin_check.twin_check`.

Measured 2026-12-06 (leave one exposure out, DN, the camera's bracket against the twin's):
Memorial 2.288 against 1.819 (0.80), the 12-bit machine-vision bracket 94.31 against 109.4
(1.16), frobisher 7.338 against 6.061 (0.83), St. Louis 9.726 against 5.699 (0.59: its
moving water and JPEG tone curve are not in the twin; not among the sets checked). These
brackets hold one frame per exposure: the twin's noise is what their neighbouring exposures
share beyond one global response, with a moving subject and edges out of register left out
of it.
"""

from __future__ import annotations

import pytest

from photoquant.calibration import calibrate_manifest
from photoquant.characterise import characterise_manifest
from pqsim.twin import twin_preset_json
from tests.photoquant.test_crossval_real import MEMORIAL_ROI, _manifest, _real
from validation.twin_check import FAITHFUL_RATIO, format_twin_check, twin_check

SETS = {
    "frobisher_001": {},
    "memorial_debevec": {"roi": MEMORIAL_ROI},
    "borealhdr_mv12bit": {"bit_depth": 12, "channels": ["Y"]},
}


@pytest.mark.slow  # Memorial ~75 s, the 12-bit bracket ~90 s, frobisher ~5 s
@pytest.mark.parametrize("name", list(SETS))
def test_a_real_cameras_twin_is_faithful_on_its_own_bracket(name, tmp_path):
    path = _manifest(_real(name), tmp_path, **SETS[name])
    model = calibrate_manifest(path, allow_outside=True)
    twin = tmp_path / "twin.json"
    twin.write_text(twin_preset_json(model, characterise_manifest(path, model, allow_outside=True)))
    check = twin_check(path, model, twin, methods=[], allow_outside=True)
    assert 1.0 / FAITHFUL_RATIO <= check.ratio <= FAITHFUL_RATIO, format_twin_check(check)
    assert len(check.twin.rows) == len(check.real.rows)
    assert check.twin.n_scored > 0.5 * check.real.n_scored
