"""Lane geometry: position and local coordinates are inverse, headings match the curve."""

import math

import numpy as np
import pytest

from simcore.geometry import CircularLane, Path, StraightLane, fillet_path
from simcore.scenario import BUILTIN_SCENARIOS, build_intersection, load_scenario

LANES = [
    StraightLane((0.0, 0.0), (30.0, 10.0), 3.5),
    StraightLane((5.0, -2.0), (-20.0, -2.0), 3.5),
    CircularLane((1.0, 2.0), 15.0, 0.2, 1.6, clockwise=False, width=3.5),
    CircularLane((-3.0, 4.0), 20.0, 2.0, 0.5, clockwise=True, width=3.5),
]


@pytest.mark.parametrize("lane", LANES, ids=lambda l: type(l).__name__)
def test_local_coordinates_invert_position(lane):
    for s in np.linspace(0.0, lane.length, 13):
        for r in (-1.7, -0.5, 0.0, 0.9, 1.7):
            s2, r2 = lane.local_coordinates(lane.position(s, r))
            assert s2 == pytest.approx(s, abs=1e-9)
            assert r2 == pytest.approx(r, abs=1e-9)


@pytest.mark.parametrize("lane", LANES, ids=lambda l: type(l).__name__)
def test_heading_follows_the_centre_line_and_left_is_positive(lane):
    for s in np.linspace(0.1, lane.length - 0.1, 7):
        (x0, y0), (x1, y1) = lane.position(s - 1e-4, 0.0), lane.position(s + 1e-4, 0.0)
        direction = math.atan2(y1 - y0, x1 - x0)
        assert math.remainder(direction - lane.heading_at(s), 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
        # a positive lateral offset lies to the left of the direction of travel
        (xl, yl), (xc, yc) = lane.position(s, 1.0), lane.position(s, 0.0)
        h = lane.heading_at(s)
        cross = math.cos(h) * (yl - yc) - math.sin(h) * (xl - xc)
        assert cross == pytest.approx(1.0, abs=1e-9)
        assert lane.width_at(s) == 3.5


def test_path_segments_join_and_round_trip():
    for name in BUILTIN_SCENARIOS:
        intersection = build_intersection(load_scenario(name))
        for route in intersection.routes:
            path = route.path
            assert path.length == pytest.approx(sum(seg.length for seg in path.segments))
            for s in np.linspace(0.0, path.length, 41):
                for r in (-1.5, 0.0, 1.5):
                    s2, r2 = path.local_coordinates(path.position(s, r))
                    assert s2 == pytest.approx(s, abs=1e-6), (name, route.turn, s, r)
                    assert r2 == pytest.approx(r, abs=1e-6)
            # headings are continuous along the whole route
            headings = path.sample(0.25)[:, 2]
            assert np.abs(np.diff(np.unwrap(headings))).max() < 0.05


def test_fillet_path_meets_its_inputs():
    start, entry, leave, end = (1.75, -57.5), (1.75, -17.5), (17.5, -1.75), (47.5, -1.75)
    path = fillet_path(start, entry, leave, end, 3.5)
    assert [type(s).__name__ for s in path.segments] == ["StraightLane", "CircularLane", "StraightLane"]
    assert path.position(0.0, 0.0) == pytest.approx(start)
    assert path.position(path.length, 0.0) == pytest.approx(end)
    assert path.heading_at(0.0) == pytest.approx(math.pi / 2)
    assert math.remainder(path.heading_at(path.length), 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert path.segments[1].radius == pytest.approx(15.75)  # a right turn 1.75 m inside a 14 m curb


def test_fillet_path_collinear_is_straight_and_reversal_is_refused():
    path = fillet_path((0, 0), (0, 10), (0, 20), (0, 30), 3.5)
    assert len(path.segments) == 1 and path.length == pytest.approx(30.0)
    with pytest.raises(ValueError, match="reverse"):
        fillet_path((0, 0), (0, 10), (0, 5), (0, -10), 3.5)


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError, match="distinct"):
        StraightLane((1.0, 1.0), (1.0, 1.0), 3.5)
    with pytest.raises(ValueError, match="direction"):
        CircularLane((0, 0), 10.0, 0.0, 1.0, clockwise=True, width=3.5)
    with pytest.raises(ValueError, match="do not join"):
        Path((StraightLane((0, 0), (10, 0), 3.5), StraightLane((11, 0), (20, 0), 3.5)))
