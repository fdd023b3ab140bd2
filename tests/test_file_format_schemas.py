"""The JSON Schemas published in the documentation agree with the loaders.

``docs/schemas/`` holds a schema per JSON format users write or read: the
capture manifest, a camera folder's ``camera.json`` and a regression
baseline. Here the files photoquant and pqsim write match their schema, and
for a set of edits the schema and the loader agree: both accept, or both
refuse. (The loaders check more than a schema can say — files that exist,
tracks naming existing views, a checksum — so only edits a schema can see
are compared.)
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

jsonschema = pytest.importorskip("jsonschema")

ROOT = Path(__file__).resolve().parents[1]
SCHEMAS = ROOT / "docs" / "schemas"


def _schema(name: str) -> Any:
    path = SCHEMAS / name
    if not path.is_file():
        pytest.skip(f"{path} is not here (an installed package without its documentation)")
    schema = json.loads(path.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _schema_ok(validator: Any, doc: Any) -> bool:
    return validator.is_valid(doc)


# ---------------------------------------------------------------------------- manifest


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    folder = tmp_path_factory.mktemp("schemas") / "capture"
    write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=1, seed=0)
    return folder


def _manifest_loads(folder: Path, doc: dict[str, Any]) -> bool:
    from photoquant.errors import PhotoquantError
    from photoquant.io import load_manifest

    path = folder / "edited.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    try:
        load_manifest(path)
    except PhotoquantError:
        return False
    return True


def _set(doc: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    out[key] = value
    return out


def _drop(doc: dict[str, Any], key: str) -> dict[str, Any]:
    out = copy.deepcopy(doc)
    out.pop(key, None)
    return out


def _manifest_edits(doc: dict[str, Any]) -> dict[str, dict[str, Any]]:
    view0 = doc["views"][0]
    return {
        "as written": doc,
        "format 2": _set(doc, "format", "photoquant.captures/2"),
        "no format": _drop(doc, "format"),
        "bit depth 7": _set(doc, "bit_depth", 7),
        "bit depth 17": _set(doc, "bit_depth", 17),
        "bit depth as text": _set(doc, "bit_depth", "8"),
        "no views": _drop(doc, "views"),
        "empty views": _set(doc, "views", []),
        "a view without frames": _set(doc, "views", [{"frames": []}]),
        "one view, no correspondences": _drop(_set(doc, "views", [view0]), "correspondences"),
        "channels repeated": _set(doc, "channels", ["R", "R", "B"]),
        "white ROI of 3 numbers": _set(doc, "white_roi", [0, 0, 10]),
        "exposure basis unknown": _set(doc, "exposure_basis", "aperture"),
        "exposure basis time": _set(doc, "exposure_basis", "time"),
        "saturation spread 65": _set(doc, "saturation_spread", 65),
        "saturation spread 8": _set(doc, "saturation_spread", 8),
        "dark subtraction as text": _set(doc, "dark_subtraction", "yes"),
        "black level 2": _set(doc, "black_level", 2),
        "black level and dark frames": _set(
            _set(doc, "black_level", 2), "dark", copy.deepcopy(view0)
        ),
        "an unknown key": _set(doc, "my_notes", {"lens": "50 mm"}),
    }


def test_manifests_written_by_pqsim_match_the_schema(capture: Path):
    validator = _schema("photoquant.captures-1.schema.json")
    doc = json.loads((capture / "capture.json").read_text(encoding="utf-8"))
    errors = [e.message for e in validator.iter_errors(doc)]
    assert not errors, errors


def test_manifest_schema_and_loader_agree(capture: Path):
    validator = _schema("photoquant.captures-1.schema.json")
    doc = json.loads((capture / "capture.json").read_text(encoding="utf-8"))
    disagree = []
    for what, edited in _manifest_edits(doc).items():
        by_schema = _schema_ok(validator, edited)
        by_loader = _manifest_loads(capture, edited)
        if by_schema != by_loader:
            disagree.append(f"{what}: schema {by_schema}, loader {by_loader}")
    assert not disagree, disagree


# ---------------------------------------------------------------------------- camera


@pytest.fixture(scope="module")
def camera(capture: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    import photoquant as pq

    model = pq.calibrate_manifest(capture / "capture.json")
    folder = tmp_path_factory.mktemp("schemas") / "camera"
    model.save(folder)
    return folder


def _camera_loads(folder: Path, doc: dict[str, Any], tmp: Path) -> bool:
    import shutil

    from photoquant.errors import PhotoquantError
    from photoquant.model import load_camera

    edited = tmp / "edited-camera"
    if edited.exists():
        shutil.rmtree(edited)
    shutil.copytree(folder, edited)
    (edited / "camera.json").write_text(json.dumps(doc), encoding="utf-8")
    try:
        load_camera(edited)
    except PhotoquantError:
        return False
    return True


def test_camera_folders_match_the_schema_and_agree_with_the_loader(camera: Path, tmp_path: Path):
    validator = _schema("photoquant.camera-2.schema.json")
    doc = json.loads((camera / "camera.json").read_text(encoding="utf-8"))
    errors = [e.message for e in validator.iter_errors(doc)]
    assert not errors, errors
    steps_without_response = copy.deepcopy(doc)
    del steps_without_response["steps"]["response"]
    edits = {
        "as written": doc,
        "format 3": _set(doc, "format", "photoquant.camera/3"),
        "no steps": _drop(doc, "steps"),
        "steps without the response": steps_without_response,
        "image shape of 3 numbers": _set(doc, "image_shape", [48, 64, 3]),
        "channels not names": _set(doc, "channels", [1, 2, 3]),
        "bit depth as text": _set(doc, "bit_depth", "8"),
        "report not an object": _set(doc, "report", []),
    }
    disagree = []
    for what, edited in edits.items():
        by_schema = _schema_ok(validator, edited)
        by_loader = _camera_loads(camera, edited, tmp_path)
        if by_schema != by_loader:
            disagree.append(f"{what}: schema {by_schema}, loader {by_loader}")
    assert not disagree, disagree


# ---------------------------------------------------------------------------- baseline


def _sealed(doc: dict[str, Any]) -> dict[str, Any]:
    from validation.baseline import baseline_checksum

    out = copy.deepcopy(doc)
    out.pop("checksum", None)
    out["checksum"] = {"sha256": baseline_checksum(out)}
    return out


def _baseline_loads(doc: dict[str, Any]) -> bool:
    from validation.baseline import validate_baseline
    from validation.config import ValidationError

    try:
        validate_baseline(copy.deepcopy(doc), "edited baseline")
    except ValidationError:
        return False
    return True


def test_the_stored_baseline_matches_the_schema_and_agrees_with_the_loader():
    validator = _schema("photoquant.validation-baseline-2.schema.json")
    path = ROOT / "validation" / "baselines" / "full.json"
    doc = json.loads(path.read_text(encoding="utf-8"))
    errors = [e.message for e in validator.iter_errors(doc)]
    assert not errors, errors
    key = next(iter(doc["metrics"]))

    def metric(field: str, value: Any) -> dict[str, Any]:
        out = copy.deepcopy(doc)
        out["metrics"][key][field] = value
        return _sealed(out)

    def configuration(field: str, value: Any) -> dict[str, Any]:
        out = copy.deepcopy(doc)
        out["configuration"][field] = value
        return _sealed(out)

    edits = {
        "as stored": doc,
        "no metrics": _sealed(_set(doc, "metrics", {})),
        "a negative tolerance": metric("tolerance", -1.0),
        "better sideways": metric("better", "sideways"),
        "a value as text": metric("value", "0.1"),
        "a null value": metric("value", None),
        "allow_none as text": metric("allow_none", "no"),
        "profile not a name": configuration("profile", 3),
        "experiments not names": configuration("experiments", [1]),
        "rendered capture as text": configuration("rendered_capture", "no"),
        "no conditions": _sealed(_drop(doc, "conditions")),
        "edited, checksum kept": _set(doc, "seed", 99),
    }
    disagree = []
    for what, edited in edits.items():
        by_schema = _schema_ok(validator, edited)
        by_loader = _baseline_loads(edited)
        # the checksum is beyond a schema: an edit with the old checksum is the loader's to refuse
        if what == "edited, checksum kept":
            assert by_schema and not by_loader
            continue
        if by_schema != by_loader:
            disagree.append(f"{what}: schema {by_schema}, loader {by_loader}")
    assert not disagree, disagree
