"""Plug-ins from other distributions, through the entry-point group ``photoquant.methods``.

The example plug-in (``examples/photoquant-plugin-example``) is built and
installed into a temporary folder with pip, exactly as a user installs one,
and used by ``photoquant`` commands run in a subprocess whose ``PYTHONPATH``
holds that folder: calibrate with its methods, info, correct, compare,
methods, and the camera folder round-trips. Broken plug-ins (a name taken by
a built-in, an import that fails) are distributions written by hand (a
module and its ``.dist-info``), which is all the entry-point machinery reads.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

from photoquant.io import read_exr
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "photoquant-plugin-example"
RESPONSE = "Linear (example)"
VIGNETTING = "Radial polynomial (example)"

pytestmark = pytest.mark.slow


def _why_no_offline_build() -> str | None:
    """Why pip cannot build the example here without a network (None: it can)."""
    if importlib.util.find_spec("pip") is None:
        return "pip is not installed"
    if importlib.util.find_spec("setuptools") is None:
        return "setuptools is not installed (the test extra requires it)"
    version = metadata.version("setuptools")
    major_minor = tuple(int(p) for p in version.split(".")[:2] if p.isdigit())
    if major_minor < (70, 1) and importlib.util.find_spec("wheel") is None:
        return (
            f"setuptools {version} needs the `wheel` package to build a wheel "
            "(setuptools >= 70.1 does not; pip install '.[test]')"
        )
    return None


def _env(*paths: Path | str) -> dict[str, str]:
    """The environment of a subprocess whose imports come from ``paths`` first, then the repo."""
    rest = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    return {**os.environ, "PYTHONPATH": os.pathsep.join([*map(str, paths), str(REPO), *rest])}


def photoquant(*args: str, path: tuple[Path, ...] = ()) -> subprocess.CompletedProcess[str]:
    """Run ``python -m photoquant ARGS`` with ``path`` on ``PYTHONPATH``."""
    return subprocess.run(
        [sys.executable, "-m", "photoquant", *args],
        env=_env(*path),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def python(code: str, path: tuple[Path, ...]) -> subprocess.CompletedProcess[str]:
    """Run a Python snippet with ``path`` on ``PYTHONPATH``."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env=_env(*path),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def one_error_line(result: subprocess.CompletedProcess[str]) -> str:
    """The single ``photoquant: error:`` line of a failed command (asserting there is one)."""
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("photoquant: error: "), result.stderr
    return lines[0]


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example plug-in, built and installed by pip into a folder of its own."""
    reason = _why_no_offline_build()
    if reason is not None:
        pytest.skip(f"cannot build the example plug-in offline: {reason}")
    root = tmp_path_factory.mktemp("plugin")
    source, site = root / "source", root / "site"
    # built from a copy: the build writes build/ and *.egg-info next to its sources
    shutil.copytree(EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info"))
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--disable-pip-version-check",
            "--quiet",
            "--target",
            str(site),
            str(source),
        ],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert (site / "photoquant_plugin_example.py").is_file()
    return site


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small synthetic capture set of the linear ``ccd`` preset (3 views, white chart)."""
    folder = tmp_path_factory.mktemp("plugin-capture") / "capture"
    return write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3)


def test_example_plugin_is_listed_with_its_options(plugin_site):
    result = photoquant("methods", "--json", path=(plugin_site,))
    assert result.returncode == 0, result.stderr
    listed = json.loads(result.stdout)
    assert listed["response"][RESPONSE]["module"] == "photoquant_plugin_example"
    assert listed["response"][RESPONSE]["options"] == {"black_level": 0.0, "floor": 0.5}
    assert listed["vignetting"][VIGNETTING]["options"] == {"min_pairs": 10}
    # the built-ins are still there, and without the plug-in its methods are not
    assert "Debevec 1997" in listed["response"]
    plain = json.loads(photoquant("methods", "--json").stdout)
    assert RESPONSE not in plain["response"] and VIGNETTING not in plain["vignetting"]


def test_example_plugin_calibrates_corrects_compares_and_round_trips(
    plugin_site, capture, tmp_path
):
    cam = tmp_path / "camera"
    result = photoquant(
        "calibrate",
        str(capture),
        "-o",
        str(cam),
        "-q",
        "--method",
        f"response={RESPONSE}",
        "--method",
        f"vignetting={VIGNETTING}",
        "--option",
        "response.black_level=0",
        path=(plugin_site,),
    )
    assert result.returncode == 0, result.stderr
    assert f"response {RESPONSE}" in result.stdout and f"vignetting {VIGNETTING}" in result.stdout

    stored = json.loads((cam / "camera.json").read_text())
    assert stored["format"] == "photoquant.camera/2"
    assert stored["steps"]["response"]["method"] == RESPONSE
    assert stored["steps"]["vignetting"]["method"] == VIGNETTING
    coefficients = np.asarray(stored["steps"]["vignetting"]["params"]["coefficients"])
    assert coefficients.shape == (3, 2)
    # the preset's lens darkens towards the corners: v falls off with r
    assert np.all(coefficients[:, 0] < 0)
    assert stored["parameters"]["steps"]["response"] == {
        "method": RESPONSE,
        "options": {"black_level": 0, "floor": 0.5},
    }

    info = photoquant("info", str(cam), "--json", path=(plugin_site,))
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["steps"]["vignetting"] == VIGNETTING

    exr = tmp_path / "scene.exr"
    corrected = photoquant(
        "correct", str(capture), "--camera", str(cam), "-o", str(exr), "-q", path=(plugin_site,)
    )
    assert corrected.returncode == 0, corrected.stderr
    image, channels = read_exr(exr)  # the photoquantity, then its uncertainty's layers
    image = image[..., :3]
    assert channels[:3] == ("R", "G", "B") and image.shape == (48, 64, 3)
    assert np.isfinite(image).mean() > 0.9

    # against the synthetic truth: the ccd preset is linear, so g = ln z is exact, and
    # the radial polynomial approximates the preset's (off-centre) vignetting
    compared = photoquant("compare", str(capture), "--camera", str(cam), "--json")
    assert compared.returncode != 0  # without the plug-in the camera does not load ...
    compared = photoquant(
        "compare", str(capture), "--camera", str(cam), "--json", path=(plugin_site,)
    )
    assert compared.returncode == 0, compared.stderr  # ... with it, it ranks like any camera
    metrics = json.loads(compared.stdout)
    assert max(ch["rms"] for ch in metrics["response"]) < 1e-9
    assert metrics["vignetting"]["method"] == VIGNETTING
    assert metrics["vignetting"]["error"]["e_mean"] < 0.03

    # save → load → save: the plug-in's own model class comes back, identical
    check = python(
        f"""
        import numpy as np
        import photoquant as pq
        from photoquant_plugin_example import RadialPolynomialVignetting
        a = pq.load_camera({str(cam)!r})
        assert type(a.vignetting) is RadialPolynomialVignetting, type(a.vignetting)
        a.save({str(tmp_path / "again")!r})
        b = pq.load_camera({str(tmp_path / "again")!r})
        assert type(b.vignetting) is RadialPolynomialVignetting
        np.testing.assert_array_equal(a.vignetting.coefficients, b.vignetting.coefficients)
        np.testing.assert_array_equal(a.vignetting_map(), b.vignetting_map())
        assert b.response.method == {RESPONSE!r}
        np.testing.assert_array_equal(a.response.log_inverse_response, b.response.log_inverse_response)
        print("round trip ok")
        """,
        path=(plugin_site,),
    )
    assert check.returncode == 0, check.stderr
    assert check.stdout.strip() == "round trip ok"


def test_camera_of_a_missing_plugin_is_a_one_line_error_naming_the_method(
    plugin_site, capture, tmp_path
):
    cam = tmp_path / "camera"
    made = photoquant(
        "calibrate", str(capture), "-o", str(cam), "-q", "--method", f"response={RESPONSE}",
        path=(plugin_site,),
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    line = one_error_line(photoquant("info", str(cam)))
    assert RESPONSE in line and "plug-in" in line and "Debevec 1997" in line


def _fake_distribution(site: Path, name: str, entry_point: str, module: str) -> None:
    """Write an installed distribution by hand: a module and its ``.dist-info``."""
    module_name = entry_point.split("=")[1].strip().split(":")[0]
    (site / f"{module_name}.py").write_text(textwrap.dedent(module))
    info = site / f"{name.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[photoquant.methods]\n{entry_point}\n")


@pytest.mark.parametrize(
    "module",
    [
        # returns a Method under a built-in's exact name
        """
        import photoquant as pq
        def methods():
            return [pq.Method("response", "Debevec 1997", lambda stack, options, rng: None)]
        """,
        # registers one itself under a built-in's name in another case
        """
        import photoquant as pq
        def methods():
            pq.register_method("response", "debevec 1997", lambda stack, options, rng: None)
        """,
    ],
    ids=["returned", "registered"],
)
def test_plugin_name_taken_by_a_builtin_is_an_error_naming_both(tmp_path, capture, module):
    site = tmp_path / "site"
    site.mkdir()
    _fake_distribution(site, "clash-plugin", "clash = clash_plugin:methods", module)
    for args in (["methods"], ["calibrate", str(capture), "-o", str(tmp_path / "c"), "-q"]):
        line = one_error_line(photoquant(*args, path=(site,)))
        # the plug-in (entry point and distribution) and the built-in (name and module)
        assert "'clash'" in line and "clash-plugin" in line, line
        assert "'Debevec 1997'" in line and "photoquant.response" in line, line
    assert not (tmp_path / "c").exists()


def test_plugin_that_fails_to_import_is_a_one_line_error_naming_it(tmp_path, capture):
    site = tmp_path / "site"
    site.mkdir()
    _fake_distribution(
        site,
        "broken-plugin",
        "broken = broken_plugin:methods",
        "import photoquant_no_such_dependency\n\ndef methods():\n    return []\n",
    )
    for args in (["methods"], ["calibrate", str(capture), "-o", str(tmp_path / "c"), "-q"]):
        line = one_error_line(photoquant(*args, path=(site,)))
        assert "plug-in 'broken' (broken-plugin) failed to load" in line, line
        assert "photoquant_no_such_dependency" in line, line


def test_example_plugin_ranks_in_the_leaderboard(plugin_site, tmp_path):
    """Issue 8's "Done when": the plug-in's methods are ranked by the comparison command."""
    from tests._commands import commands_site

    site = commands_site(tmp_path / "commands")  # `leaderboard` if the install predates it
    args = ["leaderboard", "--quick", "--presets", "ccd", "--json", "-q"]
    args += ["--step", "response", "vignetting", "--methods"]
    # the plug-in's two methods against the paper's: every other entry is another test's
    ours = [RESPONSE, "Debevec 1997", VIGNETTING, "Extended Goldman-Chen"]
    result = photoquant(*args, *ours, path=(plugin_site, site))
    assert result.returncode == 0, result.stderr
    boards = {b["step"]: b for b in json.loads(result.stdout)["boards"]}
    ranked = {e["method"]: e for e in boards["response"]["entries"]}
    assert {RESPONSE, "Debevec 1997"} <= set(ranked)
    linear = ranked[RESPONSE]
    assert linear["status"] == "ok" and linear["reference"] == "example: an ideal linear sensor"
    # the ccd preset is linear: the example's g is exact, so it ranks first, above Debevec
    assert linear["scores"]["ccd"]["g_rms"] < 1e-9
    assert linear["rank"] == 1 < ranked["Debevec 1997"]["rank"]
    assert linear["scores"]["ccd"]["scene"] < 0.1 and linear["time_s"]["ccd"] > 0
    vignetting = {e["method"]: e for e in boards["vignetting"]["entries"]}
    radial = vignetting[VIGNETTING]
    assert radial["status"] == "ok" and radial["rank"] is not None
    assert radial["scores"]["ccd"]["vignetting"] < 0.03
    assert {e["method"] for e in boards["vignetting"]["entries"]} == {VIGNETTING, ours[3]}
    # without the plug-in, the board does not know its methods (refused before any work)
    plain = photoquant(*args, *ours, path=(site,))
    assert plain.returncode == 2
    assert f"unknown method {RESPONSE!r}" in one_error_line(plain)
