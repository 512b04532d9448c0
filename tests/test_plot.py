"""Learning-curve pictures: real PNG files read back and checked pixel by pixel."""

import subprocess
import sys

import cairo
import numpy as np
import pytest

from crossway.plot import COLOURS, _nice_ticks, plot_curves, read_progress


def pixels(path) -> np.ndarray:
    surface = cairo.ImageSurface.create_from_png(str(path))
    data = np.frombuffer(surface.get_data(), np.uint8).reshape(surface.get_height(), surface.get_stride() // 4, 4)
    return data[:, : surface.get_width(), 2::-1]  # BGRx in memory -> RGB


def colour_rows(image: np.ndarray, colour) -> np.ndarray:
    target = np.round(np.array(colour) * 255).astype(int)
    hits = np.all(np.abs(image.astype(int) - target) <= 2, axis=2)
    return np.flatnonzero(hits.any(axis=1))


def test_curves_are_drawn_and_the_legend_stays_out_of_the_plot(tmp_path):
    xs = list(np.linspace(0, 1e6, 200))
    out = plot_curves([("first", xs, [min(1.0, x / 5e5) for x in xs]), ("second", xs, [0.5] * 200)],
                      tmp_path / "c.png", "title", "agent steps", "reach rate", y_range=(0, 1))
    image = pixels(out)
    assert image.shape == (480, 800, 3)
    height, bottom = 480, 60 + 18 * 2  # the plot frame ends at height - bottom
    first, second = colour_rows(image, COLOURS[0]), colour_rows(image, COLOURS[1])
    # each curve inside the frame, each legend swatch below it, in its own row
    assert first.min() < height - bottom and second.min() < height - bottom
    legend_first, legend_second = first[first > height - bottom], second[second > height - bottom]
    assert len(legend_first) and len(legend_second)
    assert legend_first.max() < legend_second.min()
    # the flat second curve at y = 0.5 is one horizontal band in the middle of the frame
    inside = second[second < height - bottom]
    assert inside.max() - inside.min() <= 3


def test_progress_columns_are_checked(tmp_path):
    path = tmp_path / "progress.csv"
    path.write_text("wall_s,agent_steps,reach_rate\n1,10,0.5\n2,20,0.75\n")
    assert read_progress(path, "agent_steps", "reach_rate") == ([10.0, 20.0], [0.5, 0.75])
    with pytest.raises(ValueError, match="no column 'speed'"):
        read_progress(path, "agent_steps", "speed")
    result = subprocess.run([sys.executable, "-m", "crossway", "plot", f"run={path}", "--out", str(tmp_path / "p.png")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert pixels(tmp_path / "p.png").shape == (480, 800, 3)


def test_styles_share_a_colour_and_dash_a_series(tmp_path):
    xs = [0.0, 1.0]
    series = [("solid", xs, [0.25, 0.25]), ("dashed", xs, [0.75, 0.75])]
    out = plot_curves(series, tmp_path / "s.png", "t", "x", "y", y_range=(0, 1), styles=[(0, False), (0, True)])
    image = pixels(out)
    target = np.round(np.array(COLOURS[0]) * 255).astype(int)
    hits = np.all(np.abs(image.astype(int) - target) <= 2, axis=2)
    rows = np.flatnonzero(hits.sum(axis=1) > 200)  # long runs of the colour: the two curves
    solid_row, dashed_row = rows.max(), rows.min()  # y = 0.25 is lower in the picture
    assert hits[solid_row].sum() > 1.4 * hits[dashed_row].sum()  # the dashed line has gaps
    with pytest.raises(ValueError, match="2 styles for 1 series"):
        plot_curves(series[:1], tmp_path / "bad.png", "t", "x", "y", styles=[(0, False), (1, True)])


def test_y_range_zooms_the_axis_and_bad_limits_are_refused(tmp_path):
    path = tmp_path / "progress.csv"
    path.write_text("samples,student_reach_rate\n0,0.95\n100,0.95\n")
    out = tmp_path / "zoom.png"
    command = [sys.executable, "-m", "crossway", "plot", f"run={path}", "--x", "samples", "--y", "student_reach_rate"]
    result = subprocess.run(command + ["--y-range", "0.9,1", "--out", str(out)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    height, top, bottom = 480, 50, 60 + 18  # frame rows top .. height - bottom, one legend row
    rows = colour_rows(pixels(out), COLOURS[0])
    curve = rows[rows < height - bottom]
    middle = (top + height - bottom) / 2
    # 0.95 is half-way up a 0.9-1 axis (on the default 0-1 axis it would sit near the top)
    assert abs(curve.mean() - middle) <= 3
    for bad, message in (("1,0.9", "LOW must be under HIGH"), ("0.9", "expected LOW,HIGH"),
                         ("0,inf", "must be finite")):
        result = subprocess.run(command + ["--y-range", bad, "--out", str(tmp_path / "bad.png")],
                                capture_output=True, text=True, timeout=60)
        assert result.returncode == 2 and message in result.stderr
        assert not (tmp_path / "bad.png").exists()


def test_ticks_reach_both_ends_of_the_axis():
    assert _nice_ticks(0.85, 1.0) == pytest.approx([0.85, 0.9, 0.95, 1.0])
    assert _nice_ticks(0.0, 1.0) == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert _nice_ticks(0.0, 1e6) == pytest.approx([0.0, 2e5, 4e5, 6e5, 8e5, 1e6])


def test_where_keeps_the_rows_of_one_sign_and_markers_show_single_points(tmp_path):
    """--where sign=stop plots one sign of a Table I tests CSV; a test alone is a dot, not nothing."""
    path = tmp_path / "table1-hard-tests.csv"
    path.write_text("delay_max_s,sign,episodes,goal\n10.0,stop,5,0.5\n10.0,none,5,1.0\n20.0,stop,5,0.75\n")
    assert read_progress(path, "delay_max_s", "goal", {"sign": "stop"}) == ([10.0, 20.0], [0.5, 0.75])
    with pytest.raises(ValueError, match="no rows matching sign=yield"):
        read_progress(path, "delay_max_s", "goal", {"sign": "yield"})
    with pytest.raises(ValueError, match="no column 'lane'"):
        read_progress(path, "delay_max_s", "goal", {"lane": "1"})
    command = [sys.executable, "-m", "crossway", "plot", f"stop={path}", "--x", "delay_max_s", "--y", "goal",
               "--x-label", "delay_max [s]", "--y-label", "reach", "--where", "sign=stop", "--y-range", "0,1"]
    result = subprocess.run(command + ["--out", str(tmp_path / "w.png")], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    bad = subprocess.run(command[:-4] + ["--where", "sign", "--out", str(tmp_path / "x.png")], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode != 0 and "expected COLUMN=VALUE" in bad.stderr
    single = plot_curves([("one", [10.0], [0.5])], tmp_path / "one.png", "t", "x", "y", y_range=(0, 1), markers=True)
    assert len(colour_rows(pixels(single), COLOURS[0])) >= 6  # the dot (and the legend swatch)
    bare = plot_curves([("one", [10.0], [0.5])], tmp_path / "bare.png", "t", "x", "y", y_range=(0, 1))
    assert len(colour_rows(pixels(bare), COLOURS[0])) < len(colour_rows(pixels(single), COLOURS[0]))


def test_table1_picture_of_a_single_test_keeps_its_dots_inside_and_draws_the_paper(tmp_path):
    """One test (--sweep-up-to 10): the x axis spans 5 s either side, so the dots sit inside the
    frame, and the paper's reach per sign is a dashed line across it, not a point."""
    from evaluation.table1 import plot_tests

    rows = [{"delay_max_s": 10.0, "sign": "stop", "episodes": 100, "goal": 0.9}]
    image = pixels(plot_tests(tmp_path / "t.png", "hard", rows))
    left, right, top, bottom = 80, 20, 50, 60 + 18 * 2  # stop: ours and the paper's, two legend rows
    target = np.round(np.array(COLOURS[2]) * 255).astype(int)  # stop is the third sign's colour
    hits = np.all(np.abs(image.astype(int) - target) <= 2, axis=2)[top:480 - bottom, left + 2:800 - right - 2]
    dot_rows = np.flatnonzero(hits[:, 330:370].sum(axis=1) >= 5)
    assert len(dot_rows) >= 5  # a filled dot in the middle of the frame (x = 10 of 5..15)
    assert hits.sum(axis=1).max() > 300  # the paper's 0.972, dashed across the frame
