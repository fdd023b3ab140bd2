"""The leaderboard's cameras beyond the presets (EMoR draws, film) and its plots (issue 11)."""

from __future__ import annotations

import numpy as np
import pytest

from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.responses import ResponseCurve
from validation.config import FULL, QUICK, TINY
from validation.experiments.leaderboard import EXTRA_CAMERAS, extra_cameras_for
from validation.leaderboard import DEFAULT_CAMERAS, run_leaderboard, write_report
from validation.plots import aligned_response

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_default_cameras_include_emor_draws_and_film() -> None:
    assert DEFAULT_CAMERAS[:2] == ("ccd", "cmos")
    emor = [c for c in DEFAULT_CAMERAS if c.startswith("emor")]
    assert len(emor) >= 2 and "film" in DEFAULT_CAMERAS
    drawn = [camera_from_preset(c).responses for c in emor]
    assert all(r.kind == "emor" for rs in drawn for r in rs)
    assert drawn[0] != drawn[1]  # different draws
    assert extra_cameras_for(QUICK) == () and extra_cameras_for(FULL) == EXTRA_CAMERAS


def test_aligned_response_removes_the_free_constant() -> None:
    g_true = np.log(np.linspace(0.01, 1.0, 50))
    w = np.ones(50)
    g, mask = aligned_response(g_true + 3.25, g_true, w)
    np.testing.assert_allclose(g, g_true, atol=1e-12)
    assert mask.all()
    g_true[0] = -np.inf
    _, mask = aligned_response(g_true + 1, g_true, w)
    assert not mask[0] and mask[1:].all()


@pytest.mark.slow
def test_standalone_board_ranks_on_the_emor_and_film_cameras(tmp_path) -> None:
    lb = run_leaderboard(
        "response",
        methods=["Debevec 1997"],
        config=TINY,
        repeats=1,
        workdir=tmp_path / "work",
        progress=lambda _m: None,
    )
    assert lb.presets == DEFAULT_CAMERAS
    entry = lb.board("response").entry("Debevec 1997")
    assert entry.status == "ok" and set(entry.scores) == set(DEFAULT_CAMERAS)
    # the board's truth on the "emor" camera is the EMoR draw of seed = channel:
    # g = ln(full_well / exposure_scale · F⁻¹(c / (a c_max))), computed here
    cam = camera_from_preset("emor")
    curves = entry.curves["emor"]
    levels = curves["levels"]
    for ch in range(3):
        top = int(np.floor(cam.balance[ch] * cam.c_max))
        c = levels[1:top]
        F = ResponseCurve.emor(seed=ch)
        want = np.log(
            cam.noise.full_well_e
            / cam.exposure_scale
            * F.inverse(c / (cam.balance[ch] * cam.c_max))
        )
        np.testing.assert_allclose(curves["g_true"][ch][1:top], want, rtol=0, atol=1e-9)
    # Debevec on 8-bit data with N = 4: g within a few hundredths in ln (quantisation)
    assert all(s["g_rms"] < 0.1 for s in entry.scores.values())
    out = write_report(lb, tmp_path / "report")
    md = (out / "leaderboard.md").read_text()
    for name in ("response_curves.png", "error_vs_time.png"):
        assert (out / name).read_bytes().startswith(PNG_SIGNATURE)
        assert f"({name})" in md
