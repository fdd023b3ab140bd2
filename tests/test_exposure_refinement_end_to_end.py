"""The issue's exposure target end to end: every frame jittered, labelled with nominal times.

A synthetic CCD capture set (120×160, K = 8 calibration exposures, N = 4,
V = 3 views, the irradiance scene and the HDR test scene) whose every
exposure is 3 % off its label at random and 0.1 ms late, calibrated and
corrected from the nominal labels (``benchmarks/bench_exposure_refinement.py``
builds it). The test scene's eq. 8 error is compared with that of the same
frames labelled with their actual times.

Measured (seed 0 / seed 1, 2026-12-06): exact 1.13 % / 1.23 %, nominal
10.5 % / 2.47 %, refined 1.44 % / 1.15 %. The scene's shortest exposure
(0.25 ms labelled, 0.1 ms late: 24 % off) sees its brightest pixels only;
the correction's screen pairs it with the next exposure at enough values
only from a larger draw (:func:`photoquant.exposure.refine_by_pairs`), and
left at its label it costs the scene 0.5 % (1.94 % on seed 0). What is left
is what the frames do not determine, shown by handing the refinement a
quantity from the truth (``benchmarks/bench_exposure_refinement.py
--oracle``: the result of ``fit_affine_shutter`` replaced in every round):

* with the true exponent ``γ`` (the ambiguity ``(g, ln t) → γ (g, ln t)``
  of Grossberg & Nayar 2003, fixed from the labels and the lag's curvature
  to ~0.5 %): 1.34 % / 1.22 %;
* with the true γ and each view's true scale (a view's gauge, the geometric
  mean of its labels, carries its jitter / √8 ≈ 1 %), no view gains:
  1.09 % / 0.94 %, the target.

Meeting the target therefore needs γ and the views' scales from outside the
frames; anchoring one time fixes neither, and the log-ratios of pixel pairs
(what ``refine_exposure_times`` fits) are already right. An expected failure.
"""

from __future__ import annotations

import numpy as np
import pytest

import photoquant as pq
from benchmarks.bench_exposure_refinement import jittered_set, scene_error
from photoquant.errors import CalibrationError, InputError

SEED = 0


@pytest.fixture(scope="module")
def runs():
    data = jittered_set(SEED, (120, 160))
    out = {}
    for name, d, refine in (
        ("exact", data.exact(), False),
        ("nominal", data, False),
        ("refined", data, True),
    ):
        e, model, res = scene_error(d, refine_exposures=refine)
        out[name] = (e, model, res)
    out["data"] = data
    return out


def _calibrate(data, **options):
    """``pq.calibrate`` of a jittered set's views with its irradiance scene, chart and tracks."""
    return pq.calibrate(
        data.views,
        irradiance=data.irradiance,
        white_roi=data.white_roi,
        correspondences=data.tracks,
        **options,
    )


def test_refinement_recovers_most_of_the_exposure_error(runs):
    exact, nominal, refined = (runs[k][0] for k in ("exact", "nominal", "refined"))
    # the shutter's errors do matter, and the test can fail
    assert nominal > 3 * exact, (exact, nominal)
    # what refinement honestly reaches: the exponent's ~0.5 % uncertainty over the
    # scene's range (module notes), far below the nominal labels' error
    assert refined < 1.7 * exact, (exact, refined)
    assert refined < 0.25 * nominal, (nominal, refined)


def test_the_default_correction_refines_the_scenes_shortest_exposure(runs):
    # few pixels see the shortest exposure and the next one both in range: the screen's
    # first draw keeps too few of their pairs, a larger one refines it
    res = runs["refined"][2]
    assert res.exposures is not None and bool(res.exposures.refined[0]), res.notes
    assert res.exposures.n_values[0] >= 200


@pytest.mark.xfail(
    strict=True,
    reason="not determined by the frames: the exponent gamma (fixed to ~0.5 % by the labels and "
    "the lag's curvature) and each view's scale (1 %); refined 1.44 % against 1.13 % exact, "
    "1.09 % when both are given from the truth (module notes, measured 2026-12-06)",
)
def test_refined_error_within_ten_percent_of_exact(runs):
    assert runs["refined"][0] <= 1.10 * runs["exact"][0]


def test_the_camera_reports_nominal_and_refined_times(runs):
    data = runs["data"]
    _, model, res = runs["refined"]
    assert model.parameters["refine_exposures"] is True
    ex = model.report["exposures"]
    assert ex["refined"] is True and len(ex["views"]) == 3 and "irradiance" in ex
    for i, view in enumerate(ex["views"]):
        np.testing.assert_array_equal(view["nominal_s"], data.views[i].exposure_s)
        nominal = np.log(view["nominal_s"])
        refined, actual = np.log(view["exposure_s"]), np.log(data.actual[f"view{i}"])
        # the jitter (3 %) is removed up to the gauge and the exponent (< 1.5 % here)
        design = np.c_[np.ones(nominal.size), nominal]
        left = refined - actual
        left -= design @ np.linalg.lstsq(design, left, rcond=None)[0]
        before = nominal - actual
        before -= design @ np.linalg.lstsq(design, before, rcond=None)[0]
        assert np.abs(left).max() < 0.3 * np.abs(before).max()
        # statistical, and the exponent's uncertainty (|ln t − mean| σ_γ, up to ~2.6 × 0.5 %)
        assert all(s is not None and s < 0.03 for s in view["log_std"])
    # the views' scales are uncertain (jitter / √K ≈ 1 %): the vignetting fitted view gains
    assert ex["view_scale_std"] > 0.005
    assert len(model.report["vignetting"]["exposure_correction"]) == 3
    # the scene was refined at correction, as the camera was calibrated
    assert res.exposures is not None
    np.testing.assert_array_equal(res.exposures.nominal_s, data.scene.exposure_s)
    # nominal-time runs record that they kept the nominal times
    assert runs["nominal"][1].parameters["refine_exposures"] is False
    assert runs["nominal"][2].exposures is None


def test_refinement_keeps_exact_times(runs):
    """Exact labels stay: the default never does worse than nominal times that are right.

    The likelihood-ratio test (``judge_exposure_times``) finds no evidence
    against exact labels, so nothing moves: the camera and the corrected
    scene are those of a calibration without refinement, to the bit.
    """
    data = runs["data"].exact()
    e, model, res = scene_error(data)  # the defaults: refinement allowed, judged
    ex = model.report["exposures"]
    assert ex["refined"] is False and ex["decision"]["refine"] is False
    assert ex["decision"]["p_value"] > ex["decision"]["alpha"]
    assert "view_gains" not in model.report["vignetting"]
    kept = runs["exact"][1]
    np.testing.assert_array_equal(
        model.response.log_inverse_response, kept.response.log_inverse_response
    )
    np.testing.assert_array_equal(model.vignetting_map(), kept.vignetting_map())
    np.testing.assert_array_equal(model.sensor_lut.lut, kept.sensor_lut.lut)
    # the scene's exact labels are kept too: the same photoquantity as without refinement
    assert res.exposures is None and res.exposure_decision is not None
    assert res.exposure_decision.refine is False
    np.testing.assert_array_equal(res.photoquantity, runs["exact"][2].photoquantity)
    assert e == runs["exact"][0]


def test_paper_profile_keeps_the_nominal_times(runs):
    # (on the jittered labels the paper's pipeline reads the views' exposure errors as
    # vignetting and refuses the fit; the exact labels show what it keeps)
    data = runs["data"].exact()
    model = _calibrate(data, profile="paper")
    assert model.parameters["refine_exposures"] is False
    assert model.report["exposures"] == {"refined": False}
    assert pq.correct(data.scene, model).exposures is None


def test_correct_refinement_choices(runs):
    data = runs["data"]
    _, model, _ = runs["refined"]
    assert pq.correct(data.scene, model, refine_exposures=False).exposures is None
    one = pq.ExposureStack(data.scene.frames[:, 4:5], data.scene.exposure_s[4:5], bit_depth=8)
    res = pq.correct(one, model)  # default: cannot refine one exposure, says so
    assert res.exposures is None and res.notes and "nominal times kept" in res.notes[0]
    with pytest.raises(CalibrationError, match="--no-refine-exposures"):
        pq.correct(one, model, refine_exposures=True)
    with pytest.raises(InputError, match="refine_exposures"):
        pq.correct(data.scene, model, refine_exposures="yes")


def test_a_refinement_the_data_cannot_support_keeps_the_nominal_times_by_default(runs, monkeypatch):
    """The profile's default refines where the data determine the times; asked for, it must."""
    import photoquant.calibration_steps as calibration_steps

    def fail(*args, **kwargs):
        raise CalibrationError("exposure refinement: the data do not determine the exposure times")

    monkeypatch.setattr(calibration_steps, "refine_jointly", fail)
    data = runs["data"]
    model = _calibrate(data)
    assert model.parameters["refine_exposures"] is False
    assert model.report["exposures"] == {"refined": False}
    assert any("nominal times kept" in n for n in model.report["notes"])
    with pytest.raises(CalibrationError, match="no-refine-exposures"):
        _calibrate(data, refine_exposures=True)


@pytest.mark.parametrize("labels", ["exact", "jittered"])
def test_the_labels_are_judged_against_the_profiles_response_whatever_the_method(
    runs, monkeypatch, labels
):
    """A response that does not fit the camera must not make exact labels look wrong: the
    views' labels are tested against the profile's own response (one more fit, of
    ``Debevec 1997``), and the chosen method is fitted once, at the labels. Jittered labels
    are rejected, and the chosen method's response is recovered jointly with the times.
    Judged with OpenCV's Robertson response itself, these exact labels were rejected and
    the method fitted five times (the screen, three rounds, the final fit)."""
    import photoquant.calibration_steps as calibration_steps

    fitted: list[str] = []
    real_fit = calibration_steps.fit_response

    def spy(stack, spec, rng=0):
        fitted.append(spec[0].name)
        return real_fit(stack, spec, rng=rng)

    monkeypatch.setattr(calibration_steps, "fit_response", spy)
    data = runs["data"].exact() if labels == "exact" else runs["data"]
    # at exact labels the vignetting fit refuses this response (no refined times absorb
    # its errors any more): the step is left out, the response's path is what is tested
    model = _calibrate(data, response="OpenCV Robertson", vignetting="None")
    decision = model.report["exposures"]["decision"]
    if labels == "exact":
        assert fitted == ["OpenCV Robertson", "Debevec 1997"]
        assert decision["refine"] is False and model.report["exposures"]["refined"] is False
    else:
        assert fitted[:2] == ["OpenCV Robertson", "Debevec 1997"]
        assert fitted[2:] == ["OpenCV Robertson"] * (len(fitted) - 2) and len(fitted) >= 4
        assert decision["refine"] is True and model.report["exposures"]["refined"] is True
