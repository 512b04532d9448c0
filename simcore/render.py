"""Pictures for people: the global view in the paper's look, one agent's views beside it, GIF/MP4.

Paper, Fig. 1 and 2: grey roads, stop lines red, yield lines yellow (as segments), learning
cars green (scripted traffic white), and the 50 x 50 m square one agent perceives, outlined in
green. The panel on the right shows that agent's four semantic channels (newest frame) exactly
as the network receives them, scaled up with nearest neighbour, plus the time, the scenario and
the episodes so far by end reason.

Entry points:

- ``render_frame(sim, result, focus_slot, pixels_per_m)``: one ``[H, W, 3]`` uint8 RGB image;
- ``choose_focus(sim, previous, lane)``: which slot to follow from frame to frame;
- ``write_animation(frames, path, fps)``: an animated GIF (Pillow) or MP4 (ffmpeg); frames may
  be any iterable and are consumed one at a time.

World frame: x east, y north [m]. The global view maps world point (x, y) to pixel column
``W0/2 + x * pixels_per_m`` and row ``W0/2 - y * pixels_per_m`` (``world_to_pixel``), where
W0 is the side of the square global view [px]. This module and ``simcore.views`` are the only
ones that import cairo.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path as FilePath

import cairo
import numpy as np

from simcore.dynamics import box_corners
from simcore.rightofway import SIGN_NAMES, Sign
from simcore.scenario import road_regions
from simcore.views import CHANNELS, VIEW_SIZE_PX, sign_line_polygon

# colours, RGB in [0, 1]
BACKGROUND = (0.13, 0.15, 0.13)  # off-road
ROAD = (0.45, 0.45, 0.47)
MARKING = (0.85, 0.85, 0.85)  # centre and lane lines
STOP_RED = (0.86, 0.12, 0.12)
YIELD_YELLOW = (0.98, 0.82, 0.10)
LEARNER_GREEN = (0.20, 0.80, 0.25)
CAR_OUTLINE = (0.05, 0.25, 0.07)
TRAFFIC_WHITE = (0.95, 0.95, 0.95)
PANEL = (0.08, 0.08, 0.10)
TEXT = (0.92, 0.92, 0.92)
TEXT_DIM = (0.62, 0.62, 0.66)

ROUTE_ALPHA = 0.25  # opacity of the focus agent's route over the road
YIELD_SEGMENTS = 3  # a yield line is drawn as this many segments across its lane
YIELD_FILL = 0.7  # fraction of each segment's share of the lane that is painted
MARGIN_PX = 14  # space around the panel's blocks [px]
LINE_PX = 18  # height of one text line [px]
PANEL_TEXT_LINES = 6  # text rows reserved above the views (longer text is cut)
FONT = "DejaVu Sans"


def world_to_pixel(sim, x: float, y: float, pixels_per_m: float = 6.0) -> tuple[int, int]:
    """Pixel ``(row, column)`` of world point ``(x, y)`` [m] in a frame from ``render_frame``."""
    half = _world_px(sim, pixels_per_m) / 2.0
    return int(math.floor(half - y * pixels_per_m)), int(math.floor(half + x * pixels_per_m))


def _world_px(sim, pixels_per_m: float) -> int:
    """Side of the square global view [px]: the whole map, every route inside it."""
    return int(math.ceil(2.0 * sim.intersection.extent_m * pixels_per_m))


def _unit(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    return np.array([math.cos(a), math.sin(a)])


def _polygon(ctx: cairo.Context, points) -> None:
    ctx.move_to(*points[0])
    for p in points[1:]:
        ctx.line_to(*p)
    ctx.close_path()


# -- the global view --------------------------------------------------------------------------


def _draw_roads(ctx: cairo.Context, sim) -> None:
    """Road surface (``scenario.road_regions``, as the navigable view), then lane markings."""
    intersection = sim.intersection
    spec = intersection.spec
    half = intersection.half_size_m
    far = intersection.extent_m * math.sqrt(2.0) + 1.0  # past the picture's corner [m]
    for region in road_regions(intersection, arm_length_m=far):
        ctx.set_source_rgb(*(ROAD if region.is_road else BACKGROUND))
        ctx.new_path()
        if region.radius > 0.0:
            ctx.arc(region.center[0], region.center[1], region.radius, 0.0, 2.0 * math.pi)
        else:
            _polygon(ctx, region.polygon)
        ctx.fill()
    # on the arms, from the sign lines outwards: solid centre line, dashed lines between lanes
    ctx.set_source_rgb(*MARKING)
    ctx.set_line_width(0.15)
    for branch in spec.branches:
        u, n = _unit(branch.angle_deg), _unit(branch.angle_deg + 90.0)
        ctx.set_dash([])
        ctx.move_to(*(half * u))
        ctx.line_to(*(far * u))
        ctx.stroke()
        ctx.set_dash([3.0, 3.0])  # 3 m painted, 3 m gap
        for k in range(1, spec.lanes_per_direction):
            for side in (-1.0, 1.0):
                offset = side * k * spec.lane_width_m * n
                ctx.move_to(*(half * u + offset))
                ctx.line_to(*(far * u + offset))
                ctx.stroke()
    ctx.set_dash([])


def lane_sign(sim, lane_index: int) -> Sign:
    """The sign shown on an entry lane: its car's sign while a car drives from it, else its arm's."""
    for slot, lane in enumerate(sim.slot_lanes):
        if lane == lane_index and sim.present[slot]:
            return Sign(int(sim.sign[slot]))
    return Sign(int(sim.branch_signs[sim.intersection.lanes[lane_index].branch]))


def sign_marking_polygons(intersection, lane_index: int, sign: Sign) -> list[list[tuple[float, float]]]:
    """Painted shapes of a lane's sign [m]: one bar for stop, ``YIELD_SEGMENTS`` for yield, none for none.

    They cover the same area as the sign channel's line (``views.sign_line_polygon``).
    """
    if sign == Sign.NONE:
        return []
    bar = [np.array(p) for p in sign_line_polygon(intersection, lane_index)]
    if sign == Sign.STOP:
        return [[tuple(p) for p in bar]]
    a, b, depth = bar[0], bar[1], bar[3] - bar[0]
    across = (b - a) / YIELD_SEGMENTS
    gap = 0.5 * (1.0 - YIELD_FILL) * across
    segments = []
    for k in range(YIELD_SEGMENTS):
        p0 = a + k * across + gap
        p1 = a + (k + 1) * across - gap
        segments.append([tuple(p0), tuple(p1), tuple(p1 + depth), tuple(p0 + depth)])
    return segments


def _draw_signs(ctx: cairo.Context, sim) -> None:
    for lane in sim.intersection.lanes:
        sign = lane_sign(sim, lane.index)
        ctx.set_source_rgb(*(STOP_RED if sign == Sign.STOP else YIELD_YELLOW))
        for shape in sign_marking_polygons(sim.intersection, lane.index, sign):
            _polygon(ctx, shape)
            ctx.fill()


def _draw_boxes(ctx: cairo.Context, poses: np.ndarray, fill, outline) -> None:
    """Oriented car boxes with a dark mark at the front; ``poses`` [N, 3]: x [m], y [m], heading [rad]."""
    if len(poses) == 0:
        return
    corners = box_corners(poses[:, 0], poses[:, 1], poses[:, 2])
    ctx.set_line_width(0.15)
    for box in corners:
        _polygon(ctx, box)
        ctx.set_source_rgb(*fill)
        ctx.fill_preserve()
        ctx.set_source_rgb(*outline)
        ctx.stroke()
        front = (box[0] + box[3]) / 2.0 - 0.5 * (box[0] - box[1]) / np.linalg.norm(box[0] - box[1])
        ctx.arc(front[0], front[1], 0.35, 0.0, 2.0 * math.pi)  # windscreen: shows the heading
        ctx.fill()


def _draw_focus_route(ctx: cairo.Context, sim, slot: int) -> None:
    """The focus agent's route, faint: its lane-wide corridor, as in the path view."""
    points = sim.intersection.routes[sim.route[slot]].path.sample(1.0)
    ctx.set_source_rgba(*LEARNER_GREEN, ROUTE_ALPHA)
    ctx.set_line_width(sim.spec.lane_width_m)
    ctx.set_line_join(cairo.LINE_JOIN_ROUND)
    ctx.move_to(points[0, 0], points[0, 1])
    for x, y, _ in points[1:]:
        ctx.line_to(x, y)
    ctx.stroke()


def _draw_focus_square(ctx: cairo.Context, sim, slot: int) -> None:
    """The square the focus agent perceives (the scenario's ``views``), turned with its heading."""
    half = sim.spec.views.extent_m / 2.0
    shift = sim.spec.views.shift_m
    c, s = math.cos(sim.heading[slot]), math.sin(sim.heading[slot])
    for i, (forward, left) in enumerate([(shift + half, half), (shift - half, half), (shift - half, -half),
                                         (shift + half, -half)]):
        px = sim.x[slot] + forward * c - left * s
        py = sim.y[slot] + forward * s + left * c
        (ctx.move_to if i == 0 else ctx.line_to)(px, py)
    ctx.close_path()
    ctx.set_source_rgb(*LEARNER_GREEN)
    ctx.set_line_width(0.5)
    ctx.set_line_join(cairo.LINE_JOIN_MITER)
    ctx.stroke()


# -- the side panel ---------------------------------------------------------------------------


def _font(ctx: cairo.Context, size: float, bold: bool = False) -> None:
    ctx.select_font_face(FONT, cairo.FONT_SLANT_NORMAL,
                         cairo.FONT_WEIGHT_BOLD if bold else cairo.FONT_WEIGHT_NORMAL)
    ctx.set_font_size(size)


def _wrap(ctx: cairo.Context, text: str, width: float) -> list[str]:
    """Break ``text`` at spaces into lines no wider than ``width`` [px] in the current font."""
    lines: list[str] = []
    for word in text.split(" "):
        if lines and ctx.text_extents(lines[-1] + " " + word).x_advance <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    return lines


def _text(ctx: cairo.Context, x: float, y: float, text: str, colour=TEXT) -> None:
    ctx.set_source_rgb(*colour)
    ctx.move_to(x, y)
    ctx.show_text(text)


def _status_lines(sim, result, focus_slot, focus_ok: bool, episodes, caption: str) -> list[tuple[str, bool]]:
    """The panel's text as (line, is_heading) pairs."""
    on_road = int(np.count_nonzero(sim.learners_present))
    lines = [(caption or f"{sim.spec.name}   t = {sim.time_s:.1f} s", True),
             (f"cars on the road: {on_road} of {sim.num_slots} lanes", False)]
    if episodes is not None:
        counts = ", ".join(f"{reason} {count}" for reason, count in sorted(episodes.items()) if count)
        lines.append((f"episodes ended: {counts or 'none yet'}", False))
    if focus_slot is not None:
        lane = sim.slot_names[focus_slot]
        if focus_ok:
            turn = sim.intersection.routes[sim.route[focus_slot]].turn
            sign = SIGN_NAMES[Sign(int(sim.sign[focus_slot]))]
            lines.append((f"views of {lane} ({turn}, sign {sign}): {sim.speed[focus_slot]:.1f} m/s, "
                          f"target {sim.target_speed[focus_slot]:.1f} m/s", False))
        else:
            lines.append((f"views of {lane}: waiting for its next episode", False))
    return lines


def _legend(sim, traffic) -> list[tuple[str, tuple[float, float, float]]]:
    items = [("learning car", LEARNER_GREEN)]
    if traffic is not None or sim.num_traffic:
        items.append(("traffic car", TRAFFIC_WHITE))
    items += [("stop line", STOP_RED), ("yield line", YIELD_YELLOW)]
    return items


def _panel_scale(world_px: int) -> int:
    """View pixels are drawn as scale x scale blocks: as large as fits the global view's height."""
    fixed = (PANEL_TEXT_LINES + 1) * LINE_PX + 2 * LINE_PX + LINE_PX + 4 * MARGIN_PX  # text, view labels, legend, gaps
    return int(min(4, max(2, (world_px - fixed) // (2 * VIEW_SIZE_PX))))


def _draw_view(ctx: cairo.Context, frame: np.ndarray, x: float, y: float, scale: int) -> None:
    """One 84x84 uint8 channel as grey, ``scale`` x ``scale`` pixels per view pixel (nearest)."""
    grey = np.repeat(np.repeat(frame, scale, axis=0), scale, axis=1).astype(np.uint32)
    rgb = np.ascontiguousarray((0xFF << 24) | (grey << 16) | (grey << 8) | grey)
    size = frame.shape[0] * scale
    image = cairo.ImageSurface.create_for_data(memoryview(rgb), cairo.FORMAT_RGB24, size, size, size * 4)
    ctx.save()
    ctx.set_source_surface(image, x, y)
    ctx.get_source().set_filter(cairo.FILTER_NEAREST)
    ctx.rectangle(x, y, size, size)
    ctx.fill()
    ctx.restore()


# -- one frame --------------------------------------------------------------------------------


def render_frame(sim, result=None, focus_slot: int | None = None, pixels_per_m: float = 6.0, *,
                 episodes: Mapping[str, int] | None = None, traffic: np.ndarray | None = None,
                 caption: str = "") -> np.ndarray:
    """The global view plus the focus agent's four channels, as an ``[H, W, 3]`` uint8 RGB image.

    ``sim``: a ``Simulator``; every car on its road is a learner, drawn green.
    ``result``: the latest ``StepResult``; its views feed the side panel (None: empty panel).
    ``focus_slot``: slot whose view square, route and channels are shown (None: none). A car
    whose episode ended in this step is still shown at its last pose.
    ``pixels_per_m``: scale of the global view [px/m]; it covers the whole map, so its side is
    ``2 * sim.intersection.extent_m * pixels_per_m`` pixels.
    ``episodes``: episodes ended so far by end reason (e.g. ``{"goal": 3}``), printed in the panel.
    ``traffic``: optional ``[N, 3]`` poses (x [m], y [m], heading [rad]) of scripted traffic
    cars, drawn white.
    ``caption``: replaces the first panel line (default: scenario and simulated time).
    """
    if not (math.isfinite(pixels_per_m) and pixels_per_m > 0):
        raise ValueError(f"pixels_per_m must be a number > 0, got {pixels_per_m}")
    if focus_slot is not None and not 0 <= focus_slot < sim.num_slots:
        raise ValueError(f"focus_slot must be in 0..{sim.num_slots - 1} or None, got {focus_slot}")
    if traffic is not None:
        traffic = np.asarray(traffic, dtype=np.float64).reshape(-1, 3)
    world_px = _world_px(sim, pixels_per_m)
    scale = _panel_scale(world_px)
    view_px = VIEW_SIZE_PX * scale
    panel_w = 2 * view_px + 3 * MARGIN_PX
    width = world_px + panel_w
    focus_ok = focus_slot is not None and bool(
        sim.present[focus_slot] or (result is not None and result.observed[focus_slot]))

    # lay the panel's text out first: its height decides the frame's
    measure = cairo.Context(cairo.ImageSurface(cairo.FORMAT_RGB24, 1, 1))
    text_lines: list[tuple[str, bool]] = []
    for line, heading in _status_lines(sim, result, focus_slot, focus_ok, episodes, caption):
        _font(measure, 15.0 if heading else 12.0, heading)
        text_lines += [(part, heading) for part in _wrap(measure, line, panel_w - 2 * MARGIN_PX)]
    # a fixed number of text rows, so that every frame of an animation has the same size
    text_lines = text_lines[:PANEL_TEXT_LINES]
    views_top = MARGIN_PX + PANEL_TEXT_LINES * LINE_PX + LINE_PX
    legend_top = views_top + 2 * (view_px + LINE_PX + MARGIN_PX)
    height = max(world_px, legend_top + LINE_PX + MARGIN_PX)
    legend_top = height - LINE_PX - MARGIN_PX  # the legend sits at the bottom

    surface = cairo.ImageSurface(cairo.FORMAT_RGB24, width, height)
    ctx = cairo.Context(surface)
    ctx.set_source_rgb(*PANEL)
    ctx.paint()

    # global view: world metres, y up, origin at the junction's centre
    ctx.save()
    ctx.rectangle(0, 0, world_px, world_px)
    ctx.clip()
    ctx.set_source_rgb(*BACKGROUND)
    ctx.paint()
    ctx.translate(world_px / 2.0, world_px / 2.0)
    ctx.scale(pixels_per_m, -pixels_per_m)
    _draw_roads(ctx, sim)
    if focus_ok:
        _draw_focus_route(ctx, sim, focus_slot)
    _draw_signs(ctx, sim)
    cars = np.flatnonzero(sim.learners_present)
    if focus_ok and not sim.present[focus_slot]:
        cars = np.append(cars, focus_slot)  # ended this step: keep it at its last pose
    _draw_boxes(ctx, np.stack([sim.x[cars], sim.y[cars], sim.heading[cars]], axis=1),
                LEARNER_GREEN, CAR_OUTLINE)
    if focus_ok:  # the followed car gets a white rim
        _polygon(ctx, box_corners(sim.x[focus_slot], sim.y[focus_slot], sim.heading[focus_slot])[0])
        ctx.set_source_rgb(*TRAFFIC_WHITE)
        ctx.set_line_width(0.3)
        ctx.stroke()
    scripted = sim.traffic_poses()  # the simulator's own IDM traffic
    if traffic is not None:
        scripted = np.concatenate([scripted, traffic])
    if len(scripted):
        _draw_boxes(ctx, scripted, TRAFFIC_WHITE, (0.3, 0.3, 0.3))
    if focus_ok:
        _draw_focus_square(ctx, sim, focus_slot)
    ctx.restore()

    # side panel
    x0 = world_px + MARGIN_PX
    y = MARGIN_PX
    for line, heading in text_lines:
        _font(ctx, 15.0 if heading else 12.0, heading)
        y += LINE_PX
        _text(ctx, x0, y - 4, line, TEXT if heading else TEXT_DIM)
    show_views = focus_ok and result is not None and bool(result.observed[focus_slot])
    _font(ctx, 12.0)
    for c, name in enumerate(CHANNELS):
        col, row = c % 2, c // 2
        x = x0 + col * (view_px + MARGIN_PX)
        y = views_top + row * (view_px + LINE_PX + MARGIN_PX) + LINE_PX
        _text(ctx, x, y - 6, name)
        if show_views:
            _draw_view(ctx, np.ascontiguousarray(result.views[focus_slot, c * 4 + 3]), x, y, scale)
        ctx.set_source_rgb(*(LEARNER_GREEN if show_views else (0.3, 0.3, 0.3)))
        ctx.set_line_width(1.0)
        ctx.rectangle(x - 0.5, y - 0.5, view_px + 1, view_px + 1)
        ctx.stroke()
    x = x0
    for label, colour in _legend(sim, traffic):
        ctx.set_source_rgb(*colour)
        ctx.rectangle(x, legend_top + 4, 14, 10)
        ctx.fill()
        _text(ctx, x + 19, legend_top + 14, label, TEXT_DIM)
        x += 19 + ctx.text_extents(label).x_advance + 16

    surface.flush()
    # cairo's RGB24 pixels are native-endian 32-bit words 0xXXRRGGBB
    words = np.frombuffer(surface.get_data(), dtype=np.uint32).reshape(height, -1)[:, :width]
    rgb = np.empty((height, width, 3), dtype=np.uint8)
    rgb[..., 0] = words >> 16  # assignment keeps the low byte
    rgb[..., 1] = words >> 8
    rgb[..., 2] = words
    return rgb


def choose_focus(sim, previous: int | None = None, lane: str | None = None) -> int | None:
    """Slot to follow: the named entry lane's slot (``ValueError`` if there is none), else the
    previous focus while its car is on the road, else the lowest-index car on the road."""
    if lane is not None:
        if lane not in sim.slot_names:
            raise ValueError(f"no entry lane {lane!r} in scenario {sim.spec.name!r}; "
                             f"lanes: {', '.join(sim.slot_names)}")
        return sim.slot_names.index(lane)
    if previous is not None and sim.present[previous]:
        return previous
    present = np.flatnonzero(sim.learners_present)
    return int(present[0]) if len(present) else previous


# -- animations -------------------------------------------------------------------------------

# always in the GIF palette, so that colours absent from the first frame still come out exact
_KEY_COLOURS = [BACKGROUND, ROAD, MARKING, STOP_RED, YIELD_YELLOW, LEARNER_GREEN, CAR_OUTLINE,
                TRAFFIC_WHITE, PANEL, TEXT, TEXT_DIM, (0.0, 0.0, 0.0), (128 / 255,) * 3, (1.0, 1.0, 1.0),
                tuple(ROUTE_ALPHA * g + (1 - ROUTE_ALPHA) * r for g, r in zip(LEARNER_GREEN, ROAD))]


class _GifPalette:
    """A 256-colour palette (key colours plus a median cut of the first frame) and a 32^3 lookup
    table from 5-bit RGB to palette index: quantizing a frame is one numpy gather."""

    def __init__(self, first: np.ndarray):
        from PIL import Image

        keys = np.array([[round(255 * v) for v in colour] for colour in _KEY_COLOURS], dtype=np.uint8)
        cut = Image.fromarray(first[::2, ::2]).quantize(256 - len(keys), method=Image.Quantize.MEDIANCUT)
        found = np.array(cut.getpalette()[: 3 * (256 - len(keys))], dtype=np.uint8).reshape(-1, 3)
        palette = np.concatenate([found, keys])
        centres = np.arange(32) * 8 + 4
        grid = np.stack(np.meshgrid(centres, centres, centres, indexing="ij"), axis=-1).reshape(-1, 1, 3)
        lut = np.empty(32 ** 3, dtype=np.uint8)
        for start in range(0, len(grid), 4096):  # nearest palette colour of every cell centre
            d = ((grid[start:start + 4096].astype(np.int32) - palette[None].astype(np.int32)) ** 2).sum(-1)
            lut[start:start + 4096] = d.argmin(axis=1)
        lut[self._cells(palette)] = np.arange(len(palette))  # palette colours map to themselves; keys win
        self.lut = lut
        self.palette = palette

    @staticmethod
    def _cells(rgb: np.ndarray) -> np.ndarray:
        """Index of each colour's 5-bit cell, r << 10 | g << 5 | b (uint16: half the memory traffic)."""
        cells = (rgb[..., 0] >> 3).astype(np.uint16) << 10
        cells |= (rgb[..., 1] >> 3).astype(np.uint16) << 5
        cells |= rgb[..., 2] >> 3
        return cells

    def quantize(self, frame: np.ndarray):
        from PIL import Image

        image = Image.fromarray(self.lut[self._cells(frame)], mode="P")
        image.putpalette(self.palette.reshape(-1).tolist())
        return image


def _check_frame(frame, shape) -> np.ndarray:
    frame = np.asarray(frame)
    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"frames must be [H, W, 3] uint8 RGB arrays, got {frame.dtype} {frame.shape}")
    if shape is not None and frame.shape != shape:
        raise ValueError(f"all frames must have one shape: {shape} then {frame.shape}")
    return frame


def check_animation_path(path: str | FilePath) -> FilePath:
    """Refuse, before any work, an output that ``write_animation`` could not write (``ValueError``)."""
    path = FilePath(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ValueError(f"unknown animation format {path.suffix or '(no extension)'!r} in {str(path)!r}: "
                         f"use .gif or .mp4")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ValueError("MP4 needs ffmpeg on PATH (e.g. apt-get install ffmpeg); write a .gif instead")
    if not path.parent.is_dir():
        raise ValueError(f"output directory {str(path.parent)!r} does not exist")
    return path


def write_animation(frames: Iterable[np.ndarray], path: str | FilePath, fps: int = 10) -> int:
    """Write ``[H, W, 3]`` uint8 RGB frames as an animated GIF (Pillow, looping forever) or, for a
    path ending in ``.mp4``, an MP4 in ffmpeg's default codec (ffmpeg on PATH). ``frames`` may be a generator: frames
    are consumed one at a time (a GIF keeps one byte per pixel per frame until it is written; an
    MP4 streams). ``fps``: frames per second, 1..60 (10 plays the 100 ms steps in real time).
    Returns the number of frames written.
    """
    path = check_animation_path(path)
    if isinstance(fps, bool) or not isinstance(fps, int) or not 1 <= fps <= 60:
        raise ValueError(f"fps must be an integer from 1 to 60, got {fps!r}")
    if path.suffix.lower() == ".gif":
        return _write_gif(frames, path, fps)
    return _write_mp4(frames, path, fps)


def _write_gif(frames: Iterable[np.ndarray], path: FilePath, fps: int) -> int:
    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise ValueError("no frames to write")
    first = _check_frame(first, None)
    palette = _GifPalette(first)
    count = 1

    def rest():  # quantized one at a time while Pillow writes: it keeps its own copy of each
        nonlocal count
        for frame in frames:
            yield palette.quantize(_check_frame(frame, first.shape))
            count += 1

    # Pillow merges identical consecutive frames into one longer frame; the timing stays right
    palette.quantize(first).save(path, save_all=True, append_images=rest(), duration=round(1000 / fps),
                                 loop=0, optimize=False, disposal=1)
    return count


def _write_mp4(frames: Iterable[np.ndarray], path: FilePath, fps: int) -> int:
    ffmpeg = shutil.which("ffmpeg")
    count = 0
    process = None
    shape = None
    with tempfile.TemporaryFile() as log:
        try:
            for frame in frames:
                frame = _check_frame(frame, shape)
                if process is None:
                    shape = frame.shape
                    height, width = shape[:2]
                    process = subprocess.Popen(
                        [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                         "-s", f"{width}x{height}", "-r", str(fps), "-i", "-",
                         "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",  # H.264 with yuv420p needs even sides
                         "-pix_fmt", "yuv420p", str(path)],
                        stdin=subprocess.PIPE, stderr=log,
                    )
                process.stdin.write(np.ascontiguousarray(frame).tobytes())
                count += 1
        except BrokenPipeError:
            pass  # ffmpeg stopped early: its log says why, below
        finally:
            if process is not None:
                try:
                    process.stdin.close()
                except BrokenPipeError:
                    pass
                code = process.wait()
        if process is None:
            raise ValueError("no frames to write")
        if code != 0:
            log.seek(0)
            raise RuntimeError(f"ffmpeg failed (exit {code}): {log.read().decode(errors='replace')[-800:]}")
    return count
