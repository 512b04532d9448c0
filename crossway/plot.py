"""Learning curves as PNG, drawn with cairo (no plotting library needed).

``plot_curves`` draws one or more series of (x, y) points on shared axes with a legend; the
``crossway plot`` command reads ``progress.csv`` files written by ``crossway train``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cairo

COLOURS = [(0.12, 0.47, 0.71), (0.84, 0.15, 0.16), (0.17, 0.63, 0.17), (1.0, 0.5, 0.05), (0.58, 0.40, 0.74)]


def read_progress(path: Path, x: str, y: str, where: dict[str, str] | None = None) -> tuple[list[float], list[float]]:
    """Two columns of a CSV (a progress.csv, or a Table I ``table1-S-tests.csv``), keeping only the
    rows whose ``where`` columns hold the given values (``{"sign": "stop"}``); a clear error names a
    missing column, or says that no row matched."""
    where = where or {}
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        for column in (x, y, *where):
            if column not in (reader.fieldnames or []):
                raise ValueError(f"{path}: no column {column!r} (columns: {reader.fieldnames})")
        xs, ys = [], []
        for row in reader:
            if all(row[column] == value for column, value in where.items()):
                xs.append(float(row[x]))
                ys.append(float(row[y]))
    if not xs:
        matching = " matching " + ", ".join(f"{c}={v}" for c, v in where.items()) if where else ""
        raise ValueError(f"{path}: no rows{matching}")
    return xs, ys


def _nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    span = max(high - low, 1e-12)
    step = 10 ** math.floor(math.log10(span / count))
    for factor in (1, 2, 5, 10):
        if span / (step * factor) <= count:
            step *= factor
            break
    first = math.ceil(low / step) * step
    # the small slack keeps a tick at ``high`` itself that rounding would drop ((1 - 0.85) / 0.05 < 3)
    return [first + i * step for i in range(int((high - first) / step + 1e-9) + 1)]


def _label(value: float) -> str:
    if abs(value) >= 1e6:
        return f"{value / 1e6:g}M"
    if abs(value) >= 1e3:
        return f"{value / 1e3:g}k"
    return f"{value:g}"


def plot_curves(series: list[tuple[str, list[float], list[float]]], out: Path, title: str, x_label: str,
                y_label: str, y_range: tuple[float, float] | None = None, width: int = 800,
                height: int = 480, styles: list[tuple[int, bool]] | None = None, markers: bool = False,
                x_range: tuple[float, float] | None = None) -> Path:
    """Curves of (name, xs, ys) on shared axes, written as a PNG; ``styles`` gives each series a
    (colour index, dashed) pair (default: colours in order, solid lines); ``markers`` also draws a
    dot at every point of the solid series (a few measured points, such as Table I's tests, rather
    than a curve); ``x_range`` sets the x axis limits (default: the data's range)."""
    if styles is None:
        styles = [(i, False) for i in range(len(series))]
    if len(styles) != len(series):
        raise ValueError(f"{len(styles)} styles for {len(series)} series")
    surface = cairo.ImageSurface(cairo.FORMAT_RGB24, width, height)
    ctx = cairo.Context(surface)
    ctx.set_source_rgb(1, 1, 1)
    ctx.paint()
    legend_rows = len(series)
    left, right, top, bottom = 80, 20, 50, 60 + 18 * legend_rows  # the legend sits under the axis label
    all_x = [v for _, xs, _ in series for v in xs]
    all_y = [v for _, _, ys in series for v in ys]
    x0, x1 = x_range if x_range else (min(all_x), max(all_x))
    y0, y1 = y_range if y_range else (min(all_y), max(all_y))
    x1 = x1 if x1 > x0 else x0 + 1
    y1 = y1 if y1 > y0 else y0 + 1

    def px(x: float) -> float:
        return left + (x - x0) / (x1 - x0) * (width - left - right)

    def py(y: float) -> float:
        return height - bottom - (y - y0) / (y1 - y0) * (height - top - bottom)

    ctx.select_font_face("sans-serif")
    ctx.set_font_size(12)
    ctx.set_line_width(1)
    for tick in _nice_ticks(x0, x1):
        ctx.set_source_rgb(0.9, 0.9, 0.9)
        ctx.move_to(px(tick), top)
        ctx.line_to(px(tick), height - bottom)
        ctx.stroke()
        ctx.set_source_rgb(0.2, 0.2, 0.2)
        text = _label(tick)
        ctx.move_to(px(tick) - ctx.text_extents(text).width / 2, height - bottom + 18)
        ctx.show_text(text)
    for tick in _nice_ticks(y0, y1):
        ctx.set_source_rgb(0.9, 0.9, 0.9)
        ctx.move_to(left, py(tick))
        ctx.line_to(width - right, py(tick))
        ctx.stroke()
        ctx.set_source_rgb(0.2, 0.2, 0.2)
        text = _label(tick)
        ctx.move_to(left - 8 - ctx.text_extents(text).width, py(tick) + 4)
        ctx.show_text(text)
    ctx.set_source_rgb(0, 0, 0)
    ctx.rectangle(left, top, width - left - right, height - top - bottom)
    ctx.stroke()
    ctx.set_font_size(15)
    ctx.move_to(left, 30)
    ctx.show_text(title)
    ctx.set_font_size(13)
    ctx.move_to(left + (width - left - right) / 2 - ctx.text_extents(x_label).width / 2, height - bottom + 42)
    ctx.show_text(x_label)
    ctx.save()
    ctx.move_to(22, top + (height - top - bottom) / 2 + ctx.text_extents(y_label).width / 2)
    ctx.rotate(-math.pi / 2)
    ctx.show_text(y_label)
    ctx.restore()
    ctx.save()
    ctx.rectangle(left, top, width - left - right, height - top - bottom)
    ctx.clip()
    ctx.set_line_width(2)
    for (_, xs, ys), (colour, dashed) in zip(series, styles):
        ctx.set_source_rgb(*COLOURS[colour % len(COLOURS)])
        ctx.set_dash([8.0, 5.0] if dashed else [])
        ctx.move_to(px(xs[0]), py(ys[0]))
        for x, y in zip(xs[1:], ys[1:]):
            ctx.line_to(px(x), py(y))
        ctx.stroke()
        if markers and not dashed:  # a dashed series is a reference line, not measured points
            for x, y in zip(xs, ys):
                ctx.arc(px(x), py(y), 4, 0, 2 * math.pi)
                ctx.fill()
    ctx.set_dash([])
    ctx.restore()
    ctx.set_font_size(12)
    for i, ((name, _, _), (colour, dashed)) in enumerate(zip(series, styles)):  # one row each, below the plot
        y = height - 18 * (legend_rows - i) + 2
        ctx.set_source_rgb(*COLOURS[colour % len(COLOURS)])
        for start in ((0, 12) if dashed else (0,)):  # a dashed swatch is two short bars
            ctx.rectangle(left + start, y - 6, 8 if dashed else 18, 4)
        ctx.fill()
        ctx.set_source_rgb(0.1, 0.1, 0.1)
        ctx.move_to(left + 26, y)
        ctx.show_text(name)
    surface.write_to_png(str(out))
    return out
