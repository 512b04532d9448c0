"""Lane geometry: position and local coordinates are inverse, headings match the curve,
fillets meet their inputs and the built-in routes are continuous."""

import math

import numpy as np
import pytest

from simcore.geometry import CircularLane, Path, StraightLane, fillet_path, wrap_to_pi
from simcore.scenario import BUILTIN_SCENARIOS, build_intersection, load_scenario

WIDTH = 3.5
LANES = [
    StraightLane((0.0, 0.0), (30.0, 10.0), WIDTH),
    StraightLane((5.0, -2.0), (-20.0, -2.0), WIDTH),
    CircularLane((1.0, 2.0), 15.0, 0.2, 1.6, clockwise=False, width=WIDTH),
    CircularLane((-3.0, 4.0), 20.0, 2.0, 0.5, clockwise=True, width=WIDTH),
    # arcs across the -pi/pi seam of atan2, both directions, and phases outside [-pi, pi)
    CircularLane((0.0, 0.0), 10.0, 2.8, 3.6, clockwise=False, width=WIDTH),
    CircularLane((0.0, 0.0), 10.0, -2.8, -3.6, clockwise=True, width=WIDTH),
    CircularLane((4.0, -1.0), 16.0, 5.0, 6.5, clockwise=False, width=WIDTH),
    CircularLane((0.0, 0.0), 30.0, 0.1, -1.4, clockwise=True, width=WIDTH),
]
LANE_IDS = [f"{type(l).__name__}{'-cw' if getattr(l, 'clockwise', False) else ''}{i}" for i, l in enumerate(LANES)]
OFFSETS = np.linspace(-0.49 * WIDTH, 0.49 * WIDTH, 7)  # |r| < width / 2


def angle_diff(a, b):
    return math.remainder(a - b, 2 * math.pi)


@pytest.fixture(scope="module")
def routes():
    """Every route of every built-in scenario, as (scenario, route)."""
    out = []
    for name in BUILTIN_SCENARIOS:
        out += [(name, route) for route in build_intersection(load_scenario(name)).routes]
    return out


@pytest.mark.parametrize("lane", LANES, ids=LANE_IDS)
def test_local_coordinates_invert_position(lane):
    for s in np.linspace(0.0, lane.length, 17):
        for r in OFFSETS:
            s2, r2 = lane.local_coordinates(lane.position(s, r))
            assert s2 == pytest.approx(s, abs=1e-9), (s, r)
            assert r2 == pytest.approx(r, abs=1e-9), (s, r)


@pytest.mark.parametrize("lane", LANES, ids=LANE_IDS)
def test_heading_follows_the_centre_line_and_left_is_positive(lane):
    for s in np.linspace(0.1, lane.length - 0.1, 9):
        (x0, y0), (x1, y1) = lane.position(s - 1e-4, 0.0), lane.position(s + 1e-4, 0.0)
        direction = math.atan2(y1 - y0, x1 - x0)
        assert angle_diff(direction, lane.heading_at(s)) == pytest.approx(0.0, abs=1e-6)
        # a positive lateral offset lies to the left of the direction of travel
        (xl, yl), (xc, yc) = lane.position(s, 1.0), lane.position(s, 0.0)
        h = lane.heading_at(s)
        cross = math.cos(h) * (yl - yc) - math.sin(h) * (xl - xc)
        assert cross == pytest.approx(1.0, abs=1e-9)
        assert lane.width_at(s) == WIDTH


def test_circular_lane_length_and_end_points():
    ccw = CircularLane((1.0, 2.0), 15.0, 0.2, 1.6, clockwise=False, width=WIDTH)
    assert ccw.length == pytest.approx(1.4 * 15.0)
    assert ccw.position(0.0, 0.0) == pytest.approx((1.0 + 15 * math.cos(0.2), 2.0 + 15 * math.sin(0.2)))
    assert ccw.position(ccw.length, 0.0) == pytest.approx((1.0 + 15 * math.cos(1.6), 2.0 + 15 * math.sin(1.6)))
    # counter-clockwise travel has the centre on the left: a left offset is nearer the centre
    assert math.dist(ccw.position(3.0, 1.0), ccw.center) == pytest.approx(14.0)
    cw = CircularLane((0.0, 0.0), 10.0, 0.5, -0.5, clockwise=True, width=WIDTH)
    assert math.dist(cw.position(3.0, 1.0), cw.center) == pytest.approx(11.0)
    # points before the start / past the end of an arc get s < 0 / s > length
    assert cw.local_coordinates(cw.position(-2.0, 0.0))[0] == pytest.approx(-2.0)
    assert cw.local_coordinates(cw.position(cw.length + 2.0, 0.0))[0] == pytest.approx(cw.length + 2.0)


def test_path_segments_join_and_round_trip(routes):
    for name, route in routes:
        path = route.path
        assert path.length == pytest.approx(sum(seg.length for seg in path.segments))
        for s in np.linspace(0.0, path.length, 41):
            for r in (-1.7, -0.8, 0.0, 0.8, 1.7):  # |r| < 3.5 / 2
                s2, r2 = path.local_coordinates(path.position(s, r))
                assert s2 == pytest.approx(s, abs=1e-6), (name, route.turn, s, r)
                assert r2 == pytest.approx(r, abs=1e-6), (name, route.turn, s, r)


def test_path_heading_matches_finite_differences(routes):
    for name, route in routes:
        path = route.path
        for s in np.linspace(0.05, path.length - 0.05, 60):
            (x0, y0), (x1, y1) = path.position(s - 1e-3, 0.0), path.position(s + 1e-3, 0.0)
            direction = math.atan2(y1 - y0, x1 - x0)
            # at a joint the two sides share the tangent, so this holds there too
            assert angle_diff(direction, path.heading_at(s)) == pytest.approx(0.0, abs=1e-4), (name, route.turn, s)


def test_route_segments_join_continuously(routes):
    for name, route in routes:
        segments = route.path.segments
        assert [type(s).__name__ for s in segments][1::2] in ([], ["CircularLane"]), (name, route.turn)
        for previous, nxt in zip(segments, segments[1:]):
            end, start = previous.position(previous.length, 0.0), nxt.position(0.0, 0.0)
            assert math.dist(end, start) < 1e-6, (name, route.turn)
            assert angle_diff(previous.heading_at(previous.length), nxt.heading_at(0.0)) == pytest.approx(0.0, abs=1e-9)
        headings = route.path.sample(0.25)[:, 2]
        assert np.abs(np.diff(np.unwrap(headings))).max() < 0.05
        # a route turns by the amount its name says
        turned = angle_diff(route.path.heading_at(route.path.length), route.path.heading_at(0.0))
        expected = {"left": math.pi / 2, "straight": 0.0, "right": -math.pi / 2}[route.turn]
        assert turned == pytest.approx(expected, abs=1e-9), (name, route.turn)


def test_fillet_path_meets_its_inputs():
    start, entry, leave, end = (1.75, -57.5), (1.75, -17.5), (17.5, -1.75), (47.5, -1.75)
    path = fillet_path(start, entry, leave, end, 3.5)
    assert [type(s).__name__ for s in path.segments] == ["StraightLane", "CircularLane", "StraightLane"]
    assert path.position(0.0, 0.0) == pytest.approx(start)
    assert path.position(path.length, 0.0) == pytest.approx(end)
    assert path.heading_at(0.0) == pytest.approx(math.pi / 2)
    assert angle_diff(path.heading_at(path.length), 0.0) == pytest.approx(0.0, abs=1e-9)
    assert path.segments[1].radius == pytest.approx(15.75)  # a right turn 1.75 m inside a 14 m curb
    assert path.segments[1].clockwise  # right turn


@pytest.mark.parametrize("exit_deg", [0, 60, 120, 150, 210, 240, 300])
def test_fillet_path_end_points_and_headings_for_any_angle(exit_deg):
    """Northbound approach to the origin, exit along ``exit_deg`` out of the junction."""
    a = math.radians(exit_deg)
    start, entry = (0.0, -60.0), (0.0, -20.0)
    leave, end = (20.0 * math.cos(a), 20.0 * math.sin(a)), (60.0 * math.cos(a), 60.0 * math.sin(a))
    path = fillet_path(start, entry, leave, end, WIDTH)
    assert path.position(0.0, 0.0) == pytest.approx(start, abs=1e-9)
    assert path.position(path.length, 0.0) == pytest.approx(end, abs=1e-9)
    assert angle_diff(path.heading_at(0.0), math.pi / 2) == pytest.approx(0.0, abs=1e-9)
    assert angle_diff(path.heading_at(path.length), a) == pytest.approx(0.0, abs=1e-9)
    arc = next(s for s in path.segments if isinstance(s, CircularLane))
    assert arc.clockwise == (wrap_to_pi(a - math.pi / 2) < 0)  # right turns run clockwise
    # the arc stays between the junction edge points: it starts past ``entry`` and ends before ``leave``
    arc_start = arc.position(0.0, 0.0)
    arc_end = arc.position(arc.length, 0.0)
    assert arc_start[1] >= entry[1] - 1e-9
    assert math.dist(arc_end, (0.0, 0.0)) <= math.dist(leave, (0.0, 0.0)) + 1e-9
    # the route passes through the junction-edge points on its centre line
    for point in (entry, leave):
        s, r = path.local_coordinates(point)
        assert abs(r) < 1e-6 and 0.0 < s < path.length


@pytest.mark.parametrize("entry_d, exit_d", [(10.0, 25.0), (25.0, 10.0)])
def test_fillet_arc_fits_the_shorter_leg_and_the_longer_leg_keeps_a_straight(entry_d, exit_d):
    """Lines meet at the origin, the junction edge is ``entry_d`` before and ``exit_d`` after it:
    the arc is tangent at the nearer edge point, so its radius is the shorter distance."""
    start, entry = (0.0, -entry_d - 40.0), (0.0, -entry_d)
    leave, end = (exit_d, 0.0), (exit_d + 30.0, 0.0)
    path = fillet_path(start, entry, leave, end, WIDTH)
    arc = next(s for s in path.segments if isinstance(s, CircularLane))
    shorter = min(entry_d, exit_d)
    assert arc.radius == pytest.approx(shorter)  # a right-angle turn: radius = tangent length
    assert arc.position(0.0, 0.0) == pytest.approx((0.0, -shorter))
    assert arc.position(arc.length, 0.0) == pytest.approx((shorter, 0.0))
    assert path.length == pytest.approx(40.0 + entry_d - shorter + 0.5 * math.pi * shorter + exit_d - shorter + 30.0)
    assert path.position(path.length, 0.0) == pytest.approx(end)


def test_fillet_path_collinear_is_straight_and_reversal_is_refused():
    path = fillet_path((0, 0), (0, 10), (0, 20), (0, 30), 3.5)
    assert len(path.segments) == 1 and path.length == pytest.approx(30.0)
    with pytest.raises(ValueError, match="reverse"):
        fillet_path((0, 0), (0, 10), (0, 5), (0, -10), 3.5)
    with pytest.raises(ValueError, match="do not meet"):
        fillet_path((0, 0), (0, 10), (-5, 5), (-10, 5), 3.5)  # the exit starts behind the approach


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError, match="distinct"):
        StraightLane((1.0, 1.0), (1.0, 1.0), 3.5)
    with pytest.raises(ValueError, match="direction"):
        CircularLane((0, 0), 10.0, 0.0, 1.0, clockwise=True, width=3.5)
    with pytest.raises(ValueError, match="radius"):
        CircularLane((0, 0), 0.0, 0.0, 1.0, clockwise=False, width=3.5)
    with pytest.raises(ValueError, match="do not join"):
        Path((StraightLane((0, 0), (10, 0), 3.5), StraightLane((11, 0), (20, 0), 3.5)))
    with pytest.raises(ValueError, match="at least one"):
        Path(())


def test_path_extrapolates_past_both_ends():
    path = Path((StraightLane((0, 0), (10, 0), 3.5), StraightLane((10, 0), (10, 10), 3.5)))
    assert path.local_coordinates((-2.0, 0.5)) == pytest.approx((-2.0, 0.5))
    assert path.local_coordinates((10.3, 12.0)) == pytest.approx((22.0, -0.3))
    # outside the convex joint neither segment contains the point: the joint is nearest
    s, _ = path.local_coordinates((11.0, -1.0))
    assert s == pytest.approx(10.0)


def test_wrap_to_pi():
    assert wrap_to_pi(math.pi) == pytest.approx(-math.pi)
    assert wrap_to_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_to_pi(-7.0) == pytest.approx(-7.0 + 2 * math.pi)
