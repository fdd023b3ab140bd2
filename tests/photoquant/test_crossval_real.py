"""Real brackets: leave-one-exposure-out cross-validation on the path users run.

photoquant is scored as a user runs it (calibrate on ``K − 1`` frames, then
``correct`` them with that camera's defaults, predict the held-out frame),
beside OpenCV's Debevec pipeline (8-bit sets) or the dataset authors' own
response through the same pipeline (the 12-bit set), on the same frames and
the same scored values. The sets are read from ``../shared/data/real``
(skipped when absent) through a manifest written in a temporary folder.

Measured 2026-12-05 (ratio to OpenCV, DN): Memorial 2.289 against 4.265
(0.54), frobisher 7.34 against 17.91 (0.41), St. Louis 9.73 against 14.17
(0.69); 2026-12-07: the 12-bit bracket 92.76 against its authors' response's 92.31
(1.0049; what estimating a response costs there, measured on a twin whose true
response is the authors', is the 12-bit test's target).
The two JPEG brackets read a JPEG block's reach of every clipped value as
clipped (the manifest's default for JPEG files), which also removes those
values from the scored ones, for both pipelines alike.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from photoquant.crossval import crossval_manifest

# Memorial Church: a pure-blue registration border, the 3 right-most columns
# and 2 bottom rows of its 512x768 frames, is not scene content
MEMORIAL_ROI = [0, 0, 509, 766]


def _manifest(folder: Path, tmp: Path, roi=None, **extra) -> Path:
    rows = [
        line.split()
        for line in (folder / "exposures.txt").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    data = {
        "format": "photoquant.captures/1",
        "bit_depth": 8,
        **extra,
        "views": [
            {"frames": [{"file": str(folder / r[0]), "exposure_s": float(r[1])} for r in rows]}
        ],
    }
    if roi is not None:
        data["crossval_roi"] = roi
    path = tmp / f"{folder.name}.json"
    path.write_text(json.dumps(data))
    return path


def _scores(path: Path) -> tuple[float, float]:
    ours = crossval_manifest(path, allow_outside=True)
    peer = crossval_manifest(path, "opencv", allow_outside=True)
    assert [r.n_scored for r in ours.rows] == [r.n_scored for r in peer.rows]
    # every scored value has a prediction: the fallback is counted, never skipped
    assert ours.n_scored == peer.n_scored > 0
    return ours.overall_mae_dn, peer.overall_mae_dn


def _real(name: str) -> Path:
    from tests.conftest import SHARED

    folder = SHARED / "data" / "real" / name
    if not folder.is_dir():
        pytest.skip(f"../shared/data/real/{name} is not available")
    return folder


@pytest.mark.slow  # 16 frames of 512x768, 14 folds per method: ~40 s here
def test_memorial_on_the_users_path_is_40_percent_below_opencv(tmp_path):
    ours, opencv = _scores(_manifest(_real("memorial_debevec"), tmp_path, MEMORIAL_ROI))
    assert ours <= 0.60 * opencv, f"photoquant {ours:.3f} DN, OpenCV {opencv:.3f} DN"


def test_frobisher_on_the_users_path_is_half_opencvs(tmp_path, frobisher_dir):
    """Two calibration frames six stops apart: the shape of g is the prior's.

    Eq. 7's straight-line prior gave 19.9 DN against OpenCV's 14.6; the
    smoothness scaled with the step about the EMoR mean
    (:mod:`photoquant.response.wide_steps`) gives 6.3 (7.3 against 17.9 where a
    JPEG block's reach of the clipped values is read as clipped, the default).
    """
    ours, opencv = _scores(_manifest(frobisher_dir, tmp_path))
    assert ours <= 0.50 * opencv, f"photoquant {ours:.3f} DN, OpenCV {opencv:.3f} DN"


def test_correcting_memorials_own_frames_reproduces_the_calibrations_merge(tmp_path):
    """Calibration and correction agree on a real bracket: the frames a camera was
    calibrated from keep their times at correction (the exposure test finds the shifts
    of the response's own floor), and their photoquantity is the calibration's merge up to
    the correction's float32 arithmetic."""
    import numpy as np

    import photoquant as pq
    from photoquant.io import load_manifest, load_stack

    m = load_manifest(_manifest(_real("memorial_debevec"), tmp_path), allow_outside=True)
    stack = load_stack(m.views[0], m)
    result = pq.calibrate([stack], return_intermediates=True)
    model, merged = result.model, result.intermediates.merged_views[0]
    corrected = pq.correct(stack, model)
    assert corrected.exposure_decision is not None and not corrected.exposure_decision.refine
    assert corrected.exposures is None
    ok = ~corrected.mask & ~merged.mask
    assert ok.mean() > 0.9
    expected = np.exp(merged.log_photoquantity[ok])  # one view: u = v = a = 1
    diff = np.abs(np.log(corrected.photoquantity[ok]) - np.log(expected))
    big = np.abs(merged.log_photoquantity[ok]).max() + np.abs(np.log(stack.exposure_s)).max()
    assert diff.max() < (stack.n_exposures + 1) * big * 2.0**-24


@pytest.mark.slow  # 4 frames of 2112x2816, 2 folds per method: ~35 s here
def test_stlouis_on_the_users_path_is_25_percent_below_opencv(tmp_path):
    """Four JPEG frames three stops apart, with moving water. A bracket of JPEG files
    reads a JPEG block's reach of every clipped value as clipped (the manifest's
    ``saturation_spread``, ``"auto"`` by default): without it, 11.14 DN against 14.48
    (0.77)."""
    ours, opencv = _scores(_manifest(_real("stlouis_arch_canon_s3is"), tmp_path))
    assert ours <= 0.75 * opencv, f"photoquant {ours:.3f} DN, OpenCV {opencv:.3f} DN"


def _authors_response(folder: Path):
    """The BorealHDR authors' inverse response (TUM/DSO pcalib: irradiance at
    ``linspace(0, 4095, 256)``) as a response table, ``g = ln``."""
    import numpy as np

    from photoquant.response.model import ResponseModel

    values = np.array((folder / "reference_pcalib_inside1.txt").read_text().split(), dtype=float)
    return ResponseModel(
        method="BorealHDR authors' response",
        levels=np.linspace(0.0, 4095.0, values.size),
        log_inverse_response=np.log(values)[None, :],
        saturation_level=np.array([4094.0]),
    )


TWIN_SEEDS = range(5)
"""The twin's noise draws. What estimating a response costs varies between draws by more
than the margins in question (measured 2026-12-07: the best estimate's cost 1.0025x to
1.0092x over these five, the default's 1.0067x to 1.0092x): one draw cannot tell a
response that costs 0.5 % from one that costs 0.25 %."""


def _authors_twin_costs(
    folder: Path, path: Path, tmp: Path
) -> tuple[float, list[dict[str, float]]]:
    """The bracket's cross-validation with the default pipeline, and what each estimate
    costs on a twin whose true response is the authors' (its cross-validation error over
    the true response's, on the same folds and values), for each of the twin's noise
    draws :data:`TWIN_SEEDS`."""
    import dataclasses

    from photoquant.calibration import calibrate_manifest
    from photoquant.characterise import characterise_manifest
    from photoquant.correction import correct
    from photoquant.crossval import crossval_stack
    from photoquant.io import load_manifest, load_stack
    from pqsim.twin import capture_camera_scene, twin_preset_json
    from validation.twin_check import twin_check

    authors = _authors_response(folder)
    ours = calibrate_manifest(path, allow_outside=True)
    response = dataclasses.replace(
        ours.response,
        levels=authors.levels,
        log_inverse_response=authors.log_inverse_response,
        covariance_factor=None,
        covariance_diagonal=None,
        covariance_reference=None,
    )
    camera = dataclasses.replace(ours, response=response)
    twin = tmp / "twin.json"
    twin.write_text(
        twin_preset_json(camera, characterise_manifest(path, camera, allow_outside=True))
    )
    manifest = load_manifest(path, allow_outside=True)
    stack = load_stack(manifest.views[0], manifest)
    scene = correct(stack, camera, uncertainty=False).photoquantity
    real = None
    costs = []
    for seed in TWIN_SEEDS:
        check = twin_check(path, camera, twin, methods=[], allow_outside=True, seed=seed)
        # the real bracket's score, whatever the twin's seed
        assert real is None or check.real.overall_mae_dn == real
        real = check.real.overall_mae_dn
        # the check's twin bracket again (its seed: the same bits)
        capture = capture_camera_scene(twin, scene, stack.exposure_s, stack.n_repeats, rng=seed)
        emor = crossval_stack(capture.to_stack(), "EMoR 2004").overall_mae_dn
        costs.append(
            {
                "Debevec 1997": check.response_cost,
                "EMoR 2004": emor / check.twin_truth.overall_mae_dn,
            }
        )
    assert real is not None
    return real, costs


@pytest.fixture(scope="module")
def twelve_bit(tmp_path_factory):
    """The 12-bit bracket's cross-validation: the default's, its authors' response's, and
    each estimate's cost on the authors' twin over the twin's noise draws (6 frames of
    1920x1200: the bracket, then the twin's bracket and its cross-validations five times,
    ~2 min here)."""
    folder = _real("borealhdr_mv12bit")
    tmp = tmp_path_factory.mktemp("twelve-bit")
    path = _manifest(folder, tmp, bit_depth=12, channels=["Y"])
    ours, costs = _authors_twin_costs(folder, path, tmp)
    authors = crossval_manifest(path, _authors_response(folder), allow_outside=True)
    assert authors.method == "BorealHDR authors' response"
    return ours, authors.overall_mae_dn, costs


@pytest.mark.slow
def test_no_estimate_reaches_the_true_response_on_the_twelve_bit_twin(twelve_bit):
    """On a simulated twin of the camera whose true response *is* the authors' (its scene,
    exposure times and noise the bracket's), no estimate from the bracket predicts the
    held-out frames as well as the true response, on any of the twin's noise draws: a
    bracket's own response cannot be held to ``1.0x`` its authors'. Measured 2026-12-07,
    seeds 0-4: the default 1.0067-1.0092x the truth's error, EMoR 2004 1.0025-1.0061x
    (1.148x on one draw). (Not a theorem: where the merge the prediction starts from is
    noisy, a fit that regresses towards the mean can predict noisy values better than the
    truth; on this twin none does.)"""
    _, _, costs = twelve_bit
    assert min(min(draw.values()) for draw in costs) > 1.0, costs


@pytest.mark.slow
def test_twelve_bit_bracket_is_within_the_cost_of_estimating_its_authors_response(twelve_bit):
    """Within its authors' response up to what estimating a response from this bracket
    costs: the default's error over the authors' response's on the real bracket is no
    larger than the best estimate's cost on the authors' twin, its median over the twin's
    noise draws (the cost varies between draws by more than the margin:
    :data:`TWIN_SEEDS`). Measured 2026-12-07: 92.76 DN against 92.31 (1.0049x); the
    best estimate's cost 1.0025x, 1.0061x, 1.0047x, 1.0056x, 1.0092x over seeds 0-4
    (median 1.0056x); the default's own 1.0067-1.0092x."""
    import numpy as np

    ours, authors, costs = twelve_bit
    best = np.median([min(draw.values()) for draw in costs])
    assert ours <= best * authors, (ours, authors, costs)


@pytest.mark.slow  # 16 frames of 512x768, 14 folds, twice: ~50 s here
def test_memorial_flat_samples_predict_held_out_frames_better(tmp_path):
    """The default's samples from flat regions on the user's path: measured 2.075 DN
    against 2.241 with every candidate (``edges="kept"``; 2026-12-06; with eq. 7, sampling
    seeds 0-3: 2.10 each time against 2.26-2.29)."""
    path = _manifest(_real("memorial_debevec"), tmp_path, MEMORIAL_ROI)
    kept = crossval_manifest(path, allow_outside=True, options={"edges": "kept"}).overall_mae_dn
    flat = crossval_manifest(path, allow_outside=True)
    assert flat.overall_mae_dn < 0.95 * kept, (kept, flat.overall_mae_dn)
