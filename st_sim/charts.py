"""Charts with axes, drawn with matplotlib: learning curves over seeds, scatter plots whose points carry their
intervals and labels that do not overlap, measured points against a reference curve with its band, measured against
reference values round the diagonal, and bars side by side.

Each chart function returns a ``matplotlib.figure.Figure`` (on its own Agg canvas: no pyplot state, no window)
with labelled axes and ticks; ``save_figure`` writes it as a PNG, atomically. matplotlib is an optional
dependency (``pip install -e ".[plots]"``, also pulled by the ``orca`` extra), imported when a chart is drawn,
with that fix in the error. OpenCV still draws predictions over scene photos (``st_sim.plot``); this module
draws everything that has axes.

    figure = learning_curves("env steps", [("success rate", {"ppo": [(steps, success)]})], title="PPO")
    save_figure(figure, "curves.png")
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from replays.atomic import atomic_path

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

DPI = 150  # pixels per inch of the written PNGs
PANEL_IN = (6.0, 3.2)  # width, height of one panel [inches]
MARKERS = "osD^v<>"  # marker of each measured series in ``band_chart``, in turn
LABEL_RINGS = (1, 2, 3, 4, 6, 8)  # candidate label positions lie on these rings, in multiples of the innermost
LABEL_OFFSETS_PT = [(dx * r, dy * r) for r in LABEL_RINGS for dx, dy in  # candidate label positions [points]
                    ((6, 6), (6, -10), (-6, 6), (-6, -10), (8, -2), (-8, -2), (0, 10), (0, -14))]

Run = tuple[np.ndarray, np.ndarray]
"""one run of a curve: x (T,) and y (T,), x increasing"""


@dataclass(frozen=True)
class ScatterPoint:
    """One labelled point of ``interval_scatter``, with its intervals (low, high) in data units, or None."""

    label: str
    x: float
    y: float
    x_interval: tuple[float, float] | None = None
    y_interval: tuple[float, float] | None = None


def new_figure(**kwargs: Any) -> Figure:
    """A matplotlib ``Figure`` on its own Agg canvas (no pyplot state, no window), laid out by constrained layout;
    ``kwargs`` go to ``Figure`` (``figsize`` in inches).

    Raises:
        ImportError: matplotlib is not installed; the message gives the command that installs it.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as err:
        raise ImportError('charts need matplotlib: `pip install -e ".[plots]"` (or `pip install matplotlib`)') from err
    figure = Figure(layout="constrained", **kwargs)
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, path: str | os.PathLike) -> Path:
    """Write ``figure`` as a PNG at ``path`` (folders made, temporary file then rename)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=DPI, format="png")
    return path


def learning_curves(x_label: str, panels: Sequence[tuple[str, Mapping[str, Sequence[Run]]]], title: str = "",
                    smooth_points: int = 9) -> Figure:
    """Curves against a shared x axis, one panel per quantity, one colour per series.

    A series with one run is drawn raw (faint) and smoothed; a series with several runs (seeds) is drawn as the
    mean of the smoothed runs, on the x values the runs share, with a band from their lowest to their highest.

    Args:
        x_label: label of the shared x axis, with its unit.
        panels: (y label with unit, {series label: runs}) per panel, top to bottom.
        title: figure title.
        smooth_points: width of the moving average, in points of a run.

    Raises:
        ValueError: a run's x and y differ in length, or a series has no run.
    """
    figure = new_figure(figsize=(PANEL_IN[0] * 1.4, PANEL_IN[1] * len(panels)))
    from matplotlib import rcParams
    from matplotlib.ticker import EngFormatter

    axes = figure.subplots(len(panels), 1, sharex=True, squeeze=False)
    colours = rcParams["axes.prop_cycle"].by_key()["color"]
    for row, (ax, (y_label, series)) in enumerate(zip(axes[:, 0], panels, strict=True)):
        for index, (label, runs) in enumerate(series.items()):
            _draw_runs(ax, label, runs, colours[index % len(colours)], smooth_points)
        ax.set_ylabel(y_label)
        ax.grid(alpha=0.3)
        if row == 0 and series:
            ax.legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel(x_label)
    axes[-1, 0].xaxis.set_major_formatter(EngFormatter(sep=""))  # 200k, 1M
    if title:
        figure.suptitle(title)
    return figure


def _draw_runs(ax: Axes, label: str, runs: Sequence[Run], colour: str, smooth_points: int) -> None:
    """One series of ``learning_curves``: raw and smoothed (one run) or mean and range band (several)."""
    if not runs:
        raise ValueError(f"learning_curves: series {label!r} has no run")
    for k, (x, y) in enumerate(runs):
        if len(x) != len(y):
            raise ValueError(f"learning_curves: series {label!r} run {k}: {len(x)} x values, {len(y)} y values")
    if len(runs) == 1:
        x, y = (np.asarray(v, np.float64) for v in runs[0])
        ax.plot(x, y, color=colour, alpha=0.25, linewidth=0.8)
        ax.plot(x, _smooth(y, smooth_points), color=colour, label=f"{label} (moving average of {smooth_points})")
        return
    start = max(float(np.min(x)) for x, _ in runs)
    end = min(float(np.max(x)) for x, _ in runs)
    grid = np.asarray(runs[0][0], np.float64)
    grid = grid[(grid >= start) & (grid <= end)]
    smoothed = np.array([_smooth(np.interp(grid, x, y), smooth_points) for x, y in runs])  # (R, T)
    ax.fill_between(grid, smoothed.min(axis=0), smoothed.max(axis=0), color=colour, alpha=0.2, linewidth=0)
    ax.plot(grid, smoothed.mean(axis=0), color=colour, label=f"{label} (mean of {len(runs)} runs, band: range)")


def _smooth(y: np.ndarray, points: int) -> np.ndarray:
    """Centred moving average over ``points`` values (edges repeat the end values)."""
    return uniform_filter1d(np.asarray(y, np.float64), size=max(1, min(points, len(y))), mode="nearest")


def interval_scatter(x_label: str, y_label: str, panels: Mapping[str, Sequence[ScatterPoint]],
                     title: str = "") -> Figure:
    """One scatter panel per entry of ``panels`` (panel title -> points): every point with its error bars and its
    label placed where it overlaps no other label, point or axis edge (when no place is free, the least crowded).

    Raises:
        ValueError: a panel has no point, or an interval does not contain its point.
    """
    figure = new_figure(figsize=(PANEL_IN[0] * len(panels), 4.8))
    axes = figure.subplots(1, len(panels), squeeze=False)
    for ax, (panel, points) in zip(axes[0], panels.items(), strict=True):
        if not points:
            raise ValueError(f"interval_scatter: panel {panel!r} has no point")
        for point in points:
            _check_interval(panel, point)
            x_err = None if point.x_interval is None else [[point.x - point.x_interval[0]],
                                                            [point.x_interval[1] - point.x]]
            y_err = None if point.y_interval is None else [[point.y - point.y_interval[0]],
                                                            [point.y_interval[1] - point.y]]
            ax.errorbar(point.x, point.y, xerr=x_err, yerr=y_err, fmt="o", color="tab:blue", ecolor="tab:gray",
                        elinewidth=1, capsize=3, markersize=5)
        ax.set_title(panel)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.grid(alpha=0.3)
        ax.margins(x=0.12, y=0.12)
    figure.canvas.draw()  # fixes the axes' limits, which the label placement works in
    for ax, points in zip(axes[0], panels.values(), strict=True):
        _place_labels(ax, points)
    if title:
        figure.suptitle(title)
    return figure


def _check_interval(panel: str, point: ScatterPoint) -> None:
    for axis, value, interval in (("x", point.x, point.x_interval), ("y", point.y, point.y_interval)):
        if interval is not None and not interval[0] <= value <= interval[1]:
            raise ValueError(f"interval_scatter: panel {panel!r}, point {point.label!r}: {axis} = {value} lies "
                             f"outside its interval {interval}")


def _place_labels(ax: Axes, points: Sequence[ScatterPoint]) -> None:
    """Annotate each point, with a leader line, at the first candidate offset whose text box covers no other label,
    marker or error bar and stays inside the axes (greedy, in display pixels; else the least covering one).
    Candidates go out ring by ring; within a ring, those facing away from the nearest other marker come first."""
    from matplotlib.text import Text

    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    centres = ax.transData.transform([[p.x, p.y] for p in points])  # (P, 2) display pixels
    taken = _obstacles(ax, points)
    for i in sorted(range(len(points)), key=lambda k: (points[k].x, points[k].y)):
        best, best_cost = None, np.inf
        for dx, dy in _candidates(centres[i], np.delete(centres, i, axis=0)):
            text = ax.annotate(points[i].label, (points[i].x, points[i].y), xytext=(dx, dy),
                               textcoords="offset points", ha="left" if dx >= 0 else "right",
                               va="bottom" if dy >= 0 else "top", fontsize="small", color="0.25",
                               arrowprops={"arrowstyle": "-", "color": "0.6", "shrinkA": 1, "shrinkB": 4})
            text.update_positions(renderer)  # applies the offset
            box = Text.get_window_extent(text, renderer)  # the text alone, without its leader line
            bounds = (box.x0, box.y0, box.x1, box.y1)
            outside = (max(0.0, frame.x0 - box.x0) + max(0.0, box.x1 - frame.x1) + max(0.0, frame.y0 - box.y0)
                       + max(0.0, box.y1 - frame.y1))
            cost = sum(_overlap(bounds, other) for other in taken) + outside * box.height
            if cost < best_cost:
                if best is not None:
                    best[0].remove()
                best, best_cost = (text, bounds), cost
            else:
                text.remove()
            if cost == 0:
                break
        taken.append(best[1])


def _obstacles(ax: Axes, points: Sequence[ScatterPoint], marker_px: float = 6.0) -> list[tuple[float, ...]]:
    """Boxes (x0, y0, x1, y1) in display pixels round every marker (half-size ``marker_px``) and error bar."""
    to_pixels = ax.transData.transform
    boxes = []
    for point in points:
        (x, y), = to_pixels([[point.x, point.y]])
        boxes.append((x - marker_px, y - marker_px, x + marker_px, y + marker_px))
        if point.x_interval is not None:
            (x0, _), (x1, _) = to_pixels([[point.x_interval[0], point.y], [point.x_interval[1], point.y]])
            boxes.append((x0, y - marker_px / 2, x1, y + marker_px / 2))
        if point.y_interval is not None:
            (_, y0), (_, y1) = to_pixels([[point.x, point.y_interval[0]], [point.x, point.y_interval[1]]])
            boxes.append((x - marker_px / 2, y0, x + marker_px / 2, y1))
    return boxes


def _candidates(centre: np.ndarray, others: np.ndarray) -> list[tuple[float, float]]:
    """Label offsets [points] for a marker at ``centre`` (display px), others at ``others`` (M, 2)."""
    if len(others) == 0:
        return LABEL_OFFSETS_PT
    away = centre - others[np.argmin(np.linalg.norm(others - centre, axis=1))]
    ring = len(LABEL_OFFSETS_PT) // len(LABEL_RINGS)
    rings = [LABEL_OFFSETS_PT[k:k + ring] for k in range(0, len(LABEL_OFFSETS_PT), ring)]
    return [offset for offsets in rings for offset in sorted(offsets, key=lambda o: -float(np.dot(o, away)))]


def _overlap(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Area shared by two boxes (x0, y0, x1, y1) [px^2]."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def band_chart(x_label: str, y_label: str, reference: tuple[str, np.ndarray, np.ndarray, np.ndarray],
               series: Mapping[str, tuple[np.ndarray, np.ndarray]], band_label: str, title: str = "") -> Figure:
    """Measured points of several models against a reference curve and its tolerance band.

    Args:
        x_label, y_label: axis labels with units.
        reference: (label, x (T,), y (T,), (2, T) band low and high) of the reference.
        series: model label -> (x (P,), y (P,)) measured points.
        band_label: legend text of the band.
        title: axes title.
    """
    figure = new_figure(figsize=(PANEL_IN[0] * 1.3, PANEL_IN[1] * 1.5))
    ax = figure.subplots()
    label, x, y, band = reference
    ax.fill_between(x, band[0], band[1], color="0.85", linewidth=0, label=band_label)
    ax.plot(x, y, color="black", linewidth=1.5, label=label)
    for index, (name, (px, py)) in enumerate(series.items()):
        ax.plot(px, py, marker=MARKERS[index % len(MARKERS)], linestyle="none", markersize=7, label=name)
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return figure


def identity_scatter(x_label: str, y_label: str, panels: Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray]]],
                     title: str = "") -> Figure:
    """Measured against reference values, one panel per entry of ``panels`` (panel title -> {series label: (x (P,),
    y (P,))}), with the line y = x: points on it match.

    Raises:
        ValueError: a series' x and y differ in length, or a panel has no point.
    """
    figure = new_figure(figsize=(PANEL_IN[0] * 0.8 * len(panels), PANEL_IN[0] * 0.8))
    axes = figure.subplots(1, len(panels), squeeze=False)
    for ax, (panel, series) in zip(axes[0], panels.items(), strict=True):
        values = [np.asarray(v, np.float64) for xy in series.values() for v in xy]
        if not any(len(v) for v in values):
            raise ValueError(f"identity_scatter: panel {panel!r} has no point")
        for index, (label, (x, y)) in enumerate(series.items()):
            if len(x) != len(y):
                raise ValueError(f"identity_scatter: panel {panel!r}, series {label!r}: {len(x)} x, {len(y)} y")
            ax.plot(x, y, marker=MARKERS[index % len(MARKERS)], linestyle="none", markersize=4, alpha=0.6,
                    label=f"{label} ({len(x)})")
        low, high = min(float(v.min()) for v in values if len(v)), max(float(v.max()) for v in values if len(v))
        ax.plot([low, high], [low, high], color="black", linewidth=1, label="y = x")
        ax.set_title(panel)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


def grouped_bars(y_label: str, panels: Mapping[str, tuple[Sequence[str], Mapping[str, Sequence[float]]]],
                 title: str = "") -> Figure:
    """Bars side by side, one panel per entry of ``panels`` (panel title -> (category labels (C,), {series label:
    values (C,)})), each series a colour, its value written over each bar.

    Raises:
        ValueError: a series has not one value per category, or a panel has no category.
    """
    figure = new_figure(figsize=(PANEL_IN[0] * 1.2, PANEL_IN[1] * 1.1 * len(panels)))
    axes = figure.subplots(len(panels), 1, squeeze=False)
    for ax, (panel, (categories, series)) in zip(axes[:, 0], panels.items(), strict=True):
        if not categories:
            raise ValueError(f"grouped_bars: panel {panel!r} has no category")
        width = 0.8 / max(len(series), 1)
        for index, (label, values) in enumerate(series.items()):
            if len(values) != len(categories):
                raise ValueError(f"grouped_bars: panel {panel!r}, series {label!r}: {len(values)} values for "
                                 f"{len(categories)} categories")
            x = np.arange(len(categories)) + (index - (len(series) - 1) / 2) * width
            bars = ax.bar(x, values, width, label=label)
            ax.bar_label(bars, fmt="%.2f", fontsize="x-small")
        ax.set_xticks(np.arange(len(categories)), categories, rotation=20, ha="right", fontsize="small")
        ax.set_ylabel(y_label)
        ax.set_title(panel)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(loc="best", fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


def small_multiples(x_label: str, y_label: str, panels: Mapping[str, Sequence[ScatterPoint]], columns: int = 6,
                    limits: tuple[float, float] = (0.0, 1.0), title: str = "") -> Figure:
    """One small panel per entry of ``panels`` (panel title -> points), ``columns`` to a row, all on the same axes
    ``limits``: each point with its error bars, coloured and marked by its label (the series), named once in a
    shared legend.

    Raises:
        ValueError: a panel has no point, or an interval does not contain its point.
    """
    series = list(dict.fromkeys(point.label for points in panels.values() for point in points))
    colours = _series_colours(len(series))
    rows = -(-len(panels) // columns)
    figure = new_figure(figsize=(2.6 * columns, 2.4 * rows + 1.2))
    axes = figure.subplots(rows, columns, squeeze=False, sharex=True, sharey=True)
    pad = 0.05 * (limits[1] - limits[0])
    for ax, (panel, points) in zip(axes.ravel(), panels.items(), strict=False):
        if not points:
            raise ValueError(f"small_multiples: panel {panel!r} has no point")
        for point in points:
            _check_interval(panel, point)
            k = series.index(point.label)
            x_err = None if point.x_interval is None else [[point.x - point.x_interval[0]],
                                                            [point.x_interval[1] - point.x]]
            y_err = None if point.y_interval is None else [[point.y - point.y_interval[0]],
                                                            [point.y_interval[1] - point.y]]
            ax.errorbar(point.x, point.y, xerr=x_err, yerr=y_err, fmt=MARKERS[k % len(MARKERS)], color=colours[k],
                        ecolor=colours[k], elinewidth=0.6, capsize=0, markersize=4, alpha=0.85)
        ax.set_title(panel, fontsize="small")
        ax.set_xlim(limits[0] - pad, limits[1] + pad)
        ax.set_ylim(limits[0] - pad, limits[1] + pad)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(x_label, fontsize="small")
    for ax in axes[:, 0]:
        ax.set_ylabel(y_label, fontsize="small")
    handles = [axes[0, 0].errorbar([], [], fmt=MARKERS[k % len(MARKERS)], color=colours[k], label=name)
               for k, name in enumerate(series)]
    figure.legend(handles=handles, loc="outside lower center", ncols=min(len(series), 5), fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


def _series_colours(count: int) -> list[tuple[float, ...]]:
    """``count`` distinguishable colours (matplotlib's tab10, then tab20's lighter shades)."""
    from matplotlib import colormaps

    palette = list(colormaps["tab10"].colors) + list(colormaps["tab20"].colors[1::2])
    return [palette[k % len(palette)] for k in range(count)]
