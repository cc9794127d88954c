"""A plot drawn with Unicode braille characters (2 x 4 dots per cell), as a rich renderable.

Layers (the θ trace, the band edges, the signature level) are rasterised separately into dot
grids; a cell shows the union of the dots of all layers in the colour of the topmost layer
that has a dot in it, so a trace crossing a band line stays visible. The plot fills whatever
width and height rich gives it; y labels sit in a left gutter.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from rich.console import Console, ConsoleOptions, RenderResult
from rich.segment import Segment
from rich.style import Style
from rich.text import Text

#: bit of the braille dot at [column 0..1, row 0..3] of a cell, Unicode order
_DOT_BITS = np.array([[0x01, 0x02, 0x04, 0x40], [0x08, 0x10, 0x20, 0x80]], dtype=np.uint8)
#: cell character for each bit pattern (no dot: a space)
_CELL_CHARS = np.array([" "] + [chr(0x2800 + bits) for bits in range(1, 256)], dtype=object)
_GUTTER = 8

Run = tuple[str, str]  # (text, style) of one stretch of a line


@dataclass
class Series:
    """One layer of the plot: a polyline (t, y) or a horizontal level (``level`` set).

    `t` is the horizontal coordinate: time in a time plot, θ1 in the θ plane. Points with a
    non-finite coordinate break the polyline."""

    style: str
    t: Sequence[float] = ()
    y: Sequence[float] = ()
    level: float | None = None
    dashed: bool = False


@dataclass
class BraillePlot:
    """Plot of `series` (last layer drawn on top) with y labels in a left gutter.

    `y_range` fixes the vertical scale; otherwise it covers every finite value of every layer.
    `x_range` fixes the horizontal one; otherwise it spans the polylines' `t`.
    `empty_text` is shown when no layer has a finite point.
    """

    series: list[Series] = field(default_factory=list)
    y_range: tuple[float, float] | None = None
    x_range: tuple[float, float] | None = None
    empty_text: str = "no data yet"
    label_style: str = "dim"

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        styles: dict[str, Style] = {}
        for row in plot_runs(self, options.max_width, options.height or 6):
            for text, style in row:
                if style not in styles:
                    styles[style] = console.get_style(style) if style else Style.null()
                yield Segment(text, styles[style])
            yield Segment.line()


def data_range(series: Sequence[Series]) -> tuple[float, float] | None:
    """The finite min and max of y over every layer, or None when there is no finite value."""
    values = [
        v
        for s in series
        for v in (s.y if s.level is None else (s.level,))
        if v is not None and math.isfinite(v)
    ]
    if not values:
        return None
    return min(values), max(values)


def padded_range(lo: float, hi: float, fraction: float = 0.08) -> tuple[float, float]:
    """Widen [lo, hi] by `fraction` of its span on each side (a flat range gets a span)."""
    span = hi - lo
    if span <= 0.0:
        span = max(abs(lo) * 0.2, 1e-6)
        return lo - span / 2, hi + span / 2
    return lo - span * fraction, hi + span * fraction


def format_tick(value: float) -> str:
    """A y-axis label of at most 7 characters."""
    text = f"{value:.3g}"
    if len(text) > 7:
        text = f"{value:.1e}"
    return text


def render_lines(plot: BraillePlot, width: int, height: int) -> list[Text]:
    """The plot as `height` Text lines of `width` cells each."""
    lines = []
    for row in plot_runs(plot, width, height):
        line = Text()
        for text, style in row:
            line.append(text, style=style or None)
        lines.append(line)
    return lines


def plot_runs(plot: BraillePlot, width: int, height: int) -> list[list[Run]]:
    """The plot as `height` rows of (text, style) runs covering `width` cells."""
    height = max(height, 1)
    gutter = _GUTTER if width >= 3 * _GUTTER else 0
    cols = max(width - gutter, 1)
    finite = data_range(plot.series)
    if finite is None:
        rows: list[list[Run]] = [[(" " * width, "")] for _ in range(height)]
        rows[height // 2] = [(plot.empty_text.center(width)[:width], "dim")]
        return rows
    y_lo, y_hi = plot.y_range if plot.y_range is not None else padded_range(*finite)
    if plot.x_range is not None:
        t_lo, t_hi = plot.x_range
    else:
        t_all = [t for s in plot.series if s.level is None for t in s.t if math.isfinite(t)]
        t_lo, t_hi = (min(t_all), max(t_all)) if t_all else (0.0, 1.0)
    if t_hi <= t_lo:
        t_hi = t_lo + 1.0
    grid = np.zeros((height, cols), dtype=np.uint8)
    top = np.full((height, cols), -1, dtype=np.int16)  # index of the topmost layer per cell
    for index, series in enumerate(plot.series):
        layer = _rasterise(series, (t_lo, t_hi), (y_lo, y_hi), cols, height)
        grid |= layer
        top[layer > 0] = index
    styles = [s.style for s in plot.series]
    labels = {0: format_tick(y_hi), height - 1: format_tick(y_lo)}
    if height >= 5:
        labels[(height - 1) // 2] = format_tick((y_hi + y_lo) / 2)
    rows = []
    for r in range(height):
        row: list[Run] = []
        if gutter:
            row.append(
                (
                    labels[r].rjust(gutter - 1) + "┤" if r in labels else " " * (gutter - 1) + "│",
                    plot.label_style,
                )
            )
        chars = _CELL_CHARS[grid[r]]
        edges = np.flatnonzero(np.diff(top[r])) + 1
        for a, b in zip(np.r_[0, edges], np.r_[edges, cols]):
            layer = top[r, a]
            row.append(("".join(chars[a:b]), styles[layer] if layer >= 0 else ""))
        rows.append(row)
    return rows


def _rasterise(
    series: Series, t_range: tuple[float, float], y_range: tuple[float, float], cols: int, rows: int
) -> np.ndarray:
    """Braille bits per cell (rows x cols) of one layer."""
    dots_x, dots_y = cols * 2, rows * 4
    (t_lo, t_hi), (y_lo, y_hi) = t_range, y_range
    y_scale = (dots_y - 1) / (y_hi - y_lo)
    grid = np.zeros((rows, cols), dtype=np.uint8)
    if series.level is not None:
        if math.isfinite(series.level) and y_lo <= series.level <= y_hi:
            row = int(round((y_hi - series.level) * y_scale))
            bits = _DOT_BITS[0, row & 3] | _DOT_BITS[1, row & 3]
            grid[row >> 2, :: 2 if series.dashed else 1] = bits
        return grid
    t = np.asarray(series.t, dtype=float)
    y = np.asarray(series.y, dtype=float)
    n = min(t.size, y.size)
    t, y = t[:n], y[:n]
    ok = np.isfinite(t) & np.isfinite(y)
    x_dot = (t - t_lo) * ((dots_x - 1) / (t_hi - t_lo))
    y_dot = (y_hi - np.clip(y, y_lo, y_hi)) * y_scale
    xs, ys = [x_dot[ok]], [y_dot[ok]]
    joined = ok[:-1] & ok[1:]  # draw the segment between two neighbouring finite points
    if joined.any():
        x0, x1 = x_dot[:-1][joined], x_dot[1:][joined]
        y0, y1 = y_dot[:-1][joined], y_dot[1:][joined]
        steps = np.ceil(np.maximum(np.abs(x1 - x0), np.abs(y1 - y0))).astype(int) + 1
        segment = np.repeat(np.arange(steps.size), steps)
        offset = np.arange(steps.sum()) - np.repeat(np.cumsum(steps) - steps, steps)
        fraction = offset / np.maximum(steps - 1, 1)[segment]
        xs.append(x0[segment] + (x1 - x0)[segment] * fraction)
        ys.append(y0[segment] + (y1 - y0)[segment] * fraction)
    x_all = np.rint(np.concatenate(xs)).astype(int)
    y_all = np.rint(np.concatenate(ys)).astype(int)
    inside = (x_all >= 0) & (x_all < dots_x) & (y_all >= 0) & (y_all < dots_y)
    x_all, y_all = x_all[inside], y_all[inside]
    np.bitwise_or.at(grid, (y_all >> 2, x_all >> 1), _DOT_BITS[x_all & 1, y_all & 3])
    return grid
