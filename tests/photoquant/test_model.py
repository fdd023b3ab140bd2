"""CameraModel: derived quantities and the versioned on-disk format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import CameraModelError, InputError, OutputExistsError
from photoquant.model import CAMERA_FORMAT, CameraModel, load_camera


def _model(rng, shape=(6, 8)) -> CameraModel:
    levels = np.arange(256.0)
    g = np.stack([2.2 * np.log(np.maximum(levels, 0.5) / 200) + ch for ch in range(3)])
    return CameraModel(
        image_shape=shape,
        channels=("R", "G", "B"),
        bit_depth=8,
        response_levels=levels,
        log_inverse_response=g,
        saturation_level=np.array([217.0, 255.0, 191.0]),
        balance=np.array([1.2, 1.0, 0.8]),
        sensor_lut=(1 + 0.01 * rng.standard_normal((*shape, 3))).astype(np.float32),
        vignetting_params=np.array([[-0.3, 0.05, -0.02, 1.2, 0.5, 0.5]] * 3),
        parameters={"smoothness": 300.0},
        report={"notes": ["x"], "n": np.int64(3)},
    )


def test_save_and_load_round_trip(tmp_path, rng):
    model = _model(rng)
    model.save(tmp_path / "cam")
    back = load_camera(tmp_path / "cam")
    for name in (
        "response_levels",
        "log_inverse_response",
        "saturation_level",
        "balance",
        "sensor_lut",
        "vignetting_params",
    ):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    assert back.image_shape == model.image_shape and back.channels == model.channels
    assert back.parameters == {"smoothness": 300.0} and back.report["n"] == 3
    np.testing.assert_allclose(back.gain_map(), model.gain_map())
    # the JSON is human-readable and versioned
    data = json.loads((tmp_path / "cam" / "camera.json").read_text())
    assert data["format"] == CAMERA_FORMAT
    assert data["vignetting"]["parameter_names"] == ["m1", "m2", "m3", "m4", "m5", "m6"]
    assert load_camera(tmp_path / "cam" / "camera.json").bit_depth == 8


def test_gain_map_and_folded_balance(rng):
    model = _model(rng)
    v = model.vignetting()
    assert v.shape == (6, 8, 3)
    np.testing.assert_allclose(model.gain_map(), 1 / (model.sensor_lut * v))
    np.testing.assert_allclose(
        model.balanced_log_inverse_response() - model.log_inverse_response,
        np.log(model.balance)[:, None] * np.ones((1, 256)),
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
    np.testing.assert_array_equal(load_camera(tmp_path / "cam").sensor_lut, other.sensor_lut)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam"]  # no temp folders left


def test_wrong_version_and_broken_files_are_clear_errors(tmp_path, rng):
    _model(rng).save(tmp_path / "cam")
    path = tmp_path / "cam" / "camera.json"
    data = json.loads(path.read_text())
    data["format"] = "photoquant.camera/9"
    path.write_text(json.dumps(data))
    with pytest.raises(
        CameraModelError, match="'photoquant.camera/9'.*reads 'photoquant.camera/1'"
    ):
        load_camera(tmp_path / "cam")
    path.write_text("{not json")
    with pytest.raises(CameraModelError, match="not readable JSON"):
        load_camera(tmp_path / "cam")
    with pytest.raises(CameraModelError, match="camera.json is missing"):
        load_camera(tmp_path / "nowhere")
    data["format"] = CAMERA_FORMAT
    del data["balance"]
    path.write_text(json.dumps(data))
    with pytest.raises(CameraModelError, match="balance"):
        load_camera(tmp_path / "cam")
    data["balance"] = [1.0, 1.0]
    path.write_text(json.dumps(data))
    with pytest.raises(CameraModelError, match=r"balance.*shape \(3\)"):
        load_camera(tmp_path / "cam")


def test_inconsistent_models_are_refused(rng):
    model = _model(rng)
    with pytest.raises(InputError, match="sensor_lut"):
        CameraModel(**{**_fields(model), "sensor_lut": np.ones((5, 8, 3), np.float32)})
    with pytest.raises(InputError, match="balance"):
        CameraModel(**{**_fields(model), "balance": np.array([1.0, -1.0, 1.0])})
    with pytest.raises(InputError, match="response_levels"):
        CameraModel(**{**_fields(model), "response_levels": np.arange(256.0)[::-1]})


def _fields(model):
    names = [
        "image_shape",
        "channels",
        "bit_depth",
        "response_levels",
        "log_inverse_response",
        "saturation_level",
        "balance",
        "sensor_lut",
        "vignetting_params",
    ]
    return {n: getattr(model, n) for n in names}
