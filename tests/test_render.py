"""Pictures for people: the global view's colours, the GIF writer and the render command."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from simcore.controller import ScriptedDriver
from simcore.render import render_frame, write_animation
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator
from simcore.views import sign_line_polygon

PPM = 5.0  # pixels per metre of the global view in these tests


def world_to_pixel(sim, x, y):
    half = int(np.ceil(2 * sim.intersection.extent_m * PPM)) / 2.0
    return int(round(half - y * PPM)), int(round(half + x * PPM))  # row, column


@pytest.fixture(scope="module")
def medium():
    sim = Simulator("medium", SimConfig(), seed=4)
    result = sim.reset()
    return sim, result


def test_frame_shape_and_car_colour(medium):
    sim, result = medium
    frame = render_frame(sim, result, 0, pixels_per_m=PPM)
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    for slot in np.flatnonzero(sim.present):
        row, col = world_to_pixel(sim, sim.x[slot], sim.y[slot])
        r, g, b = frame[row, col].astype(int)
        assert g > 150 and g > r + 60 and g > b + 60, (slot, (r, g, b))  # learning cars are green


def test_sign_lines_are_red_for_stop_and_yellow_for_yield(medium):
    sim, result = medium
    sim.sign[:] = [Sign.STOP, Sign.YIELD, Sign.NONE, Sign.STOP]
    frame = render_frame(sim, result, 0, pixels_per_m=PPM)
    for lane in range(4):
        polygon = np.array(sign_line_polygon(sim.intersection, lane))
        # centre of the bar for stop; the yield teeth are solid near their base, a third in
        cx, cy = polygon.mean(axis=0) if sim.sign[lane] == Sign.STOP else (
            polygon[0] + (polygon[1] - polygon[0]) * 0.375 + (polygon[3] - polygon[0]) * 0.25)
        r, g, b = frame[world_to_pixel(sim, cx, cy)].astype(int)
        if sim.sign[lane] == Sign.STOP:
            assert r > 180 and g < 80 and b < 80, (lane, (r, g, b))
        elif sim.sign[lane] == Sign.YIELD:
            assert r > 180 and g > 160 and b < 80, (lane, (r, g, b))
        else:
            assert abs(r - g) < 20 and abs(g - b) < 20, (lane, (r, g, b))  # plain grey road


def test_side_panel_shows_the_focus_agents_views(medium):
    sim, result = medium
    frame = render_frame(sim, result, 1, pixels_per_m=PPM)
    world_px = int(np.ceil(2 * sim.intersection.extent_m * PPM))
    panel = frame[:, world_px:]
    assert (panel == 255).all(axis=2).sum() > 500  # white road and path pixels of the views


def test_gif_has_every_frame(tmp_path):
    sim = Simulator("easy", SimConfig(), seed=0)
    result = sim.reset()
    driver = ScriptedDriver(sim)
    frames = []
    for _ in range(4):
        frames.append(render_frame(sim, result, 0, pixels_per_m=2.0))
        result = sim.step(driver.act())
    out = write_animation(frames, tmp_path / "run.gif", fps=10)
    with Image.open(out) as image:
        assert image.n_frames == 4
        assert image.size == (frames[0].shape[1], frames[0].shape[0])


def test_unknown_animation_format_is_refused(tmp_path):
    with pytest.raises(ValueError, match=".gif or .mp4"):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / "run.xyz")


def crossway(*args):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=120)


def test_render_command_writes_a_gif(tmp_path):
    out = tmp_path / "demo.gif"
    result = crossway("render", "--scenario", "easy", "--steps", "5", "--out", str(out), "--pixels-per-m", "2")
    assert result.returncode == 0, result.stderr
    assert "wrote" in result.stdout
    with Image.open(out) as image:
        assert image.n_frames == 5


@pytest.mark.parametrize("args, message", [
    (["--steps", "0"], "--steps"),
    (["--out", "run.xyz"], ".gif or .mp4"),
    (["--out", "/no/such/dir/run.gif"], "does not exist"),
    (["--focus", "nowhere_0"], "no entry lane"),
    (["--scenario", "missing.toml"], "not a built-in scenario"),
])
def test_render_command_bad_input(tmp_path, args, message):
    result = crossway("render", "--steps", "2", "--out", str(tmp_path / "x.gif"), *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.skipif(__import__("shutil").which("ffmpeg") is None, reason="MP4 output needs ffmpeg on PATH")
def test_mp4_output(tmp_path):
    out = tmp_path / "demo.mp4"
    result = crossway("render", "--scenario", "easy", "--steps", "6", "--out", str(out), "--pixels-per-m", "2")
    assert result.returncode == 0, result.stderr
    probe = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0",
                            "-show_entries", "stream=nb_read_frames,codec_name", "-of", "csv=p=0", str(out)],
                           capture_output=True, text=True)
    assert probe.stdout.strip().split(",")[-1] == "6"
