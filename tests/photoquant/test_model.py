"""CameraModel: one model per step, the versioned on-disk format, untrusted camera files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.balance import BalanceModel
from photoquant.errors import CameraModelError, InputError, OutputExistsError
from photoquant.io.images import write_exr
from photoquant.merge import MergeModel
from photoquant.model import CAMERA_FORMAT, CameraModel, load_camera
from photoquant.response import ResponseModel
from photoquant.sensor_lut import SensorLUTModel
from photoquant.vignetting import ExtendedGoldmanChenVignetting

VIG = np.array([[-0.3, 0.05, -0.02, 1.2, 0.5, 0.5]] * 3)


def _model(rng, shape=(6, 8)) -> CameraModel:
    levels = np.arange(256.0)
    g = np.stack([2.2 * np.log(np.maximum(levels, 0.5) / 200) + ch for ch in range(3)])
    return CameraModel(
        image_shape=shape,
        channels=("R", "G", "B"),
        bit_depth=8,
        response=ResponseModel(
            "Debevec 1997", levels, g, np.array([217.0, 255.0, 191.0]), valid_min=[3, 2, 4]
        ),
        merge=MergeModel("Debevec 1997", {"weighting": "hat"}),
        balance=BalanceModel("White Chart", np.array([1.2, 1.0, 0.8])),
        sensor_lut=SensorLUTModel(
            "Irradiance Scene", (1 + 0.01 * rng.standard_normal((*shape, 3))).astype(np.float32)
        ),
        vignetting=ExtendedGoldmanChenVignetting("Extended Goldman-Chen", VIG),
        parameters={"profile": "photoquant"},
        report={"notes": ["x"], "n": np.int64(3)},
    )


def _assert_same(a: CameraModel, b: CameraModel) -> None:
    np.testing.assert_array_equal(a.response.levels, b.response.levels)
    np.testing.assert_array_equal(a.response.log_inverse_response, b.response.log_inverse_response)
    np.testing.assert_array_equal(a.response.saturation_level, b.response.saturation_level)
    np.testing.assert_array_equal(a.response.valid_min, b.response.valid_min)
    np.testing.assert_array_equal(a.balance.factors, b.balance.factors)
    np.testing.assert_array_equal(a.sensor_lut.lut, b.sensor_lut.lut)
    np.testing.assert_array_equal(a.vignetting.params, b.vignetting.params)
    assert a.merge.method == b.merge.method and a.merge.options == b.merge.options
    assert a.image_shape == b.image_shape and a.channels == b.channels
    np.testing.assert_allclose(a.gain_map(), b.gain_map())


def test_save_and_load_round_trip(tmp_path, rng):
    model = _model(rng)
    model.save(tmp_path / "cam")
    back = load_camera(tmp_path / "cam")
    _assert_same(back, model)
    assert back.parameters == {"profile": "photoquant"} and back.report["n"] == 3
    assert {k: m.method for k, m in back.steps().items()} == {
        "response": "Debevec 1997",
        "merge": "Debevec 1997",
        "balance": "White Chart",
        "sensor_lut": "Irradiance Scene",
        "vignetting": "Extended Goldman-Chen",
    }
    # the JSON is human-readable and versioned: {"method", "params"} per step
    data = json.loads((tmp_path / "cam" / "camera.json").read_text())
    assert data["format"] == CAMERA_FORMAT == "photoquant.camera/2"
    vig = data["steps"]["vignetting"]["params"]
    assert vig["parameter_names"] == ["m1", "m2", "m3", "m4", "m5", "m6"]
    assert data["steps"]["sensor_lut"]["images"] == {"sensor_lut": "sensor_lut.exr"}
    assert load_camera(tmp_path / "cam" / "camera.json").bit_depth == 8


def _write_v1(folder, model: CameraModel) -> None:
    """A camera folder as photoquant 0.1 wrote it (photoquant.camera/1)."""
    folder.mkdir()
    write_exr(folder / "sensor_lut.exr", model.sensor_lut.lut, channels=model.channels)
    data = {
        "format": "photoquant.camera/1",
        "image_shape": list(model.image_shape),
        "channels": list(model.channels),
        "bit_depth": 8,
        "saturation_level": model.response.saturation_level.tolist(),
        "balance": model.balance.factors.tolist(),
        "vignetting": {"model": "Extended Goldman-Chen", "params": VIG.tolist()},
        "response": {
            "levels": model.response.levels.tolist(),
            "valid_min": model.response.valid_min.tolist(),
            "log_inverse_response": model.response.log_inverse_response.tolist(),
        },
        "sensor_lut": {"file": "sensor_lut.exr"},
        "parameters": {"merge_weighting": "hat", "merge_method": "Debevec 1997"},
        "report": {},
    }
    (folder / "camera.json").write_text(json.dumps(data))


def test_camera_folders_written_as_format_1_still_load(tmp_path, rng):
    model = _model(rng)
    _write_v1(tmp_path / "old", model)
    back = load_camera(tmp_path / "old")
    _assert_same(back, model)
    assert back.merge.options.weighting == "hat"
    back.save(tmp_path / "new")  # and can be re-saved in the current format
    assert json.loads((tmp_path / "new" / "camera.json").read_text())["format"] == CAMERA_FORMAT


def test_gain_map_and_folded_balance(rng):
    model = _model(rng)
    v = model.vignetting_map()
    assert v.shape == (6, 8, 3)
    np.testing.assert_allclose(model.gain_map(), 1 / (model.sensor_lut.lut * v))
    np.testing.assert_allclose(
        model.balanced_log_inverse_response() - model.response.log_inverse_response,
        np.log(model.balance.factors)[:, None] * np.ones((1, 256)),
    )


def test_existing_camera_is_not_overwritten_unless_asked(tmp_path, rng):
    model = _model(rng)
    model.save(tmp_path / "cam")
    lut_file = tmp_path / "cam" / "sensor_lut.exr"
    before = lut_file.read_bytes()
    other = _model(np.random.default_rng(1))  # another LUT
    with pytest.raises(OutputExistsError, match="already exists"):
        other.save(tmp_path / "cam")
    assert lut_file.read_bytes() == before
    other.save(tmp_path / "cam", overwrite=True)
    np.testing.assert_array_equal(
        load_camera(tmp_path / "cam").sensor_lut.lut, other.sensor_lut.lut
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam"]  # no temp folders left


def _tamper(path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def test_wrong_version_and_broken_files_are_clear_errors(tmp_path, rng):
    _model(rng).save(tmp_path / "cam")
    path = tmp_path / "cam" / "camera.json"
    good = path.read_text()
    _tamper(path, lambda d: d.update(format="photoquant.camera/9"))
    with pytest.raises(
        CameraModelError, match="'photoquant.camera/9'.*reads 'photoquant.camera/1'"
    ):
        load_camera(tmp_path / "cam")
    path.write_text("{not json")
    with pytest.raises(CameraModelError, match="not valid JSON"):
        load_camera(tmp_path / "cam")
    with pytest.raises(CameraModelError, match="camera.json is missing"):
        load_camera(tmp_path / "nowhere")
    path.write_text(good)
    _tamper(path, lambda d: d["steps"].pop("balance"))
    with pytest.raises(CameraModelError, match="lacks balance"):
        load_camera(tmp_path / "cam")
    path.write_text(good)
    _tamper(path, lambda d: d["steps"]["balance"]["params"].update(factors=[1.0, 1.0]))
    with pytest.raises(CameraModelError, match="balance has 2 factors"):
        load_camera(tmp_path / "cam")
    path.write_text(good)
    _tamper(path, lambda d: d["steps"]["vignetting"].update(method="Spline 2031"))
    with pytest.raises(CameraModelError, match="unknown vignetting method 'Spline 2031'.*plug-in"):
        load_camera(tmp_path / "cam")
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(CameraModelError, match="nested deeper than"):
        load_camera(tmp_path / "cam")
    path.write_text(good.replace('"bit_depth": 8', '"bit_depth": NaN'))
    with pytest.raises(CameraModelError, match="not valid JSON"):
        load_camera(tmp_path / "cam")


def _response(d):
    return d["steps"]["response"]["params"]


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda d: _response(d)["log_inverse_response"][1].reverse(), "decreases"),
        (lambda d: _response(d).update(saturation_level=[0, 255, 191]), "saturation_level"),
        (lambda d: _response(d).update(saturation_level=[-5, 255, 191]), "saturation_level"),
        (lambda d: _response(d).update(valid_min=[3, 255, 4]), "valid_min"),
        (
            lambda d: _response(d).update(
                log_inverse_response=[
                    [v * 1000 for v in row] for row in _response(d)["log_inverse_response"]
                ]
            ),
            "spans",
        ),
        (lambda d: _response(d).update(levels=list(range(0, 512, 2))), "outside \\[0, 255\\]"),
        (lambda d: _response(d).update(levels="0..255"), "levels"),
        (
            lambda d: d["steps"]["vignetting"]["params"].update(
                params=[[-3.0, 0, 0, 1, 0.5, 0.5]] * 3
            ),
            "vignetting map is not positive",
        ),
        (lambda d: d.update(channels=["G", "R", "B"]), "channels"),
        (lambda d: d.update(image_shape=[6, "8"]), "image_shape"),
        (
            lambda d: d["steps"]["merge"]["params"].update(options={"weighting": "cubic"}),
            "weighting",
        ),
        (lambda d: d["steps"]["merge"]["params"].update(options={"speed": 3}), "no option"),
        (
            lambda d: d["steps"]["sensor_lut"].update(images={"sensor_lut": "../x.exr"}),
            "plain file",
        ),
    ],
)
def test_tampered_camera_files_are_refused_in_one_line(tmp_path, rng, edit, match):
    """A hand-edited camera.json that would correct into garbage is named, not used."""
    _model(rng).save(tmp_path / "cam")
    _tamper(tmp_path / "cam" / "camera.json", edit)
    with pytest.raises(CameraModelError, match=match) as info:
        load_camera(tmp_path / "cam")
    assert "\n" not in str(info.value)


def test_a_non_positive_lut_file_is_refused(tmp_path, rng):
    model = _model(rng)
    model.save(tmp_path / "cam")
    lut = model.sensor_lut.lut.copy()
    lut[0, 0, 1] = -1.0
    write_exr(tmp_path / "cam" / "sensor_lut.exr", lut, channels=model.channels)
    with pytest.raises(CameraModelError, match="positive"):
        load_camera(tmp_path / "cam")


def test_inconsistent_models_are_refused(rng):
    model = _model(rng)
    fields = {k: getattr(model, k) for k in ("image_shape", "channels", "bit_depth")}
    fields |= model.steps()
    with pytest.raises(InputError, match="sensor LUT"):
        CameraModel(**{**fields, "sensor_lut": SensorLUTModel("x", np.ones((5, 8, 3), np.float32))})
    with pytest.raises(InputError, match="balance"):
        BalanceModel("x", np.array([1.0, -1.0, 1.0]))
    with pytest.raises(InputError, match="levels"):
        ResponseModel("x", np.arange(256.0)[::-1], model.response.log_inverse_response, [200] * 3)
    with pytest.raises(InputError, match="`balance` must be a BalanceModel"):
        CameraModel(**{**fields, "balance": np.ones(3)})
