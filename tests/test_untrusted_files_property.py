"""Property tests: random damage to camera files and manifests never gives a traceback or garbage.

Every mutated file either fails with one :class:`~photoquant.errors.PhotoquantError`
line (the CLI's exit 2), or gives a complete result that works: a camera that
loads, corrects into finite values where a value is valid, and saves and
loads again; a manifest whose frames load.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import photoquant as pq
from photoquant.errors import PhotoquantError
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset

SHAPE = (48, 64)


@pytest.fixture(scope="module")
def capture_and_camera(tmp_path_factory):
    root = tmp_path_factory.mktemp("untrusted")
    manifest = write_capture_set(
        root / "set",
        camera_from_preset("ccd"),
        shape=SHAPE,
        exposure_s=np.geomspace(0.002, 0.2, 5),
        n_repeats=2,
        n_views=3,
        seed=3,
    )
    model = pq.calibrate_manifest(manifest)
    model.save(root / "cam")
    return manifest, root / "cam"


# values a hand edit or a corrupted file may put anywhere
_json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=False, allow_infinity=False, width=64),
    st.text(max_size=12),
)
_json_values = st.recursive(
    _json_scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=8,
)


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a JSON document (lists by index, only their first 3 items)."""
    out = [prefix] if prefix else []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:3]):
            out += _paths(v, (*prefix, i))
    return out


def _mutate(doc: Any, path: tuple, action: str, value: Any) -> Any:
    doc = copy.deepcopy(doc)
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    if action == "delete":
        del parent[key]
    elif (
        action == "scale"
        and isinstance(parent[key], int | float)
        and not isinstance(parent[key], bool)
    ):
        parent[key] = parent[key] * 1000.0 + 1.0
    else:
        parent[key] = value
    return doc


def _one_line(exc: BaseException) -> None:
    text = str(exc)
    assert text and "\n" not in text, repr(text)


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(data=st.data())
def test_a_damaged_camera_file_is_refused_in_one_line_or_works(capture_and_camera, tmp_path, data):
    manifest, camera = capture_and_camera
    doc = json.loads((camera / "camera.json").read_text())
    path = data.draw(st.sampled_from(_paths(doc)), label="path")
    action = data.draw(st.sampled_from(["replace", "delete", "scale"]), label="action")
    value = data.draw(_json_values, label="value")
    work = Path(tempfile.mkdtemp(dir=tmp_path))  # one folder per example
    target = work / "cam"
    shutil.copytree(camera, target)
    (target / "camera.json").write_text(json.dumps(_mutate(doc, path, action, value)))
    try:
        model = pq.load_camera(target)
    except PhotoquantError as exc:
        _one_line(exc)
        return
    # accepted: it must be a camera that works end to end
    m = pq.load_manifest(manifest)
    result = pq.correct(pq.load_stack(m.scene, m), model)
    valid = ~result.mask
    assert np.all(np.isfinite(result.photoquantity[valid]))
    assert np.all(result.photoquantity[valid] > 0)
    model.save(work / "again")
    back = pq.load_camera(work / "again")
    np.testing.assert_array_equal(back.gain_map(), model.gain_map())


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(data=st.data())
def test_a_damaged_manifest_is_refused_in_one_line_or_loads(capture_and_camera, data):
    manifest, _ = capture_and_camera
    doc = json.loads(Path(manifest).read_text())
    # the frame lists are long: mutate the first frames of each set and the top-level keys
    path = data.draw(st.sampled_from(_paths(doc)), label="path")
    action = data.draw(st.sampled_from(["replace", "delete", "scale"]), label="action")
    value = data.draw(_json_values, label="value")
    fd, name = tempfile.mkstemp(dir=Path(manifest).parent, suffix=".json")
    os.close(fd)
    mutated = Path(name)
    mutated.write_text(json.dumps(_mutate(doc, path, action, value)))
    try:
        try:
            m = pq.load_manifest(mutated)
            stacks = [pq.load_stack(v, m) for v in m.views]
        except PhotoquantError as exc:
            _one_line(exc)
            return
        assert stacks and all(isinstance(s, pq.ExposureStack) for s in stacks)
    finally:
        mutated.unlink()
