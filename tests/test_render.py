"""Pictures for people: the global view's colours and layout, focus choice, GIF/MP4 writing, and
``crossway render`` as a user runs it."""

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from crossway.cli import main as crossway_main
from simcore.controller import ScriptedDriver
from simcore.render import (
    choose_focus,
    lane_sign,
    render_frame,
    sign_marking_polygons,
    world_to_pixel,
    write_animation,
)
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator
from simcore.views import VIEW_EXTENT_M, VIEW_SIZE_PX

PPM = 4.0  # pixels per metre of the global view in these tests
SCENARIOS = ("easy", "medium", "hard")


def is_green(rgb) -> bool:
    r, g, b = (int(v) for v in rgb)
    return g > 150 and g > r + 60 and g > b + 60


def is_red(rgb) -> bool:
    r, g, b = (int(v) for v in rgb)
    return r > 180 and g < 80 and b < 80


def is_yellow(rgb) -> bool:
    r, g, b = (int(v) for v in rgb)
    return r > 180 and g > 160 and b < 80


def is_grey(rgb) -> bool:
    r, g, b = (int(v) for v in rgb)
    return max(r, g, b) - min(r, g, b) < 20


def pixel(frame, sim, x, y):
    return frame[world_to_pixel(sim, x, y, PPM)]


@pytest.fixture(scope="module", params=SCENARIOS)
def running(request):
    """A scenario a few scripted steps in: every lane has a car near its start."""
    sim = Simulator(request.param, SimConfig(), seed=3)
    sim.reset()
    driver = ScriptedDriver(sim)
    for _ in range(3):
        result = sim.step(driver.act())
    assert sim.present.all()
    return sim, result


def test_frame_shape_and_layout(running):
    sim, result = running
    frame = render_frame(sim, result, 0, pixels_per_m=PPM)
    world_px = math.ceil(2 * sim.intersection.extent_m * PPM)
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= world_px
    assert frame.shape[1] > world_px + 2 * 2 * VIEW_SIZE_PX  # the panel holds two views a row, >= 2x
    assert render_frame(sim, result, 0, pixels_per_m=PPM).shape == frame.shape  # stable size
    # and stable whatever the panel's text: an animation's frames must all have one size
    wordy = render_frame(sim, result, 0, pixels_per_m=PPM, caption="a long caption " * 12,
                         episodes={"goal": 12345, "crash": 678, "off_path": 9, "time_over": 10, "horizon": 11})
    assert wordy.shape == frame.shape
    assert render_frame(sim, result, None, pixels_per_m=PPM).shape == frame.shape


def test_cars_are_green_at_their_centres(running):
    sim, result = running
    frame = render_frame(sim, result, None, pixels_per_m=PPM)
    for slot in np.flatnonzero(sim.present):
        assert is_green(pixel(frame, sim, sim.x[slot], sim.y[slot])), sim.slot_names[slot]


def test_traffic_cars_are_white(running):
    sim, result = running
    frame = render_frame(sim, result, None, pixels_per_m=PPM, traffic=[[0.0, 0.0, 0.3]])
    assert (pixel(frame, sim, 0.0, 0.0) > 220).all()


def test_focus_square_is_green_and_turns_with_the_car(running):
    sim, result = running
    slot = 0
    frame = render_frame(sim, result, slot, pixels_per_m=PPM)
    half = VIEW_EXTENT_M / 2.0
    c, s = math.cos(sim.heading[slot]), math.sin(sim.heading[slot])
    # the middle of the square's left edge (seen from the car), well inside the picture
    x, y = sim.x[slot] - half * s, sim.y[slot] + half * c
    row, col = world_to_pixel(sim, x, y, PPM)
    patch = frame[row - 1:row + 2, col - 1:col + 2].reshape(-1, 3)
    assert any(is_green(p) for p in patch)
    # without a focus there is no square there
    plain = render_frame(sim, result, None, pixels_per_m=PPM)
    assert not any(is_green(p) for p in plain[row - 1:row + 2, col - 1:col + 2].reshape(-1, 3))


def test_sign_lines_red_for_stop_yellow_for_yield(running):
    sim, result = running
    branches = len(sim.intersection.branches)
    pattern = np.array([Sign.STOP, Sign.YIELD, Sign.NONE, Sign.STOP][:branches], dtype=np.int8)
    saved = sim.branch_signs.copy(), sim.sign.copy()
    try:
        sim.branch_signs[:] = pattern
        for slot, lane in enumerate(sim.slot_lanes):
            sim.sign[slot] = pattern[sim.intersection.lanes[lane].branch]
        frame = render_frame(sim, result, None, pixels_per_m=PPM)
        for lane in sim.intersection.lanes:
            expected = Sign(int(pattern[lane.branch]))
            assert lane_sign(sim, lane.index) == expected
            shapes = sign_marking_polygons(sim.intersection, lane.index, expected)
            if expected == Sign.NONE:
                assert shapes == []
                continue
            assert len(shapes) == (1 if expected == Sign.STOP else 3)
            for shape in shapes:
                colour = pixel(frame, sim, *np.mean(shape, axis=0))
                assert (is_red if expected == Sign.STOP else is_yellow)(colour), (lane.name, colour)
        # the arm without a sign: plain road where a line would be
        if branches > 2:
            none_lane = next(l for l in sim.intersection.lanes if pattern[l.branch] == Sign.NONE)
            bar = sign_marking_polygons(sim.intersection, none_lane.index, Sign.STOP)[0]
            assert is_grey(pixel(frame, sim, *np.mean(bar, axis=0)))
        # a car's own sign wins over its arm's while it is on the road
        slot = 0
        lane = sim.intersection.lanes[sim.slot_lanes[slot]]
        sim.branch_signs[lane.branch] = Sign.YIELD
        sim.sign[slot] = Sign.STOP
        frame = render_frame(sim, result, None, pixels_per_m=PPM)
        bar = sign_marking_polygons(sim.intersection, lane.index, Sign.STOP)[0]
        assert is_red(pixel(frame, sim, *np.mean(bar, axis=0)))
    finally:
        sim.branch_signs[:], sim.sign[:] = saved


def test_side_panel_shows_the_focus_agents_views(running):
    sim, result = running
    world_px = math.ceil(2 * sim.intersection.extent_m * PPM)
    with_views = render_frame(sim, result, 0, pixels_per_m=PPM)[:, world_px:]
    without = render_frame(sim, result, None, pixels_per_m=PPM)[:, world_px:]
    white = (with_views == 255).all(axis=2).sum()
    # road and path of the view, 2x2 or more screen pixels per view pixel
    assert white > 4 * (result.views[0, 3] == 255).sum()
    assert (without == 255).all(axis=2).sum() == 0


def test_focus_follows_a_lane_or_the_first_car():
    sim = Simulator("medium", SimConfig(observe=False), seed=0)
    sim.reset()
    assert choose_focus(sim, None, "south_0") == sim.slot_names.index("south_0")
    with pytest.raises(ValueError, match="no entry lane 'nowhere_0'.*south_0"):
        choose_focus(sim, None, "nowhere_0")
    assert choose_focus(sim) == 0  # lowest-index car on the road
    assert choose_focus(sim, 2) == 2  # keeps following while its car is there
    sim.present[2] = False
    sim.present[0] = False
    assert choose_focus(sim, 2) == 1  # switches when it leaves
    sim.present[:] = False
    assert choose_focus(sim, 1) == 1  # nobody on the road: keep the last


def test_gif_has_every_frame_and_loops(tmp_path):
    sim = Simulator("easy", SimConfig(), seed=0)
    sim.reset()
    driver = ScriptedDriver(sim)

    def frames():  # a generator: write_animation takes any iterable
        for _ in range(4):
            result = sim.step(driver.act())
            yield render_frame(sim, result, 0, pixels_per_m=2.0)

    out = tmp_path / "run.gif"
    assert write_animation(frames(), out, fps=5) == 4
    with Image.open(out) as image:
        assert image.n_frames == 4
        assert image.info["loop"] == 0
        assert image.info["duration"] == 200
        image.seek(3)
        last = np.asarray(image.convert("RGB"))
    assert last.shape[1] > last.shape[0] > 0


def test_gif_keeps_the_paper_colours_exactly(tmp_path):
    colours = np.array([[219, 31, 31], [250, 209, 26], [51, 204, 64], [115, 115, 120]], dtype=np.uint8)
    frame = np.repeat(np.repeat(colours[:, None, :], 8, axis=0), 8, axis=1)  # [32, 8, 3] stripes
    out = tmp_path / "colours.gif"
    write_animation([frame, frame[::-1].copy()], out)
    with Image.open(out) as image:
        got = np.asarray(image.convert("RGB"))
    assert np.abs(got.astype(int) - frame).max() <= 2


@pytest.mark.parametrize("name, message", [
    ("run.xyz", "use .gif or .mp4"),
    ("run", "use .gif or .mp4"),
    ("missing/run.gif", "does not exist"),
])
def test_bad_animation_paths_are_refused(tmp_path, name, message):
    with pytest.raises(ValueError, match=message):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / name)


def test_bad_frames_and_fps_are_refused(tmp_path):
    with pytest.raises(ValueError, match="no frames"):
        write_animation([], tmp_path / "run.gif")
    with pytest.raises(ValueError, match="fps"):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / "run.gif", fps=0)
    with pytest.raises(ValueError, match="one shape"):
        write_animation([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 6, 3), np.uint8)], tmp_path / "run.gif")


def test_mp4_without_ffmpeg_suggests_gif(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(ValueError, match="ffmpeg.*\\.gif"):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / "run.mp4")


# -- the command --------------------------------------------------------------------------------


def crossway(*args):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=120)


def test_render_command_writes_a_gif(tmp_path):
    out = tmp_path / "demo.gif"
    result = crossway("render", "--scenario", "easy", "--steps", "5", "--out", str(out), "--pixels-per-m", "2")
    assert result.returncode == 0, result.stderr
    assert str(out) in result.stdout and "5 frames" in result.stdout
    assert "episodes by end reason" in result.stdout
    assert "render: step 5/5" in result.stderr
    with Image.open(out) as image:
        assert image.n_frames == 5


def test_render_command_refuses_bad_input_from_a_shell(tmp_path):
    result = crossway("render", "--steps", "0", "--out", str(tmp_path / "x.gif"))
    assert result.returncode == 2
    assert "crossway render: error: --steps must be >= 1" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("args, message", [
    (["--steps", "0"], "--steps must be >= 1"),
    (["--fps", "0"], "--fps must be between 1 and 60"),
    (["--fps", "61"], "--fps must be between 1 and 60"),
    (["--pixels-per-m", "0"], "--pixels-per-m"),
    (["--delay-max", "-1"], "--delay-max"),
    (["--out", "run.xyz"], "use .gif or .mp4"),
    (["--out", "/no/such/dir/run.gif"], "does not exist"),
    (["--focus", "nowhere_0"], "no entry lane"),
    (["--scenario", "missing.toml"], "not a built-in scenario"),
])
def test_render_command_bad_input(tmp_path, capsys, args, message):
    out = ["--out", str(tmp_path / "x.gif")]
    assert crossway_main(["render", "--steps", "2", *out, *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("crossway render: error:") and message in err
    assert not (tmp_path / "x.gif").exists()


def test_render_help_documents_every_option(capsys):
    with pytest.raises(SystemExit) as exit_info:
        crossway_main(["render", "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for option in ("--scenario", "--steps", "--out", "--seed", "--focus", "--fps", "--delay-max", "--pixels-per-m"):
        assert option in text
    assert text.count("(default:") >= 8
    assert "100 ms" in text and "[s]" in text and "pixels per metre" in text


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="MP4 output needs ffmpeg on PATH")
def test_mp4_output(tmp_path):
    out = tmp_path / "demo.mp4"
    result = crossway("render", "--scenario", "easy", "--steps", "6", "--out", str(out), "--pixels-per-m", "2")
    assert result.returncode == 0, result.stderr
    probe = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0",
                            "-show_entries", "stream=nb_read_frames", "-of", "csv=p=0", str(out)],
                           capture_output=True, text=True)
    assert probe.stdout.strip() == "6"


def test_render_drives_with_a_checkpoint(tmp_path):
    import torch

    from learner.core import LearnerCore

    checkpoint = tmp_path / "ckpt.pt"
    torch.save(LearnerCore().state_dict(), checkpoint)
    out = tmp_path / "trained.gif"
    result = subprocess.run([sys.executable, "-m", "crossway", "render", "--scenario", "easy", "--steps", "3",
                             "--checkpoint", str(checkpoint), "--out", str(out), "--pixels-per-m", "2"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    with Image.open(out) as image:
        assert image.n_frames == 3
