"""Standard output and error never raise, whatever the locale, encoding and error handler.

Under ``LC_ALL=C PYTHONUTF8=0`` Python's standard output is ASCII with the
``surrogateescape`` handler, which raises for ``—`` or ``±``; under
``PYTHONIOENCODING=ascii:strict`` it raises for any non-ASCII text. The
commands print both (``methods``' table, ``info``'s exposures ``±``,
``crossval``'s table), so each is run under each environment; and any text
at all is printed through streams of every encoding and handler.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant._stdio import safe_stdio
from photoquant.cli import main
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset

REPO = Path(__file__).resolve().parents[1]

#: The environments that gave standard streams a handler that can raise.
LOCALES = {
    "C, no UTF-8 mode": {"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"},
    "ascii:strict": {"LC_ALL": "C", "LANG": "C", "PYTHONIOENCODING": "ascii:strict"},
    "latin-1:surrogateescape": {"PYTHONIOENCODING": "latin-1:surrogateescape"},
}


def _env(overrides: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONIOENCODING", "PYTHONUTF8")}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])
    env.update(overrides)
    return env


@pytest.fixture(scope="module")
def capture_and_camera(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("locale")
    manifest = write_capture_set(
        root / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3
    )
    assert main(["calibrate", str(manifest), "-o", str(root / "cam"), "-q"]) == 0
    return manifest, root / "cam"


@pytest.mark.parametrize("locale", sorted(LOCALES))
def test_methods_info_and_crossval_print_under_any_locale(capture_and_camera, locale):
    manifest, camera = capture_and_camera
    commands = {
        "methods": ["methods"],
        "info": ["info", str(camera)],
        "crossval": ["crossval", str(manifest)],
    }
    outputs = {}
    for name, argv in commands.items():
        proc = subprocess.run(
            [sys.executable, "-m", "photoquant", *argv],
            env=_env(LOCALES[locale]),
            capture_output=True,
            timeout=300,
        )
        assert proc.returncode == 0, (name, proc.stderr.decode("ascii", "replace"))
        assert b"Traceback" not in proc.stderr, name
        outputs[name] = proc.stdout
    # the characters the encoding lacks are escaped, not lost
    assert b"\\u2014" in outputs["methods"]
    assert b"\\xb1" in outputs["info"] or b"\xb1" in outputs["info"]  # latin-1 has a ±


def _stream(encoding: str, errors: str) -> tuple[io.TextIOWrapper, io.BytesIO]:
    raw = io.BytesIO()
    return io.TextIOWrapper(raw, encoding=encoding, errors=errors, write_through=True), raw


@settings(max_examples=200, deadline=None)
@given(
    text=st.text(
        alphabet=st.characters(blacklist_categories=("Cs",)) | st.sampled_from(["\udcff", "\udc80"])
    ),
    encoding=st.sampled_from(["ascii", "latin-1", "utf-8", "cp1252"]),
    errors=st.sampled_from(["strict", "surrogateescape", "surrogatepass", "replace"]),
)
def test_any_text_prints_through_any_stream(text, encoding, errors):
    out, out_raw = _stream(encoding, errors)
    err, _ = _stream(encoding, errors)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(sys, "stdout", out)
        m.setattr(sys, "stderr", err)
        safe_stdio()
        print(text, file=sys.stdout)
        print(text, file=sys.stderr)
    written = out_raw.getvalue()
    assert written.endswith(b"\n")
    if errors == "surrogateescape":
        # an undecodable byte of a file name is written back as that byte
        for ch in ("\udcff", "\udc80"):
            if ch in text:
                assert bytes([ord(ch) - 0xDC00]) in written


def test_safe_stdio_keeps_a_handler_that_cannot_raise(monkeypatch):
    out, _ = _stream("ascii", "replace")
    monkeypatch.setattr(sys, "stdout", out)
    safe_stdio()
    assert out.errors == "replace"
    print("—")
    assert sys.stdout.errors == "replace"
