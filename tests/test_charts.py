"""Charts have labelled axes with ticks, carry every point's interval, keep labels apart and write whole PNGs."""

from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.collections import PolyCollection
from matplotlib.text import Annotation, Text

from st_sim import charts
from st_sim.charts import ScatterPoint, band_chart, grouped_bars, interval_scatter, learning_curves, save_figure

STUDY = Path(__file__).resolve().parents[1] / "results" / "study" / "study.json"


def label_boxes(figure) -> list[tuple[str, tuple[float, float, float, float]]]:
    """(text, display box) of every point label in the figure, as drawn."""
    renderer = figure.canvas.get_renderer()
    boxes = []
    for ax in figure.axes:
        for text in (child for child in ax.get_children() if isinstance(child, Annotation)):
            text.update_positions(renderer)
            box = Text.get_window_extent(text, renderer)
            boxes.append((text.get_text(), (box.x0, box.y0, box.x1, box.y1)))
    return boxes


def overlapping(boxes) -> list[tuple[str, str]]:
    return [(a, b) for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2)
            if min(box_a[2], box_b[2]) > max(box_a[0], box_b[0]) and min(box_a[3], box_b[3]) > max(box_a[1], box_b[1])]


def assert_axes_readable(ax, x_label: str, y_label: str, shares_x: bool = False) -> None:
    """Axis labels as given and at least three tick labels on each axis (on y only if it shares x with the panel
    below, which carries the x ticks)."""
    ax.figure.canvas.draw()
    assert (ax.get_xlabel(), ax.get_ylabel()) == (x_label, y_label)
    for axis in (ax.yaxis,) if shares_x else (ax.xaxis, ax.yaxis):
        ticks = [tick.get_text() for tick in axis.get_ticklabels() if tick.get_visible() and tick.get_text()]
        assert len(ticks) >= 3, f"{axis.axis_name} axis has {ticks} as tick labels"


def test_learning_curves_of_several_runs_draw_their_mean_and_range() -> None:
    x = np.arange(0, 1000, 10.0)
    runs = [(x, np.sin(x / 100) + offset) for offset in (0.0, 0.5, 1.0)]
    figure = learning_curves("env steps", [("success rate", {"seeds": runs}), ("return", {"one": [runs[0]]})])
    top, bottom = figure.axes
    band = [child for child in top.get_children() if isinstance(child, PolyCollection)]
    assert len(band) == 1, "one range band for the three runs"
    (mean_line,) = top.get_lines()
    raw, smoothed = bottom.get_lines()  # a single run is drawn raw and smoothed
    np.testing.assert_allclose(raw.get_ydata(), runs[0][1])
    np.testing.assert_allclose(mean_line.get_ydata(), smoothed.get_ydata() + 0.5, err_msg="mean of the runs")
    inside = slice(5, -5)  # beyond half the moving average's width from the ends
    assert np.abs(smoothed.get_ydata() - raw.get_ydata())[inside].max() < 0.05, "smoothing a smooth curve moved it"
    extent = band[0].get_paths()[0].vertices[:, 1]
    assert extent.min() < mean_line.get_ydata().min() - 0.4 and extent.max() > mean_line.get_ydata().max() + 0.4
    assert_axes_readable(bottom, "env steps", "return")
    assert_axes_readable(top, "", "success rate", shares_x=True)


def test_learning_curves_refuse_a_ragged_run() -> None:
    with pytest.raises(ValueError, match="run 0: 3 x values, 2 y values"):
        learning_curves("steps", [("y", {"bad": [(np.arange(3.0), np.arange(2.0))]})])


def study_panels() -> dict[str, list[ScatterPoint]]:
    """The committed study's points (rates in %), the crowded case the issue showed overlapping."""
    study = json.loads(STUDY.read_text())
    return {part["env"]: [ScatterPoint(r["predictor"], r["fde"], 100 * r["collision_at_fault"],
                                       y_interval=(0.0, 100 * r["collision_at_fault"] + 2)) for r in part["rows"]]
            for part in study["study"]}


def test_interval_scatter_of_the_study_keeps_labels_apart_and_draws_intervals() -> None:
    panels = study_panels()
    figure = interval_scatter("FDE [m]", "at-fault collisions [%]", panels)
    boxes = label_boxes(figure)
    assert sorted(text for text, _ in boxes) == sorted(p.label for points in panels.values() for p in points)
    assert overlapping(boxes) == []
    for ax, points in zip(figure.axes, panels.values(), strict=True):
        bars = [line for line in ax.get_children() if type(line).__name__ == "LineCollection"]
        assert len(bars) == len(points), "one error bar per point"
        assert_axes_readable(ax, "FDE [m]", "at-fault collisions [%]")


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 1), st.floats(0, 1)), min_size=1, max_size=8))
def test_interval_scatter_labels_never_overlap(xy: list[tuple[float, float]]) -> None:
    points = [ScatterPoint(f"predictor-{k}", x, y) for k, (x, y) in enumerate(xy)]
    assert overlapping(label_boxes(interval_scatter("x", "y", {"panel": points}))) == []


def test_interval_scatter_refuses_an_interval_that_misses_its_point() -> None:
    with pytest.raises(ValueError, match=r"'cvm': y = 3\.0 lies outside its interval"):
        interval_scatter("x", "y", {"zara1": [ScatterPoint("cvm", 1.0, 3.0, y_interval=(0.0, 2.0))]})


def test_band_chart_draws_the_band_the_reference_and_every_series() -> None:
    x = np.linspace(0.0, 5.0, 50)
    figure = band_chart("density [1/m²]", "speed [m/s]", ("reference", x, 1.3 - 0.2 * x, np.stack([x * 0, x + 1])),
                        {"model a": (np.array([1.0, 2.0]), np.array([1.0, 0.8])), "model b": (np.ones(1), np.ones(1))},
                        band_label="±20 %")
    (ax,) = figure.axes
    assert [line.get_label() for line in ax.get_lines()] == ["reference", "model a", "model b"]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["±20 %", "reference", "model a", "model b"]
    assert_axes_readable(ax, "density [1/m²]", "speed [m/s]")


def test_save_figure_writes_a_whole_png(tmp_path: Path) -> None:
    figure = learning_curves("x", [("y", {"a": [(np.arange(5.0), np.arange(5.0))]})])
    out = save_figure(figure, tmp_path / "a" / "c.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and list(out.parent.iterdir()) == [out]


def test_missing_matplotlib_gives_the_install_command(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [name for name in sys.modules if name.split(".")[0] == "matplotlib"]:
        monkeypatch.setitem(sys.modules, name, None)  # makes `import matplotlib...` fail
    with pytest.raises(ImportError, match=r'pip install -e "\.\[plots\]"'):
        charts.new_figure()


def test_grouped_bars_draws_every_series_in_every_panel_and_refuses_a_short_series() -> None:
    figure = grouped_bars("score", {"realism": (["speed", "meta"], {"blind": [0.2, 0.5], "reactive": [0.3, 0.6]}),
                                    "folds": (["a", "b", "c"], {"blind": [1.0, 0.9, 0.8]})})
    top, bottom = figure.axes
    assert [t.get_text() for t in top.get_legend().get_texts()] == ["blind", "reactive"]
    assert [round(bar.get_height(), 2) for bar in top.patches] == [0.2, 0.5, 0.3, 0.6] and len(bottom.patches) == 3
    assert [t.get_text() for t in bottom.get_xticklabels()] == ["a", "b", "c"]
    with pytest.raises(ValueError, match="'folds', series 'blind': 2 values for 3 categories"):
        grouped_bars("", {"folds": (["a", "b", "c"], {"blind": [1.0, 0.9]})})
    with pytest.raises(ValueError, match="panel 'empty' has no category"):
        grouped_bars("", {"empty": ([], {})})
