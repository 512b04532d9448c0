"""Semantic views (paper, "Environment", Fig. 2): four 84x84 uint8 images per agent.

Each agent sees the 50 x 50 m square around it, ego-centred and heading-aligned: the car's
centre is the image centre and it points up. A scenario's ``[views]`` table may change the
square's side and move its centre ahead of the car (``ViewSpec``; not the paper's). Channels
and pixel codes (the paper's "white" is 255, its "black" is 128, and 0 is always "nothing here"):

======  ==============  =====================================================================
index   channel         codes
======  ==============  =====================================================================
0       navigable space 255 road, 0 off-road
1       path            255 the ego's route corridor (lane width), 0 elsewhere
2       obstacles       255 the ego and cars it has priority over ("white"),
                        128 cars with priority over the ego ("black"), 0 free
3       traffic sign    128 stop line ("black"), 255 yield line ("white"), 0 none
======  ==============  =====================================================================

How it is fast: what does not move (the road, every route's corridor, every lane's sign
line) is drawn once with cairo into world-aligned rasters at twice the view's resolution.
Each step cairo draws every car once into a shared raster of car labels; each agent's view
is then a rotated nearest-neighbour lookup into those rasters (one index computation shared
by all four channels), and a per-agent table turns car labels into priority shades.
"""

from __future__ import annotations

import math

import cairo
import numpy as np

from simcore.dynamics import VEHICLE_LENGTH, VEHICLE_WIDTH, box_corners
from simcore.rightofway import Sign
from simcore.scenario import Intersection, road_regions

VIEW_SIZE_PX = 84  # [px] (paper, Fig. 3)
VIEW_EXTENT_M = 50.0  # side of the square each agent sees [m] (paper, "Environment")
SUPERSAMPLE = 2  # world rasters are this many times finer than the view
SIGN_LINE_DEPTH_M = 2.0  # thickness of a drawn stop or yield line [m]

CHANNELS = ("navigable", "path", "obstacles", "sign")
ROAD = 255
PATH = 255
EGO_OR_LOWER = 255  # the paper's white obstacle
HIGHER_PRIORITY = 128  # the paper's black obstacle
STOP_LINE = 128  # the paper's black sign line
YIELD_LINE = 255  # the paper's white sign line
SIGN_CODES = {Sign.NONE: 0, Sign.YIELD: YIELD_LINE, Sign.STOP: STOP_LINE}


def may_show(ego_x, ego_y, ego_heading, x, y, extent_m: float = VIEW_EXTENT_M, shift_m: float = 0.0) -> np.ndarray:
    """Whether a car whose centre is at (``x``, ``y``) may show in the view of a car at
    (``ego_x``, ``ego_y``) heading ``ego_heading`` [rad]: its centre lies within the view's square
    (side ``extent_m``, centre ``shift_m`` ahead of the ego, aligned with its heading) grown by half
    a car length on every side, so some of its body can be in the picture. Arrays broadcast; NaN
    positions give False."""
    dx, dy = np.asarray(x) - ego_x, np.asarray(y) - ego_y
    cos, sin = np.cos(ego_heading), np.sin(ego_heading)
    ahead, left = dx * cos + dy * sin, dy * cos - dx * sin
    reach = 0.5 * extent_m + 0.5 * VEHICLE_LENGTH
    with np.errstate(invalid="ignore"):
        return (np.abs(ahead - shift_m) <= reach) & (np.abs(left) <= reach)


def _unit(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    return np.array([math.cos(a), math.sin(a)])


class WorldRaster:
    """A world-aligned A8 cairo surface covering [-half_extent, half_extent]^2 metres."""

    def __init__(self, half_extent_m: float, pixels_per_m: float):
        size = int(math.ceil(2.0 * half_extent_m * pixels_per_m))
        size += (-size) % 4  # A8 rows are 4-byte aligned: keep the stride equal to the width
        self.size = size
        self.pixels_per_m = pixels_per_m
        self.half_extent_m = size / pixels_per_m / 2.0
        self.surface = cairo.ImageSurface(cairo.FORMAT_A8, size, size)
        self.context = cairo.Context(self.surface)
        self.context.set_antialias(cairo.ANTIALIAS_NONE)  # exact pixel codes, no blended edges
        self.context.set_operator(cairo.OPERATOR_SOURCE)
        # world (x east, y north) -> raster (column right, row down)
        self.context.set_matrix(
            cairo.Matrix(pixels_per_m, 0.0, 0.0, -pixels_per_m,
                         self.half_extent_m * pixels_per_m, self.half_extent_m * pixels_per_m)
        )

    def value(self, code: int) -> None:
        self.context.set_source_rgba(0.0, 0.0, 0.0, code / 255.0)

    def polygon(self, points, code: int) -> None:
        ctx = self.context
        self.value(code)
        ctx.move_to(*points[0])
        for p in points[1:]:
            ctx.line_to(*p)
        ctx.close_path()
        ctx.fill()

    def array(self) -> np.ndarray:
        self.surface.flush()
        return np.frombuffer(self.surface.get_data(), dtype=np.uint8).reshape(self.size, self.size)


def draw_navigable(raster: WorldRaster, intersection: Intersection) -> None:
    """Road arms plus the junction square with curb fillets cut out of its corners."""
    ctx = raster.context
    # arms run on to the raster's edge, so a car at its start sees road behind it too
    for region in road_regions(intersection, arm_length_m=2.0 * raster.half_extent_m):
        code = ROAD if region.is_road else 0
        if region.radius > 0.0:
            raster.value(code)
            ctx.new_path()
            ctx.arc(region.center[0], region.center[1], region.radius, 0.0, 2.0 * math.pi)
            ctx.fill()
        else:
            raster.polygon(region.polygon, code)


def draw_route(raster: WorldRaster, intersection: Intersection, route_index: int, code: int = PATH) -> None:
    route = intersection.routes[route_index]
    points = route.path.sample(0.5)
    ctx = raster.context
    raster.value(code)
    ctx.set_line_width(intersection.spec.lane_width_m)
    ctx.set_line_cap(cairo.LINE_CAP_BUTT)
    ctx.set_line_join(cairo.LINE_JOIN_ROUND)
    ctx.move_to(points[0, 0], points[0, 1])
    for x, y, _ in points[1:]:
        ctx.line_to(x, y)
    ctx.stroke()


def sign_line_polygon(intersection: Intersection, lane_index: int) -> list[tuple[float, float]]:
    """The painted line across an entry lane, just before the junction edge [m]."""
    lane = intersection.lanes[lane_index]
    u = _unit(intersection.branches[lane.branch].angle_deg)
    a, b = np.array(lane.sign_line[0]), np.array(lane.sign_line[1])
    return [tuple(a), tuple(b), tuple(b + SIGN_LINE_DEPTH_M * u), tuple(a + SIGN_LINE_DEPTH_M * u)]


class ViewRenderer:
    """Renders the four semantic channels for many agents at once."""

    def __init__(self, intersection: Intersection, max_vehicles: int,
                 view_size_px: int = VIEW_SIZE_PX, view_extent_m: float = VIEW_EXTENT_M,
                 supersample: int = SUPERSAMPLE, view_shift_m: float = 0.0):
        if max_vehicles > 254:
            raise ValueError("at most 254 vehicles fit in the 8-bit label raster")
        self.intersection = intersection
        self.view_size_px = view_size_px
        self.view_extent_m = view_extent_m
        self.view_shift_m = view_shift_m  # the square's centre lies this far ahead of the car [m]
        pixels_per_m = view_size_px / view_extent_m * supersample
        # pad by the view's half diagonal (plus its shift) so that every lookup from a car on the
        # map lands inside
        pad = view_extent_m / math.sqrt(2.0) + abs(view_shift_m) + 1.0
        self._labels = WorldRaster(intersection.extent_m + pad, pixels_per_m)
        size = self._labels.size
        self.raster_size = size
        self.half_extent_m = self._labels.half_extent_m
        self.pixels_per_m = pixels_per_m

        nav = WorldRaster(intersection.extent_m + pad, pixels_per_m)
        draw_navigable(nav, intersection)
        self.navigable = nav.array().copy()
        routes = np.zeros((len(intersection.routes), size, size), dtype=np.uint8)
        for r in range(len(intersection.routes)):
            raster = WorldRaster(intersection.extent_m + pad, pixels_per_m)
            draw_route(raster, intersection, r)
            routes[r] = raster.array()
        self.routes = routes
        # one raster per (lane, sign); index lane * 3 + sign; Sign.NONE stays empty
        signs = np.zeros((len(intersection.lanes) * len(Sign), size, size), dtype=np.uint8)
        for lane in range(len(intersection.lanes)):
            for sign in (Sign.YIELD, Sign.STOP):
                raster = WorldRaster(intersection.extent_m + pad, pixels_per_m)
                raster.polygon(sign_line_polygon(intersection, lane), SIGN_CODES[sign])
                signs[lane * len(Sign) + int(sign)] = raster.array()
        self.signs = signs
        self._routes_flat = routes.reshape(-1)
        self._signs_flat = signs.reshape(-1)
        self._navigable_flat = self.navigable.reshape(-1)

        # view pixel centres in the ego frame: forward up the image, left to the image's left
        meters_per_px = view_extent_m / view_size_px
        centres = (view_size_px / 2.0 - np.arange(view_size_px) - 0.5) * meters_per_px
        forward, left = np.meshgrid(centres + view_shift_m, centres, indexing="ij")
        self._forward = forward.reshape(-1).astype(np.float32)
        self._left = left.reshape(-1).astype(np.float32)
        self.max_vehicles = max_vehicles

    # -- per step -----------------------------------------------------------------------------

    def draw_vehicles(self, x: np.ndarray, y: np.ndarray, heading: np.ndarray, labels: np.ndarray) -> None:
        """Draw every present car's footprint into the shared label raster (label = slot + 1)."""
        raster = self._labels
        ctx = raster.context
        ctx.set_source_rgba(0.0, 0.0, 0.0, 0.0)
        ctx.paint()
        if len(x) == 0:
            return
        corners = box_corners(x, y, heading, VEHICLE_LENGTH, VEHICLE_WIDTH)
        for box, label in zip(corners.tolist(), labels.tolist()):
            ctx.set_source_rgba(0.0, 0.0, 0.0, label / 255.0)
            ctx.move_to(*box[0])
            ctx.line_to(*box[1])
            ctx.line_to(*box[2])
            ctx.line_to(*box[3])
            ctx.close_path()
            ctx.fill()
        raster.surface.flush()

    def lookup_indices(self, x: np.ndarray, y: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """Flat raster index of every view pixel for every ego, [N, size*size] intp."""
        c = np.cos(heading).astype(np.float32)[:, None]
        s = np.sin(heading).astype(np.float32)[:, None]
        px = x.astype(np.float32)[:, None] + self._forward * c - self._left * s
        py = y.astype(np.float32)[:, None] + self._forward * s + self._left * c
        scale = np.float32(self.pixels_per_m)
        offset = np.float32(self.half_extent_m)
        col = ((px + offset) * scale).astype(np.intp)
        row = ((offset - py) * scale).astype(np.intp)
        last = self.raster_size - 1
        np.clip(col, 0, last, out=col)
        np.clip(row, 0, last, out=row)
        row *= self.raster_size
        row += col
        return row

    def render(self, x: np.ndarray, y: np.ndarray, heading: np.ndarray, routes: np.ndarray,
               lane_signs: np.ndarray, obstacle_shades: np.ndarray, out: np.ndarray) -> None:
        """Write the four channels of N egos into ``out`` [N, 4, size*size] uint8.

        ``routes`` [N] route indices; ``lane_signs`` [N] ``lane * 3 + sign``; ``obstacle_shades``
        [N, max_vehicles + 1] uint8: the code each car label takes in that ego's view
        (column 0, the background, must be 0). Call ``draw_vehicles`` first.
        """
        index = self.lookup_indices(x, y, heading)
        plane = self.raster_size * self.raster_size
        out[:, 0] = self._navigable_flat[index]
        out[:, 1] = self._routes_flat[index + (routes.astype(np.intp) * plane)[:, None]]
        labels = self._labels.array().reshape(-1)[index]
        rows = np.arange(len(x), dtype=np.intp)[:, None] * obstacle_shades.shape[1]
        out[:, 2] = obstacle_shades.reshape(-1)[labels + rows]
        out[:, 3] = self._signs_flat[index + (lane_signs.astype(np.intp) * plane)[:, None]]
