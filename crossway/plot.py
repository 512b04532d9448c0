"""Learning curves as PNG, drawn with cairo (no plotting library needed).

``plot_curves`` draws one or more series of (x, y) points on shared axes with a legend; ``plot_dot_panels``
values by category with error whiskers in panels (Table I reports side by side); the
``crossway plot`` command reads ``progress.csv`` files written by ``crossway train``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cairo

# ten distinct colours (matplotlib's tab10 order), so ten series or policies tell apart before any repeats
COLOURS = [(0.12, 0.47, 0.71), (0.84, 0.15, 0.16), (0.17, 0.63, 0.17), (1.0, 0.5, 0.05), (0.58, 0.40, 0.74),
           (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.5, 0.5, 0.5), (0.74, 0.74, 0.13), (0.09, 0.75, 0.81)]


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


def _y_axis_label(ctx, text: str, middle_y: float) -> None:
    """``text`` upright along the left edge, centred on ``middle_y``."""
    ctx.save()
    ctx.move_to(22, middle_y + ctx.text_extents(text).width / 2)
    ctx.rotate(-math.pi / 2)
    ctx.show_text(text)
    ctx.restore()


def _legend_name(ctx, left: float, y: float, name: str) -> None:
    """A legend row's text, beside the swatch at ``left``."""
    ctx.set_source_rgb(0.1, 0.1, 0.1)
    ctx.move_to(left + 26, y)
    ctx.show_text(name)


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
    _y_axis_label(ctx, y_label, top + (height - top - bottom) / 2)
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
        _legend_name(ctx, left, y, name)
    surface.write_to_png(str(out))
    return out


def plot_dot_panels(panels: list[tuple[str, list[tuple[str, list[float | None], list[float | None]]],
                                       list[float | None]]],
                    categories: list[str], out: Path, title: str, y_label: str, reference_name: str,
                    panel_width: int = 260, height: int = 420) -> Path:
    """Fractions (rates in [0, 1]) by category, one panel each, side by side on a shared y axis
    that runs on a 0.01 grid from just under the lowest value to at most 1: every series a dot per
    category with a whisker of +-its error (None: no dot, or no whisker), the panel's reference
    value per category as a black bar across the category (None: no bar). ``panels``: (panel title,
    series as (name, values, errors), references). A series keeps its colour in every panel."""
    names = list(dict.fromkeys(name for _, series, _ in panels for name, _, _ in series))
    colour_of = {name: COLOURS[i % len(COLOURS)] for i, name in enumerate(names)}
    points = [(v - (e or 0.0), v + (e or 0.0)) for _, series, _ in panels for _, values, errors in series
              for v, e in zip(values, errors) if v is not None]
    points += [(r, r) for _, _, references in panels for r in references if r is not None]
    if not points:
        raise ValueError("nothing to draw: no value in any panel")
    low, high = min(p[0] for p in points), max(p[1] for p in points)
    y0 = math.floor((low - 0.005) * 100) / 100
    y1 = max(min(1.0, math.ceil((high + 0.005) * 100) / 100), y0 + 0.01)
    legend_rows = len(names) + 1
    left, right, top, bottom, gap = 70, 20, 60, 40 + 18 * legend_rows, 16
    width = left + right + len(panels) * panel_width + (len(panels) - 1) * gap
    surface = cairo.ImageSurface(cairo.FORMAT_RGB24, width, height)
    ctx = cairo.Context(surface)
    ctx.set_source_rgb(1, 1, 1)
    ctx.paint()
    ctx.select_font_face("sans-serif")

    def py(y: float) -> float:
        return height - bottom - (y - y0) / (y1 - y0) * (height - top - bottom)

    ctx.set_font_size(15)
    ctx.set_source_rgb(0, 0, 0)
    ctx.move_to(left, 26)
    ctx.show_text(title)
    ctx.set_font_size(13)
    _y_axis_label(ctx, y_label, top + (height - top - bottom) / 2)
    ticks = _nice_ticks(y0, y1)
    for index, (panel_title, series, references) in enumerate(panels):
        x_left = left + index * (panel_width + gap)
        ctx.set_font_size(12)
        ctx.set_line_width(1)
        for tick in ticks:
            ctx.set_source_rgb(0.9, 0.9, 0.9)
            ctx.move_to(x_left, py(tick))
            ctx.line_to(x_left + panel_width, py(tick))
            ctx.stroke()
            if index == 0:
                ctx.set_source_rgb(0.2, 0.2, 0.2)
                text = f"{tick:.3g}"
                ctx.move_to(x_left - 8 - ctx.text_extents(text).width, py(tick) + 4)
                ctx.show_text(text)
        ctx.set_source_rgb(0, 0, 0)
        ctx.rectangle(x_left, top, panel_width, height - top - bottom)
        ctx.stroke()
        ctx.set_font_size(13)
        ctx.move_to(x_left + panel_width / 2 - ctx.text_extents(panel_title).width / 2, top - 8)
        ctx.show_text(panel_title)
        slot = panel_width / len(categories)
        for k, category in enumerate(categories):
            centre = x_left + (k + 0.5) * slot
            ctx.set_font_size(12)
            ctx.set_source_rgb(0.2, 0.2, 0.2)
            ctx.move_to(centre - ctx.text_extents(category).width / 2, height - bottom + 18)
            ctx.show_text(category)
            if references[k] is not None:
                ctx.set_source_rgb(0, 0, 0)
                ctx.set_line_width(3)
                ctx.move_to(centre - 0.42 * slot, py(references[k]))
                ctx.line_to(centre + 0.42 * slot, py(references[k]))
                ctx.stroke()
            step = 0.7 * slot / max(len(series), 1)
            for j, (name, values, errors) in enumerate(series):
                value, error = values[k], errors[k]
                if value is None:
                    continue
                x = centre - 0.35 * slot + (j + 0.5) * step
                ctx.set_source_rgb(*colour_of[name])
                if error:
                    ctx.set_line_width(2)
                    ctx.move_to(x, py(value - error))
                    ctx.line_to(x, py(value + error))
                    ctx.stroke()
                ctx.arc(x, py(value), 4, 0, 2 * math.pi)
                ctx.fill()
    ctx.set_font_size(12)
    legend = [(name, colour_of[name], False) for name in names] + [(reference_name, (0, 0, 0), True)]
    for i, (name, colour, is_bar) in enumerate(legend):  # one row each, below the panels
        y = height - 18 * (legend_rows - i) + 2
        ctx.set_source_rgb(*colour)
        if is_bar:
            ctx.rectangle(left, y - 6, 18, 3)
        else:
            ctx.arc(left + 9, y - 4, 4, 0, 2 * math.pi)
        ctx.fill()
        _legend_name(ctx, left, y, name)
    surface.write_to_png(str(out))
    return out
