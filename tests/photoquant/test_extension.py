"""Extending photoquant: a new method is one function (and its model) plus one registry entry.

Each test defines a method here, in the test module, registers it with
:func:`photoquant.register_method` and runs it through calibrate → save →
load → correct on a small synthetic capture set; nothing else in photoquant
is touched. Then the profiles: the paper's options reach the camera, the
photoquant profile is the paper's with every deviation applied, and wrong
specs are one-line errors that name the valid choices.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

import photoquant as pq
from photoquant.calibration import resolve_steps
from photoquant.cli import main
from photoquant.errors import CameraModelError, InputError
from photoquant.methods import options_to_dict, resolve_method
from photoquant.profiles import DEVIATIONS, PROFILES
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A small synthetic set of the ``ccd`` preset (linear response): 3 views, LUT scene, chart."""
    folder = tmp_path_factory.mktemp("extension") / "capture"
    return write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=5)


@pytest.fixture(scope="module")
def scene(capture):
    manifest = pq.load_manifest(capture)
    return pq.load_stack(manifest.scene, manifest)


@contextmanager
def registered(step: str, name: str, function: Any, **kwargs: Any) -> Iterator[pq.Method]:
    """Register a method for the duration of a test, and always unregister it."""
    method = pq.register_method(step, name, function, **kwargs)
    try:
        yield method
    finally:
        pq.registry(step).remove(name)


def same_correction(a: Any, b: Any) -> None:
    np.testing.assert_array_equal(a.photoquantity, b.photoquantity)
    np.testing.assert_array_equal(a.mask, b.mask)


# ---------------------------------------------------------------------------
# A response method: g = γ ln z
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PowerLawOptions:
    gamma: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.gamma, bool) or not isinstance(self.gamma, int | float):
            raise InputError(f"`gamma` must be a number, got {self.gamma!r}")
        if not self.gamma > 0:
            raise InputError(f"`gamma` must be positive, got {self.gamma!r}")


def power_law_g(levels: np.ndarray, gamma: float) -> np.ndarray:
    return gamma * np.log(np.maximum(levels, 0.5))


def characterise_response_power_law(
    stack: pq.ExposureStack, options: PowerLawOptions | None, rng: Any
) -> pq.StepFit[pq.ResponseModel]:
    """``g = γ ln z``: a camera with ``z ∝ E^(1/γ)`` (nothing fitted)."""
    opts = options or PowerLawOptions()
    levels = np.arange(2.0**stack.bit_depth)
    model = pq.ResponseModel(
        "Power law (test)",
        levels,
        np.tile(power_law_g(levels, opts.gamma), (stack.n_channels, 1)),
        np.asarray(stack.saturation_level, dtype=np.float64),
        valid_min=np.ones(stack.n_channels),
        params={"gamma": opts.gamma},
    )
    return pq.StepFit(model, {"gamma": opts.gamma})


def test_a_new_response_method_runs_through_calibrate_save_load_correct(capture, scene, tmp_path):
    with registered(
        "response", "Power law (test)", characterise_response_power_law, options=PowerLawOptions
    ):
        model = pq.calibrate_manifest(capture, response=("power law (test)", {"gamma": 2.0}))
        assert model.response.method == "Power law (test)"
        levels = model.response.levels
        np.testing.assert_allclose(model.response.log_inverse_response[1], power_law_g(levels, 2))
        assert model.parameters["steps"]["response"] == {
            "method": "Power law (test)",
            "options": {"gamma": 2.0},
        }
        assert model.report["response"]["gamma"] == 2.0

        model.save(tmp_path / "camera")
        loaded = pq.load_camera(tmp_path / "camera")
        assert loaded.response.method == "Power law (test)"
        assert loaded.response.params == {"gamma": 2.0}
        np.testing.assert_array_equal(
            loaded.response.log_inverse_response, model.response.log_inverse_response
        )
        same_correction(pq.correct(scene, loaded), pq.correct(scene, model))
    # the camera is rebuilt through the registry: without the method it does not load
    with pytest.raises(CameraModelError, match=r"Power law \(test\)"):
        pq.load_camera(tmp_path / "camera")


@pytest.mark.parametrize("notes", [["gamma assumed, not fitted", "second line"], "one line"])
def test_a_response_methods_notes_reach_the_cameras_notes(capture, notes):
    # a method's report may hold lines for the user (a list, or one string: one line)
    def with_notes(stack, options, rng):
        fit = characterise_response_power_law(stack, options, rng)
        return pq.StepFit(fit.model, {**fit.report, "notes": notes})

    with registered("response", "Noted (test)", with_notes, options=PowerLawOptions):
        model = pq.calibrate_manifest(capture, response="noted (test)")
    expected = [notes] if isinstance(notes, str) else notes
    assert [n for n in model.report["notes"] if n in expected] == expected


def test_a_response_methods_notes_that_are_not_lines_are_a_named_error(capture):
    def with_notes(stack, options, rng):
        fit = characterise_response_power_law(stack, options, rng)
        return pq.StepFit(fit.model, {**fit.report, "notes": 5})

    with registered("response", "Noted (test)", with_notes, options=PowerLawOptions):
        with pytest.raises(InputError, match=r"report `notes` must be a string or a list.*got 5"):
            pq.calibrate_manifest(capture, response="noted (test)")


# ---------------------------------------------------------------------------
# A vignetting model of its own class, stored as an image in the camera folder
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TabulatedVignetting(pq.VignettingModel):
    """``v`` given on the pixel grid, stored as an OpenEXR image of the step."""

    method: str
    table: np.ndarray

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        if self.table.shape[:2] != tuple(image_shape):
            raise InputError(f"the table is {self.table.shape[:2]}, the image {image_shape}")
        return self.table.astype(np.float64)

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {"kind": "table"}, {"table": self.table}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> TabulatedVignetting:
        if params.get("kind") != "table":
            raise InputError(f"not a tabulated vignetting: {params!r}")
        return cls(method, images["table"])


@dataclass(frozen=True)
class FalloffOptions:
    k: float = 0.2


def characterise_vignetting_falloff(
    data: pq.VignettingData, options: FalloffOptions | None
) -> pq.StepFit[TabulatedVignetting]:
    """``v = 1 − k r²`` tabulated (``r = 1`` at the corners); nothing fitted."""
    opts = options or FalloffOptions()
    h, w = data.image_shape
    y, x = np.mgrid[0:h, 0:w]
    r2 = (((x + 0.5) / w - 0.5) ** 2 + ((y + 0.5) / h - 0.5) ** 2) / 0.5
    n_ch = data.uniform_views[0].shape[-1]
    table = np.repeat((1 - opts.k * r2)[..., None], n_ch, axis=-1).astype(np.float32)
    return pq.StepFit(TabulatedVignetting("Falloff (test)", table), {"n_tracks": len(data.tracks)})


def test_a_vignetting_methods_warnings_reach_the_cameras_notes(capture):
    # the vignetting step's report warnings (photoquant.vignetting.trust's) are the
    # camera's notes, read as a response method's notes are
    def with_warnings(data, options):
        fit = characterise_vignetting_falloff(data, options)
        return pq.StepFit(fit.model, {**fit.report, "warnings": ["the views agree poorly"]})

    with registered(
        "vignetting", "Warned (test)", with_warnings, options=FalloffOptions,
        model=TabulatedVignetting,
    ):  # fmt: skip
        model = pq.calibrate_manifest(capture, vignetting="warned (test)")
    assert "the views agree poorly" in model.report["notes"]


def test_a_new_vignetting_model_runs_through_calibrate_save_load_correct(capture, scene, tmp_path):
    with registered(
        "vignetting",
        "Falloff (test)",
        characterise_vignetting_falloff,
        options=FalloffOptions,
        model=TabulatedVignetting,
    ):
        model = pq.calibrate_manifest(capture, vignetting=("Falloff (test)", {"k": 0.3}))
        assert isinstance(model.vignetting, TabulatedVignetting)
        v = model.vignetting_map()
        assert v[0, 0, 0] == pytest.approx(
            1 - 0.3 * ((0.5 - 0.5 / 64) ** 2 + (0.5 - 0.5 / 48) ** 2) / 0.5
        )
        assert model.report["vignetting"]["n_tracks"] > 0  # the correspondences reached it
        assert model.parameters["steps"]["vignetting"]["options"] == {"k": 0.3}

        folder = model.save(tmp_path / "camera")
        stored = pq.load_camera(folder).to_json_dict()["steps"]["vignetting"]
        assert stored["method"] == "Falloff (test)" and stored["images"] == {"table": "table.exr"}
        assert (folder / "table.exr").is_file()
        loaded = pq.load_camera(folder)
        assert isinstance(loaded.vignetting, TabulatedVignetting)
        np.testing.assert_array_equal(loaded.vignetting_map(), v)
        same_correction(pq.correct(scene, loaded), pq.correct(scene, model))
        # the model divides the scene: with v = 1 the corner would be darker by 1 / v
        plain = pq.calibrate_manifest(capture, vignetting="None")
        ratio = pq.correct(scene, model).photoquantity / pq.correct(scene, plain).photoquantity
        assert np.nanmedian(ratio[0, 0] / ratio[24, 32]) == pytest.approx(1 / v[0, 0, 0], rel=0.05)
    with pytest.raises(CameraModelError, match=r"Falloff \(test\)"):
        pq.load_camera(folder)


# ---------------------------------------------------------------------------
# A merge method: the unweighted mean over the valid exposures
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class UniformMergeOptions:
    min_exposures: int = 1


MERGE_CALLS: list[tuple[int, int]] = []


def merge_uniform_mean(
    stack: pq.ExposureStack, response: pq.ResponseModel, options: UniformMergeOptions | None
) -> pq.MergeResult:
    """``ln c = mean_k [g(z_k) − ln t_k]`` over exposures strictly inside the valid range."""
    opts = options or UniformMergeOptions()
    MERGE_CALLS.append(stack.image_shape)
    values = stack.mean()
    saturated = stack.saturated(response.saturation_level)
    valid = (values > response.valid_min) & (values < response.saturation_level) & ~saturated
    log_t = np.log(stack.exposure_s)[:, None, None, None]
    w = valid.astype(np.float64)
    num = (w * (response.log_inverse(values) - log_t)).sum(axis=0)
    den = w.sum(axis=0)
    mask = den < opts.min_exposures
    with np.errstate(invalid="ignore", divide="ignore"):
        log_c = np.where(mask, np.nan, num / np.where(den > 0, den, 1))
    any_unsat = (~saturated).any(axis=0)
    return pq.MergeResult(log_c, mask, mask & ~any_unsat, mask & any_unsat, den)


def test_a_new_merge_method_runs_through_calibrate_save_load_correct(capture, scene, tmp_path):
    with registered(
        "merge", "Uniform mean (test)", merge_uniform_mean, options=UniformMergeOptions
    ):
        MERGE_CALLS.clear()
        model = pq.calibrate_manifest(capture, merge=("Uniform mean (test)", {"min_exposures": 2}))
        assert len(MERGE_CALLS) == 4  # 3 views and the irradiance scene
        assert model.merge.method == "Uniform mean (test)"
        assert model.merge.options == UniformMergeOptions(2)

        model.save(tmp_path / "camera")
        loaded = pq.load_camera(tmp_path / "camera")
        assert loaded.merge.options == UniformMergeOptions(2)
        MERGE_CALLS.clear()
        corrected = pq.correct(scene, loaded)
        assert MERGE_CALLS == [scene.image_shape]  # the correction merges with the camera's method
        same_correction(corrected, pq.correct(scene, model))
        debevec = pq.correct(scene, loaded, merge="Debevec 1997")
        assert not np.array_equal(corrected.photoquantity, debevec.photoquantity, equal_nan=True)
    with pytest.raises(CameraModelError, match=r"Uniform mean \(test\)"):
        pq.load_camera(tmp_path / "camera")


def test_registered_names_are_unique_and_cleaned_up():
    with registered("merge", "Uniform mean (test)", merge_uniform_mean):
        with pytest.raises(InputError, match=r"'Uniform mean \(test\)' is already registered"):
            pq.register_method("merge", "UNIFORM MEAN (TEST)", merge_uniform_mean)
    assert "Uniform mean (test)" not in pq.registry("merge")


# ---------------------------------------------------------------------------
# Profiles
# ---------------------------------------------------------------------------

PAPER_OPTIONS = {
    "response": {"weighting": "hat", "sampling": "random", "n_samples": 500},
    "merge": {"weighting": "hat", "exclude_below_valid_min": False},
    "balance": {"stage": "linearised"},
    "vignetting": {"normalise": "none"},
}
"""The paper's choices (§5.2, eq. 6, §5.3, §5.5), as the camera must record them."""


def assert_paper_steps(steps: dict[str, Any]) -> None:
    for step, options in PAPER_OPTIONS.items():
        recorded = steps[step]["options"]
        assert {k: recorded[k] for k in options} == options, step


def test_paper_profile_is_recorded_and_applied(capture):
    model = pq.calibrate_manifest(capture, profile="paper")
    assert model.parameters["profile"] == "paper"
    assert_paper_steps(model.parameters["steps"])
    # applied, not only recorded: the camera merges with the plain hat and all values
    assert model.merge.options.weighting == "hat"
    assert model.merge.options.exclude_below_valid_min is False
    default = pq.calibrate_manifest(capture)
    assert default.parameters["profile"] == "photoquant"
    assert default.parameters["steps"]["response"]["options"]["n_samples"] == 2000
    assert not np.array_equal(default.balance.factors, model.balance.factors)


def test_cli_calibrate_with_the_paper_profile_end_to_end(capture, tmp_path, capsys):
    cam, exr = tmp_path / "camera", tmp_path / "scene.exr"
    assert main(["calibrate", str(capture), "-o", str(cam), "-q", "--profile", "paper"]) == 0
    assert "profile: paper" in capsys.readouterr().out
    model = pq.load_camera(cam)
    assert model.parameters["profile"] == "paper"
    assert_paper_steps(model.parameters["steps"])
    assert main(["correct", str(capture), "--camera", str(cam), "-o", str(exr), "-q"]) == 0
    image, names = pq.read_exr(exr)  # the photoquantity, then its uncertainty's layers
    image = image[..., :3]
    assert names[:3] == ("R", "G", "B") and np.isfinite(image).mean() > 0.9
    assert main(["info", str(cam)]) == 0
    assert "profile: paper" in capsys.readouterr().out


def test_photoquant_profile_is_the_paper_profile_with_every_deviation():
    """Apart from the paper's statement of its biases (``uncorrected_bias``, which changes
    no estimate and, with every deviation applied, has nothing left to state: the options
    are then the reference's own)."""
    derived: dict[str, tuple[str, dict[str, Any]]] = {
        step: (name, {k: v for k, v in options.items() if k != "uncorrected_bias"})
        for step, (name, options) in PROFILES["paper"].items()
    }
    for deviation in DEVIATIONS:
        name, options = derived[deviation.step]
        derived[deviation.step] = (name, options | dict(deviation.options))
    ours = resolve_steps("photoquant")
    for step, (name, options) in derived.items():
        method, resolved = resolve_method(step, (name, options), (name, {}))
        assert ours[step][0].name == method.name, step
        assert options_to_dict(ours[step][1]) == options_to_dict(resolved), step


@pytest.mark.parametrize("deviation", DEVIATIONS, ids=lambda d: d.name)
def test_each_deviation_alone_changes_the_paper_profile(deviation):
    paper = resolve_steps("paper")
    name, options = PROFILES["paper"][deviation.step]
    _, switched = resolve_method(
        deviation.step, (name, dict(options) | dict(deviation.options)), (name, {})
    )
    before, after = options_to_dict(paper[deviation.step][1]), options_to_dict(switched)
    changed = {k for k in after if after[k] != before[k]}
    assert changed and changed <= set(deviation.options), deviation.name
    assert deviation.why and deviation.step in PROFILES["paper"]


@pytest.mark.parametrize(
    ("specs", "needles"),
    [
        ({"response": "Nope"}, ["'Nope'", "valid methods are", "Debevec 1997"]),
        ({"vignetting": "Nope"}, ["Extended Goldman-Chen", "None"]),
        (
            {"response": ("Debevec 1997", {"smoothnes": 3})},
            ["smoothnes", "its options are", "smoothness", "n_samples"],
        ),
        ({"vignetting": ("None", {"k": 1})}, ["'None' takes no options"]),
        ({"response": {"n_samples": "many"}}, ["n_samples", "integer", "'many'"]),
        ({"merge": {"weighting": "bogus"}}, ["'bogus'", "hat", "hat-quantisation", "uniform"]),
        ({"balance": {"stage": "after"}}, ["'uniformised'", "'linearised'", "'after'"]),
        ({"response": 42}, ["method name", "(name, options)", "int"]),
        ({"bogus_step": "x"}, ["bogus_step", "response", "correspondences"]),
    ],
)
def test_spec_errors_are_one_line_and_name_the_choices(specs, needles):
    with pytest.raises(InputError) as err:
        resolve_steps("photoquant", **specs)
    message = str(err.value)
    assert "\n" not in message
    for needle in needles:
        assert needle in message


def test_unknown_profile_names_the_profiles():
    with pytest.raises(
        InputError, match=r"unknown profile 'papers'; profiles are: photoquant, paper"
    ):
        resolve_steps("papers")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--method", "response=Nope"], "Debevec 1997"),
        (["--option", "response.smoothnes=3"], "smoothness"),
        (["--option", "merge.weighting=bogus"], "hat-quantisation"),
    ],
)
def test_cli_spec_errors_are_one_line(capture, tmp_path, capsys, args, needle):
    out = tmp_path / "camera"
    assert main(["calibrate", str(capture), "-o", str(out), "-q", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("photoquant: error: ") and needle in err
    assert not out.exists()


def test_options_dataclass_instance_selects_its_method():
    with registered(
        "response", "Power law (test)", characterise_response_power_law, options=PowerLawOptions
    ):
        method, options = resolve_steps("paper", response=PowerLawOptions(3.0))["response"]
        assert method.name == "Power law (test)" and options == PowerLawOptions(3.0)
        assert dataclasses.asdict(options) == {"gamma": 3.0}
