"""Table 1's Hugin row (validation.experiments.table1): built from Hugin's own calibration."""

from __future__ import annotations

import pytest

from photoquant.peers import hugin
from validation.config import TINY
from validation.experiments import run_validation
from validation.experiments import table1 as table1_module


def _quiet(_message: str) -> None:
    pass


def _hugin_rows(res):
    return [r for r in res.rows if r.quantity.startswith("r, Hugin")]


def test_table1_has_a_hugin_row_from_vig_optimize():
    if not hugin.available():
        pytest.skip(f"peer not installed: needs {hugin.REQUIREMENT}")
    run = run_validation(TINY, 0, experiments=["table1"], progress=_quiet)
    res = run.experiments["table1"]
    rows = _hugin_rows(res)
    assert len(rows) == 2  # vs CIE RGB and vs the camera photoquantity
    assert all("missing" not in r.ours and "not installed" not in r.ours for r in rows)
    m = run.metrics
    for col in ("ccd.outdoor", "ccd.indoor", "cmos.outdoor", "cmos.indoor"):
        # Hugin's calibration linearises: far better than the LDR frame, near ours
        assert m[f"table1.{col}.hugin.r_camera"] > m[f"table1.{col}.uncorrected.r_camera"]
        assert m[f"table1.{col}.hugin.r_camera"] > 0.99
        assert 0 < m[f"table1.{col}.hugin.e_mean"] < 0.05
    assert any("vig_optimize" in note for note in res.notes)


def test_table1_says_what_to_install_without_hugin(monkeypatch):
    monkeypatch.setattr(hugin, "available", lambda: False)
    run = run_validation(TINY, 0, experiments=["table1"], progress=_quiet)
    res = run.experiments["table1"]
    rows = _hugin_rows(res)
    assert rows and all(r.ours == "not installed" for r in rows)
    assert table1_module.NO_HUGIN in res.notes
    assert not any(k.split(".")[3] == "hugin" for k in run.metrics if k.startswith("table1."))


def test_table1_and_fig7_have_a_row_per_pipeline_and_fig7_a_hugin_row():
    """Issue 11: "Table 1 and Fig. 7 get the Hugin row from the real Hugin, and a row per pipeline"."""
    from photoquant.profiles import DEFAULT_PROFILE, PROFILES

    run = run_validation(TINY, 0, experiments=["table1", "fig7"], progress=_quiet)
    m = run.metrics
    others = [p for p in PROFILES if p != DEFAULT_PROFILE]
    assert others  # the paper's own profile at least
    keys = [f"profile_{p}" for p in others] + (["hugin"] if hugin.available() else [])
    for col in ("ccd.outdoor", "ccd.indoor", "cmos.outdoor", "cmos.indoor"):
        for key in keys:
            # every pipeline linearises the camera: its chart correlates with the truth
            # better than the clipped, non-linear LDR frame does
            assert m[f"table1.{col}.{key}.r_camera"] > m[f"table1.{col}.uncorrected.r_camera"]
            assert 0 < m[f"table1.{col}.{key}.e_mean"] < 0.1
            for gt in ("cie", "camera"):
                # Fig. 7's regression of the same pipeline's chart: a line through the
                # points with a smaller residual than the LDR frame's
                fit = f"fig7.{col}.{key}.{gt}"
                assert m[f"{fit}.residual_norm"] < m[f"fig7.{col}.uncorrected.{gt}.residual_norm"]
                assert m[f"{fit}.slope"] > 0
    for p in others:
        rows = [r for r in run.experiments["table1"].rows if f"({p} profile)" in r.quantity]
        assert len(rows) == 2
        rows = [r for r in run.experiments["fig7"].rows if f"({p} profile)" in r.quantity]
        assert len(rows) == 2 * 4  # both ground truths, four columns
    if hugin.available():
        rows = [r for r in run.experiments["fig7"].rows if ", Hugin vs" in r.quantity]
        assert len(rows) == 2 * 4
