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
