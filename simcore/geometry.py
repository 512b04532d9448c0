"""Lane geometry: straight segments, circular arcs and the paths built from them.

World frame: x east, y north, metres; headings in radians, counter-clockwise from +x.
Every geometry answers the same four primitives (after HighwayEnv's ``AbstractLane``):

- ``position(s, r)``: world point at arc length ``s`` [m] and lateral offset ``r`` [m]
  (positive to the left of the direction of travel);
- ``local_coordinates(xy)``: the inverse, ``(s, r)``;
- ``heading_at(s)``: direction of travel [rad];
- ``width_at(s)``: drivable width [m].

Everything else (on-path tests, distance to the centre line) is built on these.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_to_pi(angle: float) -> float:
    """Wrap an angle [rad] to [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


@dataclass(frozen=True)
class StraightLane:
    """A straight segment from ``start`` to ``end`` [m] of constant ``width`` [m]."""

    start: tuple[float, float]
    end: tuple[float, float]
    width: float

    def __post_init__(self) -> None:
        dx, dy = self.end[0] - self.start[0], self.end[1] - self.start[1]
        length = math.hypot(dx, dy)
        if length <= 0.0:
            raise ValueError("StraightLane needs distinct start and end points")
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "_dir", (dx / length, dy / length))
        object.__setattr__(self, "_heading", math.atan2(dy, dx))

    length: float = field(init=False)

    def position(self, s: float, r: float) -> tuple[float, float]:
        dx, dy = self._dir
        # normal to the left of travel: (-dy, dx)
        return (self.start[0] + s * dx - r * dy, self.start[1] + s * dy + r * dx)

    def local_coordinates(self, xy: tuple[float, float]) -> tuple[float, float]:
        dx, dy = self._dir
        px, py = xy[0] - self.start[0], xy[1] - self.start[1]
        return (px * dx + py * dy, -px * dy + py * dx)

    def heading_at(self, s: float) -> float:
        return self._heading

    def width_at(self, s: float) -> float:
        return self.width


@dataclass(frozen=True)
class CircularLane:
    """An arc around ``center`` [m] of ``radius`` [m], from ``start_phase`` to ``end_phase`` [rad].

    ``clockwise`` is the direction of travel. Phases are the polar angles of the arc's end
    points seen from the centre.
    """

    center: tuple[float, float]
    radius: float
    start_phase: float
    end_phase: float
    clockwise: bool
    width: float

    length: float = field(init=False)

    def __post_init__(self) -> None:
        if self.radius <= 0.0:
            raise ValueError("CircularLane needs a positive radius")
        sweep = self.end_phase - self.start_phase
        if sweep == 0.0 or (sweep > 0.0) == self.clockwise:
            raise ValueError("CircularLane phases disagree with its direction of travel")
        object.__setattr__(self, "length", abs(sweep) * self.radius)
        object.__setattr__(self, "_direction", -1.0 if self.clockwise else 1.0)
        object.__setattr__(self, "_mid_phase", 0.5 * (self.start_phase + self.end_phase))

    def position(self, s: float, r: float) -> tuple[float, float]:
        d = self._direction
        phi = self.start_phase + d * s / self.radius
        # counter-clockwise travel has the centre on its left: a left offset shrinks the radius
        rho = self.radius - d * r
        return (self.center[0] + rho * math.cos(phi), self.center[1] + rho * math.sin(phi))

    def local_coordinates(self, xy: tuple[float, float]) -> tuple[float, float]:
        d = self._direction
        px, py = xy[0] - self.center[0], xy[1] - self.center[1]
        phi = math.atan2(py, px)
        # measured from the arc's middle so that points past either end give s < 0 or s > length
        dphi = wrap_to_pi(phi - self._mid_phase)
        s = 0.5 * self.length + d * dphi * self.radius
        r = d * (self.radius - math.hypot(px, py))
        return (s, r)

    def heading_at(self, s: float) -> float:
        d = self._direction
        return self.start_phase + d * s / self.radius + d * 0.5 * math.pi

    def width_at(self, s: float) -> float:
        return self.width


LaneGeometry = StraightLane | CircularLane


@dataclass(frozen=True)
class Path:
    """A centre line made of consecutive lane geometries, travelled from the first to the last.

    ``segments`` must join end to start (checked to 1 cm).
    """

    segments: tuple[LaneGeometry, ...]

    length: float = field(init=False)
    offsets: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        if not self.segments:
            raise ValueError("a Path needs at least one segment")
        offsets = [0.0]
        for previous, nxt in zip(self.segments, self.segments[1:]):
            end = previous.position(previous.length, 0.0)
            start = nxt.position(0.0, 0.0)
            if math.hypot(end[0] - start[0], end[1] - start[1]) > 0.01:
                raise ValueError(f"path segments do not join: {end} -> {start}")
            offsets.append(offsets[-1] + previous.length)
        object.__setattr__(self, "offsets", tuple(offsets))
        object.__setattr__(self, "length", offsets[-1] + self.segments[-1].length)

    def _segment_at(self, s: float) -> tuple[LaneGeometry, float]:
        index = max(0, bisect.bisect_right(self.offsets, s) - 1)
        return self.segments[index], s - self.offsets[index]

    def position(self, s: float, r: float) -> tuple[float, float]:
        segment, local_s = self._segment_at(s)
        return segment.position(local_s, r)

    def heading_at(self, s: float) -> float:
        segment, local_s = self._segment_at(s)
        return segment.heading_at(local_s)

    def width_at(self, s: float) -> float:
        segment, local_s = self._segment_at(s)
        return segment.width_at(local_s)

    def local_coordinates(self, xy: tuple[float, float]) -> tuple[float, float]:
        """Project onto the nearest segment; before the first or past the last, extrapolate."""
        best: tuple[float, float] | None = None
        best_score = math.inf
        last = len(self.segments) - 1
        for index, segment in enumerate(self.segments):
            s, r = segment.local_coordinates(xy)
            inside = (s >= 0.0 or index == 0) and (s <= segment.length or index == last)
            if inside and abs(r) < best_score:
                best_score = abs(r)
                best = (self.offsets[index] + s, r)
        if best is None:  # in the gap outside a convex joint: the joint itself is nearest
            distances = [
                (math.dist(xy, seg.position(seg.length, 0.0)), i) for i, seg in enumerate(self.segments)
            ]
            _, index = min(distances)
            segment = self.segments[index]
            s, r = segment.local_coordinates(xy)
            best = (self.offsets[index] + min(max(s, 0.0), segment.length), r)
        return best

    def sample(self, step: float = 0.5) -> np.ndarray:
        """Centre-line points every ``step`` metres (end included), shape [N, 3]: x, y, heading."""
        count = max(2, int(math.ceil(self.length / step)) + 1)
        out = np.empty((count, 3))
        for i, s in enumerate(np.linspace(0.0, self.length, count)):
            out[i, 0:2] = self.position(float(s), 0.0)
            out[i, 2] = self.heading_at(float(s))
        return out


def fillet_path(
    entry_start: tuple[float, float],
    junction_entry: tuple[float, float],
    junction_exit: tuple[float, float],
    exit_end: tuple[float, float],
    width: float,
) -> Path:
    """Straight approach, tangent circular arc, straight exit: a road fillet through a junction.

    The approach runs from ``entry_start`` through ``junction_entry``; the exit runs from
    ``junction_exit`` to ``exit_end``. The arc is the largest one tangent to both lines that
    stays between ``junction_entry`` and ``junction_exit``; the longer leg keeps a straight
    piece. Collinear lines give a single straight segment.
    """
    entry_heading = math.atan2(junction_entry[1] - entry_start[1], junction_entry[0] - entry_start[0])
    exit_heading = math.atan2(exit_end[1] - junction_exit[1], exit_end[0] - junction_exit[0])
    c0, s0 = math.cos(entry_heading), math.sin(entry_heading)
    c1, s1 = math.cos(exit_heading), math.sin(exit_heading)
    cross = c0 * s1 - s0 * c1
    if abs(cross) < 1e-9:
        if c0 * c1 + s0 * s1 < 0.0:
            raise ValueError("a path cannot reverse its direction")
        return Path((StraightLane(entry_start, exit_end, width),))
    # intersection X = junction_entry + a * d0 = junction_exit - b * d1
    rx, ry = junction_exit[0] - junction_entry[0], junction_exit[1] - junction_entry[1]
    a = (rx * s1 - ry * c1) / cross
    b = (ry * c0 - rx * s0) / cross
    if a <= 0.0 or b <= 0.0:
        raise ValueError("the approach and exit lines do not meet inside the junction")
    turn = wrap_to_pi(exit_heading - entry_heading)
    tangent = min(a, b)
    radius = tangent / math.tan(abs(turn) / 2.0)
    ix, iy = junction_entry[0] + a * c0, junction_entry[1] + a * s0
    arc_start = (ix - tangent * c0, iy - tangent * s0)
    arc_end = (ix + tangent * c1, iy + tangent * s1)
    left_turn = turn > 0.0
    # the centre lies on the inside of the turn, perpendicular to the approach at the arc start
    side = 1.0 if left_turn else -1.0
    center = (arc_start[0] - side * radius * s0, arc_start[1] + side * radius * c0)
    start_phase = math.atan2(arc_start[1] - center[1], arc_start[0] - center[0])
    end_phase = start_phase + turn
    segments: list[LaneGeometry] = []
    if math.dist(entry_start, arc_start) > 1e-6:
        segments.append(StraightLane(entry_start, arc_start, width))
    segments.append(CircularLane(center, radius, start_phase, end_phase, not left_turn, width))
    if math.dist(arc_end, exit_end) > 1e-6:
        segments.append(StraightLane(arc_end, exit_end, width))
    return Path(tuple(segments))
