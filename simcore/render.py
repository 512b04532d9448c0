"""Pictures for people: the global view in the paper's look, one agent's views beside it, GIF/MP4.

Paper, Fig. 1 and 2: grey roads, stop lines red, yield lines yellow, learning cars green
(scripted traffic white), and the 50 x 50 m square one agent perceives. The panel on the right
shows that agent's four semantic channels (newest frame) as the network receives them.
This module and ``simcore.views`` are the only ones that import cairo.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path as FilePath

import cairo
import numpy as np

from simcore.dynamics import box_corners
from simcore.rightofway import Sign
from simcore.scenario import road_regions
from simcore.views import CHANNELS, VIEW_EXTENT_M, sign_line_polygon

BACKGROUND = (0.13, 0.15, 0.13)
ROAD = (0.45, 0.45, 0.47)
MARKING = (0.85, 0.85, 0.85)
STOP_RED = (0.86, 0.12, 0.12)
YIELD_YELLOW = (0.98, 0.82, 0.10)
LEARNER_GREEN = (0.20, 0.80, 0.25)
TRAFFIC_WHITE = (0.95, 0.95, 0.95)
PANEL = (0.08, 0.08, 0.10)
TEXT = (0.92, 0.92, 0.92)
PANEL_SCALE = 2  # view pixels are drawn 2x2


def _polygon(ctx: cairo.Context, points) -> None:
    ctx.move_to(*points[0])
    for p in points[1:]:
        ctx.line_to(*p)
    ctx.close_path()


def _unit(angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return (math.cos(a), math.sin(a))


def _draw_roads(ctx: cairo.Context, sim) -> None:
    """Road surface (``scenario.road_regions``), then lane markings on the arms."""
    intersection = sim.intersection
    spec = intersection.spec
    half = intersection.half_size_m
    far = half + max(spec.approach_length_m, spec.exit_length_m) + 20.0  # past the picture's edge
    for region in road_regions(intersection, arm_length_m=far):
        ctx.set_source_rgb(*(ROAD if region.is_road else BACKGROUND))
        if region.radius > 0.0:
            ctx.new_path()
            ctx.arc(region.center[0], region.center[1], region.radius, 0.0, 2.0 * math.pi)
        else:
            _polygon(ctx, region.polygon)
        ctx.fill()
    # lane markings on the arms: solid centre line, dashed lines between lanes of one direction
    ctx.set_source_rgb(*MARKING)
    for branch in spec.branches:
        u, n = np.array(_unit(branch.angle_deg)), np.array(_unit(branch.angle_deg + 90.0))
        ctx.set_line_width(0.15)
        ctx.set_dash([])
        ctx.move_to(*(half * u))
        ctx.line_to(*(far * u))
        ctx.stroke()
        ctx.set_dash([3.0, 3.0])
        for k in range(1, spec.lanes_per_direction):
            for side in (-1.0, 1.0):
                offset = side * k * spec.lane_width_m * n
                ctx.move_to(*(half * u + offset))
                ctx.line_to(*(far * u + offset))
                ctx.stroke()
    ctx.set_dash([])


def _lane_sign(sim, lane_index: int) -> int:
    """The sign shown on a lane: its car's sign if a car drives from it, else its arm's sign."""
    for slot, lane in enumerate(sim.slot_lanes):
        if lane == lane_index and sim.present[slot]:
            return int(sim.sign[slot])
    return int(sim.branch_signs[sim.intersection.lanes[lane_index].branch])


def _draw_signs(ctx: cairo.Context, sim) -> None:
    for lane in sim.intersection.lanes:
        sign = _lane_sign(sim, lane.index)
        if sign == Sign.NONE:
            continue
        pts = sign_line_polygon(sim.intersection, lane.index)
        if sign == Sign.STOP:
            ctx.set_source_rgb(*STOP_RED)
            _polygon(ctx, pts)
            ctx.fill()
        else:  # yield: a row of yellow triangles ("shark teeth") pointing at the arriving car
            a, b = np.array(pts[0]), np.array(pts[1])
            depth = np.array(pts[3]) - a
            teeth = 4
            ctx.set_source_rgb(*YIELD_YELLOW)
            for t in range(teeth):
                p0 = a + (b - a) * (t + 0.1) / teeth
                p1 = a + (b - a) * (t + 0.9) / teeth
                tip = a + (b - a) * (t + 0.5) / teeth + depth
                _polygon(ctx, (p0, p1, tip))
                ctx.fill()


def _draw_cars(ctx: cairo.Context, sim, learner_colour=LEARNER_GREEN) -> None:
    idx = np.flatnonzero(sim.present)
    if len(idx) == 0:
        return
    corners = box_corners(sim.x[idx], sim.y[idx], sim.heading[idx])
    for box in corners:
        ctx.set_source_rgb(*learner_colour)
        _polygon(ctx, box)
        ctx.fill_preserve()
        ctx.set_source_rgb(0.05, 0.25, 0.07)
        ctx.set_line_width(0.15)
        ctx.stroke()
        # windscreen mark at the front so the heading is visible
        front = (box[0] + box[3]) / 2.0
        ctx.set_source_rgb(0.05, 0.25, 0.07)
        ctx.arc(front[0], front[1], 0.35, 0.0, 2.0 * math.pi)
        ctx.fill()


def _draw_focus_route(ctx: cairo.Context, sim, slot: int) -> None:
    """The focus agent's route, faint, under the sign lines."""
    points = sim.intersection.routes[sim.route[slot]].path.sample(1.0)
    ctx.set_source_rgba(*LEARNER_GREEN, 0.25)
    ctx.set_line_width(sim.spec.lane_width_m)
    ctx.move_to(points[0, 0], points[0, 1])
    for x, y, _ in points[1:]:
        ctx.line_to(x, y)
    ctx.stroke()


def _draw_focus_square(ctx: cairo.Context, sim, slot: int) -> None:
    """The 50 x 50 m square the focus agent perceives."""
    half = VIEW_EXTENT_M / 2.0
    c, s = math.cos(sim.heading[slot]), math.sin(sim.heading[slot])
    ctx.set_source_rgb(*LEARNER_GREEN)
    ctx.set_line_width(0.5)
    for i, (f, l) in enumerate([(half, half), (-half, half), (-half, -half), (half, -half)]):
        px = sim.x[slot] + f * c - l * s
        py = sim.y[slot] + f * s + l * c
        (ctx.move_to if i == 0 else ctx.line_to)(px, py)
    ctx.close_path()
    ctx.stroke()


def _text(ctx: cairo.Context, x: float, y: float, text: str, size: float = 13.0) -> None:
    ctx.select_font_face("sans-serif", cairo.FONT_SLANT_NORMAL, cairo.FONT_WEIGHT_NORMAL)
    ctx.set_font_size(size)
    ctx.set_source_rgb(*TEXT)
    ctx.move_to(x, y)
    ctx.show_text(text)


def choose_focus(sim, previous: int | None = None, lane: str | None = None) -> int | None:
    """Slot to follow: the named lane's car, else the previous focus if still there, else the first car."""
    if lane is not None:
        if lane not in sim.slot_names:
            raise ValueError(f"no entry lane {lane!r}; lanes: {sim.slot_names}")
        return sim.slot_names.index(lane)
    if previous is not None and sim.present[previous]:
        return previous
    present = np.flatnonzero(sim.present)
    return int(present[0]) if len(present) else previous


def render_frame(sim, result=None, focus_slot: int | None = None, pixels_per_m: float = 6.0,
                 caption: str = "") -> np.ndarray:
    """The global view plus the focus agent's four channels, as an [H, W, 3] uint8 image.

    ``result`` is the latest ``StepResult`` (its views feed the side panel; None: no panel
    content). ``focus_slot`` may be None (no square, empty panel).
    """
    if pixels_per_m <= 0:
        raise ValueError(f"pixels_per_m must be > 0, got {pixels_per_m}")
    extent = sim.intersection.extent_m
    world_px = int(math.ceil(2 * extent * pixels_per_m))
    view_px = 84 * PANEL_SCALE
    panel_w = 2 * view_px + 3 * 12
    width = world_px + panel_w
    height = max(world_px, 2 * view_px + 3 * 28 + 90)
    surface = cairo.ImageSurface(cairo.FORMAT_RGB24, width, height)
    ctx = cairo.Context(surface)
    ctx.set_source_rgb(*PANEL)
    ctx.paint()

    ctx.save()
    ctx.rectangle(0, 0, world_px, world_px)
    ctx.clip()
    ctx.set_source_rgb(*BACKGROUND)
    ctx.paint()
    ctx.translate(world_px / 2.0, world_px / 2.0)
    ctx.scale(pixels_per_m, -pixels_per_m)  # world y points up
    focus_ok = focus_slot is not None and (sim.present[focus_slot] or
                                           (result is not None and result.observed[focus_slot]))
    _draw_roads(ctx, sim)
    if focus_ok:
        _draw_focus_route(ctx, sim, focus_slot)
    _draw_signs(ctx, sim)
    if focus_ok:
        _draw_focus_square(ctx, sim, focus_slot)
    _draw_cars(ctx, sim)
    ctx.restore()

    # side panel: the focus agent's newest frame of each channel
    x0 = world_px + 12
    _text(ctx, x0, 22, caption or f"{sim.spec.name}  t = {sim.time_s:6.1f} s", 14.0)
    if focus_ok:
        _text(ctx, x0, 42, f"agent {sim.slot_names[focus_slot]}: {sim.speed[focus_slot]:4.1f} m/s "
                           f"(target {sim.target_speed[focus_slot]:4.1f})", 12.0)
    for c, name in enumerate(CHANNELS):
        col, row = c % 2, c // 2
        x = x0 + col * (view_px + 12)
        y = 70 + row * (view_px + 28)
        _text(ctx, x, y - 6, name, 12.0)
        ctx.set_source_rgb(0.3, 0.3, 0.3)
        ctx.rectangle(x - 1, y - 1, view_px + 2, view_px + 2)
        ctx.stroke()
        if focus_ok and result is not None and result.observed[focus_slot]:
            frame = np.ascontiguousarray(result.views[focus_slot, c * 4 + 3])
            grey = np.repeat(np.repeat(frame, PANEL_SCALE, axis=0), PANEL_SCALE, axis=1).astype(np.uint32)
            argb = (0xFF << 24) | (grey << 16) | (grey << 8) | grey
            image = cairo.ImageSurface.create_for_data(memoryview(np.ascontiguousarray(argb)),
                                                       cairo.FORMAT_RGB24, view_px, view_px, view_px * 4)
            ctx.set_source_surface(image, x, y)
            ctx.paint()
    surface.flush()
    data = np.frombuffer(surface.get_data(), dtype=np.uint8).reshape(height, surface.get_stride() // 4, 4)
    # cairo's RGB24 is native-endian 0xXXRRGGBB: on little-endian machines bytes are B, G, R, X
    return data[:, :width, 2::-1].copy()


def write_animation(frames: Sequence[np.ndarray], out: str | FilePath, fps: int = 10) -> FilePath:
    """Write frames as an animated GIF (Pillow) or an MP4 (needs ffmpeg on PATH)."""
    out = FilePath(out)
    if not frames:
        raise ValueError("no frames to write")
    if not 1 <= fps <= 60:
        raise ValueError(f"fps must be between 1 and 60, got {fps}")
    suffix = out.suffix.lower()
    if suffix == ".gif":
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        palette = images[0].quantize(colors=255, method=Image.Quantize.MEDIANCUT)
        quantized = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
        quantized[0].save(out, save_all=True, append_images=quantized[1:], duration=int(1000 / fps),
                          loop=0, optimize=False, disposal=1)
        return out
    if suffix == ".mp4":
        ffmpeg = shutil.which("ffmpeg")
        if ffmpeg is None:
            raise ValueError("writing MP4 needs ffmpeg on PATH (apt-get install ffmpeg); or write a .gif")
        height, width = frames[0].shape[:2]
        with tempfile.TemporaryFile() as log:
            process = subprocess.Popen(
                [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                 "-s", f"{width}x{height}", "-r", str(fps), "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                 "-pix_fmt", "yuv420p", str(out)],
                stdin=subprocess.PIPE, stderr=log,
            )
            for frame in frames:
                process.stdin.write(np.ascontiguousarray(frame).tobytes())
            process.stdin.close()
            if process.wait() != 0:
                log.seek(0)
                raise RuntimeError(f"ffmpeg failed: {log.read().decode(errors='replace')[-500:]}")
        return out
    raise ValueError(f"unknown animation format {out.suffix!r}: use .gif or .mp4")
