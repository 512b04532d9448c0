"""Pixel codes of the four semantic views: ego at the centre, heading up (paper, Fig. 2)."""

import numpy as np
import pytest

from conftest import empty_simulator, place, still, view_pixel
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator
from simcore import views

# the paper's codes, written out: "white" 255, "black" 128, nothing 0
ROAD = PATH = EGO_OR_LOWER = YIELD_LINE = 255
HIGHER_PRIORITY = STOP_LINE = 128

NEWEST = 3
NAVIGABLE, PATH_CH, OBSTACLES, SIGN = (c * 4 + NEWEST for c in range(4))
ARMS = ["east_0", "north_0", "west_0", "south_0"]  # headings west, south, east, north
PX_PER_M = 84 / 50.0


@pytest.fixture(scope="module")
def medium():
    return empty_simulator("medium")


def test_pixel_codes_are_the_papers():
    assert (views.ROAD, views.PATH, views.EGO_OR_LOWER, views.YIELD_LINE) == (255, 255, 255, 255)
    assert (views.HIGHER_PRIORITY, views.STOP_LINE) == (128, 128)
    assert views.SIGN_CODES == {Sign.NONE: 0, Sign.YIELD: 255, Sign.STOP: 128}
    assert (views.VIEW_SIZE_PX, views.VIEW_EXTENT_M) == (84, 50.0)
    assert views.CHANNELS == ("navigable", "path", "obstacles", "sign")


def view_of(sim, lane, sign=Sign.NONE, s=33.0, turn="straight"):
    sim.present[:] = False
    slot = place(sim, lane, turn, s=s, sign=sign, speed=0.0)
    result = sim.step(still(sim))
    assert result.observed[slot] and not result.terminated[slot]
    return result.views[slot]


@pytest.mark.parametrize("lane", ARMS)
def test_navigable_space(medium, lane):
    view = view_of(medium, lane)[NAVIGABLE]
    assert set(np.unique(view).tolist()) == {0, ROAD}
    assert (view[38:46, 39:45] == ROAD).all()  # the car stands on the road
    # on a straight approach the road is a vertical band of two lanes (7 m = 11.8 px)
    for row in (50, 70, 83):
        road = np.flatnonzero(view[row] == ROAD)
        assert 11 <= len(road) <= 13
        assert road.max() - road.min() + 1 == len(road)  # one band
        assert road.min() <= 41 - 2 and road.max() >= 43  # ego's lane plus the opposite lane to its left
        assert road.max() - 42 < 42 - road.min()  # right-hand traffic: more road on the left
        assert view[row, :20].max() == 0 and view[row, 70:].max() == 0  # off-road far to both sides
    # the junction ahead opens the road sideways
    assert (view[5] == ROAD).sum() > 3 * 13


def test_t_junction_has_no_road_beyond_its_far_curb():
    sim = empty_simulator("easy")
    view = view_of(sim, "south_0", s=39.0, turn="left")[NAVIGABLE]
    # the car is at y = -18.5 heading north; the far curb of the T is at y = +3.5, 22 m
    # (37 px) ahead: beyond it nothing is road, short of it the junction and the east and
    # west arms span the whole width of the view
    curb_row = 42 - 22.0 * PX_PER_M
    assert view[: int(curb_row) - 1].max() == 0
    assert (view[int(curb_row) + 2: int(curb_row) + 6] == ROAD).all()


@pytest.mark.parametrize("lane", ARMS)
def test_path_is_the_ego_lane_ahead(medium, lane):
    view = view_of(medium, lane)[PATH_CH]
    assert set(np.unique(view).tolist()) == {0, PATH}
    assert (view[:42, 41:43] == PATH).all()  # straight route: the centre column ahead of the car
    assert (view[:, 41:43] == PATH).all()  # ... and behind it, back to the start of the route
    assert view[:, 35:37].max() == 0  # the opposite lane (3.5 m to the left, column 36) is not path
    assert view[:, :36].max() == 0 and view[:, 48:].max() == 0  # lane is 3.5 m = 5.9 px wide
    width = (view[60] == PATH).sum()
    assert 5 <= width <= 7


@pytest.mark.parametrize("lane", ARMS)
@pytest.mark.parametrize("turn, side", [("left", -1), ("right", +1)])
def test_turning_path_bends_the_right_way(medium, lane, turn, side):
    """Left is left in the image: a mirrored view would swap these."""
    view = view_of(medium, lane, s=36.0, turn=turn)[PATH_CH]
    top = np.argwhere(view[:12] == PATH)
    assert len(top) > 0
    assert side * (top[:, 1].mean() - 42) > 8  # far to that side near the top of the view
    assert (view[42:, 41:43] == PATH).all()  # still straight behind the car


@pytest.mark.parametrize("lane", ARMS)
def test_obstacles_show_the_ego_at_the_centre_heading_up(medium, lane):
    view = view_of(medium, lane)[OBSTACLES]
    assert set(np.unique(view).tolist()) == {0, EGO_OR_LOWER}
    ego = np.argwhere(view == EGO_OR_LOWER)
    rows, cols = ego[:, 0], ego[:, 1]
    assert rows.min() < 42 <= rows.max() and cols.min() < 42 <= cols.max()  # covers the centre
    assert (view[39:45, 41:43] == EGO_OR_LOWER).all()
    assert rows.max() - rows.min() > 2 * (cols.max() - cols.min())  # long axis vertical: heading up
    # 4.5 m x 1.8 m = 7.6 x 3.0 px, centred
    assert 7 <= rows.max() - rows.min() + 1 <= 9 and 3 <= cols.max() - cols.min() + 1 <= 4
    assert abs((rows.min() + rows.max() + 1) / 2 - 42) <= 1 and abs((cols.min() + cols.max() + 1) / 2 - 42) <= 1


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
    assert (view[bar[:, 0].min():bar[:, 0].max() + 1, 41:43] == code).all()  # a solid bar


@pytest.mark.parametrize("lane", ARMS)
def test_no_sign_draws_nothing(medium, lane):
    assert view_of(medium, lane, sign=Sign.NONE)[SIGN].max() == 0


def test_sign_line_moves_down_as_the_car_approaches(medium):
    far = np.argwhere(view_of(medium, "south_0", sign=Sign.STOP, s=25.0)[SIGN] == STOP_LINE)[:, 0].mean()
    near = np.argwhere(view_of(medium, "south_0", sign=Sign.STOP, s=35.0)[SIGN] == STOP_LINE)[:, 0].mean()
    assert near - far == pytest.approx(10.0 * PX_PER_M, abs=1.5)


def test_every_car_has_its_priority_shade_in_every_view():
    """Eight cars in hard: at each other car's centre each view shows 128 when that car has
    priority over the ego (``Simulator.priorities``), 255 otherwise; codes stay in {0, 128, 255}."""
    sim = empty_simulator("hard")
    signs = {"east": Sign.NONE, "north": Sign.YIELD, "west": Sign.STOP, "south": Sign.YIELD}
    for k, lane in enumerate(sim.slot_names):
        turn = "left" if lane.endswith("_0") else "straight"
        place(sim, lane, turn, s=39.0 + 0.5 * k, sign=signs[lane[:-2]], speed=3.0)
    result = sim.step(still(sim))
    assert not result.terminated.any() and result.observed.all()
    idx = np.flatnonzero(sim.present)
    higher = sim.priorities(idx)
    assert higher.any() and not higher.all()
    seen = {EGO_OR_LOWER: 0, HIGHER_PRIORITY: 0}
    for a, ego in enumerate(idx):
        view = result.views[ego, OBSTACLES]
        for channel in (OBSTACLES, SIGN):
            assert set(np.unique(result.views[ego, channel]).tolist()) <= {0, 128, 255}
        assert set(np.unique(result.views[ego, NAVIGABLE]).tolist()) <= {0, 255}
        assert set(np.unique(result.views[ego, PATH_CH]).tolist()) <= {0, 255}
        assert (view[40:44, 41:43] == EGO_OR_LOWER).all()
        for b, other in enumerate(idx):
            row, col = view_pixel(sim, ego, sim.x[other], sim.y[other])
            if not (1 <= row < 83 and 1 <= col < 83):
                continue
            expected = HIGHER_PRIORITY if higher[a, b] else EGO_OR_LOWER
            wrong = EGO_OR_LOWER if higher[a, b] else HIGHER_PRIORITY
            where = (sim.slot_names[ego], sim.slot_names[other])
            assert view[row, col] == expected, where
            assert not (view[row - 1:row + 2, col - 1:col + 2] == wrong).any(), where
            seen[expected] += a != b
        if not higher[a].any():
            assert (view == HIGHER_PRIORITY).sum() == 0  # nobody outranks this ego: no black at all
    assert seen[HIGHER_PRIORITY] >= 5 and seen[EGO_OR_LOWER] >= 10


def test_a_new_episode_fills_all_four_frames_with_its_first_view():
    sim = Simulator("easy", SimConfig(), seed=3)
    result = sim.reset()
    assert result.started.all()
    for slot in range(sim.num_slots):
        frames = result.views[slot].reshape(4, 4, 84, 84)
        for c in range(4):
            assert all(np.array_equal(frames[c, k], frames[c, 3]) for k in range(3))
        assert frames[0, 3].max() == ROAD and frames[2, 3, 40:44, 41:43].min() == EGO_OR_LOWER


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


def test_a_scenarios_views_table_widens_and_shifts_the_square():
    """70 m at 84 px (0.83 m per pixel), centred 15 m ahead: the ego sits 18 px below the image
    centre, and a car 40 m straight ahead, beyond the paper's 25 m, comes into view 12 px from the top."""
    from dataclasses import replace

    from conftest import EMPTY_ROAD
    from simcore.controller import view_sight
    from simcore.scenario import ViewSpec, load_scenario

    def obstacles_of_the_ego(spec):
        sim = Simulator(spec, EMPTY_ROAD, seed=0)
        sim.reset()
        ego = place(sim, "south_1", "straight", s=10.0, sign=0, speed=5.0)
        other = place(sim, "north_1", "straight", s=10.0, sign=0, speed=5.0)
        # move the other car 40 m straight ahead of the ego, on its axis, facing it
        h = sim.heading[ego]
        sim.x[other], sim.y[other] = sim.x[ego] + 40.0 * np.cos(h), sim.y[ego] + 40.0 * np.sin(h)
        sim.heading[other] = h + np.pi
        result = sim.step(still(sim))
        return sim, result.views[ego].reshape(4, 4, 84, 84)[2, -1]

    def centre_row(mask):
        return np.nonzero(mask)[0].mean()

    hard = load_scenario("hard")
    _, paper = obstacles_of_the_ego(hard)
    assert abs(centre_row(paper > 0) - 41.5) < 1.5  # the ego alone, at the centre
    sim, shifted = obstacles_of_the_ego(replace(hard, views=ViewSpec(extent_m=70.0, shift_m=15.0)))
    metres_per_px = 70.0 / 84.0
    top, bottom = shifted[:42] > 0, shifted[42:] > 0
    assert abs(42 + centre_row(bottom) - (41.5 + 15.0 / metres_per_px)) < 1.5  # the ego, 18 px down
    assert abs(centre_row(top) - (41.5 - (40.0 - 15.0) / metres_per_px)) < 1.5  # the other car, row 11.5
    assert 4 <= top.sum() <= 15  # 4.5 x 1.8 m at 0.83 m per pixel: about 5 x 2 px
    assert view_sight(sim) == {"sight_m": 35.0, "sight_shift_m": 15.0}
