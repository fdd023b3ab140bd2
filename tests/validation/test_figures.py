"""The report's figures: drawn in memory they are the bytes of the file; a run draws its
own while it waits and stops when told; the report writes what was drawn as it is."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from validation.config import QUICK  # noqa: E402
from validation.experiments import ValidationRun  # noqa: E402
from validation.experiments.base import ExperimentResult, FigureSpec  # noqa: E402
from validation.figures import draw_figure, draw_while, figure_png  # noqa: E402
from validation.report import write_report  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _maps(name: str, seed: int) -> FigureSpec:
    image = np.random.default_rng(seed).random((12, 16))
    panel = {"title": "t", "image": image, "vmin": 0.0, "vmax": 1.0}
    return FigureSpec(name, "maps", name.upper(), "", {"panels": [panel]})


def test_a_figure_drawn_in_memory_is_the_file_drawn(tmp_path):
    spec = _maps("a", 0)
    path = draw_figure(spec, tmp_path / "a.png")
    assert path is not None
    png = figure_png(spec)
    assert png.startswith(PNG_SIGNATURE)
    assert png == path.read_bytes()
    assert png != figure_png(_maps("a", 1))  # another image, other bytes


def test_draw_while_stops_when_told_and_goes_on_where_it_stopped():
    results = [ExperimentResult("x", "X", ""), ExperimentResult("y", "Y", "")]
    results[0].figures += [_maps("a", 0), _maps("b", 1)]
    results[1].figures += [_maps("c", 2)]
    answers = iter([True, True, False])
    assert draw_while(results, lambda: next(answers)) == 2
    assert [sorted(res.drawn) for res in results] == [["a", "b"], []]
    first = results[0].drawn["a"]
    assert first == figure_png(results[0].figures[0])
    assert draw_while(results, lambda: True) == 1  # the one left, not the drawn ones again
    assert results[0].drawn["a"] is first
    assert [sorted(res.drawn) for res in results] == [["a", "b"], ["c"]]


def test_a_figure_that_fails_to_draw_ends_the_drawing_and_is_left_to_the_report():
    res = ExperimentResult("x", "X", "")
    broken = FigureSpec("broken", "no such kind", "B", "", {})
    res.figures += [_maps("a", 0), broken, _maps("c", 2)]
    assert draw_while([res], lambda: True) == 1
    assert sorted(res.drawn) == ["a"]


def test_the_report_writes_a_drawn_figure_as_it_is_and_draws_the_others(tmp_path):
    res = ExperimentResult("response", "Response", "")
    drawn, left = _maps("drawn", 0), _maps("left", 1)
    res.figures += [drawn, left]
    res.drawn["drawn"] = b"the bytes the run drew"
    run = ValidationRun(config=QUICK, seed=0, experiments={"response": res}, seeds={})
    folder = write_report(run, tmp_path / "report")
    assert (folder / "figures" / "drawn.png").read_bytes() == b"the bytes the run drew"
    assert (folder / "figures" / "left.png").read_bytes() == figure_png(left)
    assert res.figure_paths == ["figures/drawn.png", "figures/left.png"]
