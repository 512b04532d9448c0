"""Pixel codes of the four semantic views: ego at the centre, heading up (paper, Fig. 2)."""

import numpy as np
import pytest

from conftest import empty_simulator, place, still
from simcore.rightofway import Sign
from simcore.views import EGO_OR_LOWER, PATH, ROAD, STOP_LINE, YIELD_LINE

NEWEST = 3
NAVIGABLE, PATH_CH, OBSTACLES, SIGN = (c * 4 + NEWEST for c in range(4))
ARMS = ["east_0", "north_0", "west_0", "south_0"]  # headings west, south, east, north


@pytest.fixture(scope="module")
def medium():
    return empty_simulator("medium")


def view_of(sim, lane, sign=Sign.NONE, s=33.0, turn="straight"):
    sim.present[:] = False
    slot = place(sim, lane, turn, s=s, sign=sign, speed=0.0)
    result = sim.step(still(sim))
    assert result.observed[slot]
    return result.views[slot]


@pytest.mark.parametrize("lane", ARMS)
def test_navigable_space(medium, lane):
    view = view_of(medium, lane)[NAVIGABLE]
    assert set(np.unique(view).tolist()) <= {0, ROAD}
    assert (view[38:46, 39:45] == ROAD).all()  # the car stands on the road
    # on a straight approach the road is a vertical band of two lanes (7 m = 11.8 px)
    row = view[70]
    road = np.flatnonzero(row == ROAD)
    assert 11 <= len(road) <= 13
    assert road.min() <= 41 - 2 and road.max() >= 43  # ego's lane plus the opposite lane to its left
    assert road.max() - 42 < 42 - road.min()  # right-hand traffic: more road on the left
    assert view[70, :20].max() == 0 and view[70, 70:].max() == 0  # off-road far to both sides
    # the junction ahead opens the road sideways
    assert (view[5] == ROAD).sum() > 3 * len(road)


@pytest.mark.parametrize("lane", ARMS)
def test_path_is_the_ego_lane_ahead(medium, lane):
    view = view_of(medium, lane)[PATH_CH]
    assert set(np.unique(view).tolist()) <= {0, PATH}
    assert (view[:, 41:43] == PATH).all()  # straight route: the centre columns, top to bottom
    assert view[:, :36].max() == 0 and view[:, 48:].max() == 0  # lane is 3.5 m = 5.9 px wide


@pytest.mark.parametrize("lane", ARMS)
def test_obstacles_show_the_ego_at_the_centre_heading_up(medium, lane):
    view = view_of(medium, lane)[OBSTACLES]
    ego = np.argwhere(view == EGO_OR_LOWER)
    rows, cols = ego[:, 0], ego[:, 1]
    assert rows.min() < 42 <= rows.max() and cols.min() < 42 <= cols.max()  # covers the centre
    assert rows.max() - rows.min() > 2 * (cols.max() - cols.min())  # long axis vertical: heading up
    assert set(np.unique(view).tolist()) == {0, EGO_OR_LOWER}


@pytest.mark.parametrize("lane", ARMS)
@pytest.mark.parametrize("sign, code", [(Sign.STOP, STOP_LINE), (Sign.YIELD, YIELD_LINE)])
def test_sign_line_is_a_bar_ahead(medium, lane, sign, code):
    view = view_of(medium, lane, sign=sign)[SIGN]
    assert set(np.unique(view).tolist()) == {0, code}
    bar = np.argwhere(view == code)
    # 40 m approach, car at s = 33 m: the line is 5-7 m ahead (8-12 px above the centre)
    assert 42 - 13 <= bar[:, 0].min() and bar[:, 0].max() <= 42 - 7
    assert bar[:, 1].max() - bar[:, 1].min() > bar[:, 0].max() - bar[:, 0].min()  # horizontal
    assert bar[:, 1].min() >= 38 and bar[:, 1].max() <= 46  # across the ego's lane only


def test_no_sign_draws_nothing(medium):
    assert view_of(medium, "south_0", sign=Sign.NONE)[SIGN].max() == 0


def test_history_holds_four_frames_oldest_first():
    sim = empty_simulator("medium")
    slot = place(sim, "south_0", "straight", s=10.0, speed=8.0)
    result = sim.step(still(sim))
    first = result.views[slot, PATH_CH].copy()
    for _ in range(3):
        result = sim.step(still(sim))
    frames = result.views[slot, 4:8]  # path channel, oldest to newest
    # the route starts 10 m behind the car; as the car drives on, that start slides down the view
    assert not np.array_equal(frames[0], frames[3])
    assert np.array_equal(frames[0], first)  # the oldest kept frame is the one seen 3 steps ago
    assert (frames[3] == PATH).sum() > (frames[0] == PATH).sum()  # more route behind the car now
