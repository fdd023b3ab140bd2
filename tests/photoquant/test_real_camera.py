"""A real camera: three JPEG brackets of a Canon EOS 5D Mark II (no ground truth).

Exposure times come from EXIF only (the manifest gives none).
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from scipy.stats import spearmanr

from photoquant.calibration import calibrate_manifest
from photoquant.io import load_manifest, load_stack
from photoquant.merge import apply_log_inverse_response, merge_stack


@pytest.fixture(scope="module")
def frobisher(tmp_path_factory, request):
    from tests.conftest import FROBISHER

    if not FROBISHER.is_dir():
        pytest.skip("../shared/data/real/frobisher_001 is not available")
    folder = tmp_path_factory.mktemp("frobisher")
    names = sorted(p.name for p in FROBISHER.glob("*.jpg"))
    for name in names:
        shutil.copy(FROBISHER / name, folder / name)
    manifest = {
        "format": "photoquant.captures/1",
        "bit_depth": 8,
        "views": [{"frames": [{"file": n} for n in names]}],
    }
    (folder / "capture.json").write_text(json.dumps(manifest))
    return folder / "capture.json"


def test_exposures_come_from_exif(frobisher):
    m = load_manifest(frobisher)
    stack = load_stack(m.views[0], m)
    np.testing.assert_array_equal(stack.exposure_s, [0.125, 1.0, 8.0])
    assert stack.shape == (1, 3, 426, 640, 3)


def test_real_bracket_calibrates_and_merges(frobisher):
    model = calibrate_manifest(frobisher)
    notes = " ".join(model.report["notes"])
    assert "sensor LUT left at 1" in notes and "vignetting left at 1" in notes
    assert "colour balance left at 1" in notes
    g = model.response.log_inverse_response
    assert np.all(np.diff(g, axis=1) >= 0), "response must be monotonic in every channel"

    m = load_manifest(frobisher)
    stack = load_stack(m.views[0], m)
    merged = merge_stack(stack, model.response.levels, g, model.response.saturation_level)
    # unmeasurable: what the shortest exposure clipped (JPEG files: with a block's reach
    # around it, read as clipped), the sky's few per cent, and hardly anything else
    clipped_short = stack.frames[0, 0] >= stack.saturation_level
    assert merged.mask.mean() < 0.10
    assert np.mean(merged.mask & ~clipped_short) < 0.005
    values = stack.mean()
    for k, t in enumerate(stack.exposure_s):
        v = values[k]
        well = (v > 25) & (v < 230) & ~merged.mask
        assert well.sum() > 10000
        # merged values order like the frame's values
        rho = spearmanr(merged.log_photoquantity[well], v[well]).statistic
        assert rho > 0.95
        # and agree with this frame's own linearised value g(c) - ln t: an 8-bit
        # JPEG value c of a gamma ~2.2 tone curve is known to ±0.5 DN, i.e.
        # 2.2·0.5/c in ln; at the typical c ~ 75 that is 1.5 %; two frames
        # disagree by up to twice that, and the median must stay within it.
        own = apply_log_inverse_response(v, model.response.levels, g) - np.log(t)
        diff = np.abs(merged.log_photoquantity - own)[well]
        assert np.median(diff) < 2 * 2.2 * 0.5 / 75
