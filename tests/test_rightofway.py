"""Right of way: the priority table for every sign pair, priority to the right, conflicts."""

import itertools

import numpy as np
import pytest

from conftest import place, route_index, still
from simcore.dynamics import VEHICLE_LENGTH
from simcore.rightofway import (
    SIGN_RANK,
    Sign,
    build_priority_table,
    draw_signs,
    is_right_of,
    redraw_one_sign,
    sign_outranks,
)
from simcore.scenario import build_intersection, load_scenario
from simcore.views import EGO_OR_LOWER, HIGHER_PRIORITY


@pytest.fixture(scope="module")
def medium():
    intersection = build_intersection(load_scenario("medium"))
    return intersection, build_priority_table(intersection)


def route(intersection, lane, turn):
    entry = next(l for l in intersection.lanes if l.name == lane)
    return next(r for r in entry.routes if intersection.routes[r].turn == turn)


def test_sign_order_is_none_over_yield_over_stop():
    assert sign_outranks(Sign.NONE, Sign.YIELD) and sign_outranks(Sign.YIELD, Sign.STOP)
    assert sign_outranks(Sign.NONE, Sign.STOP)
    assert not sign_outranks(Sign.STOP, Sign.YIELD) and not sign_outranks(Sign.YIELD, Sign.YIELD)
    assert list(SIGN_RANK) == [2, 1, 0]


def test_right_arm_geometry():
    assert is_right_of(270.0, 0.0)  # entering from the south, the east arm is on the right
    assert not is_right_of(0.0, 270.0)
    assert not is_right_of(270.0, 90.0)  # opposite


@pytest.mark.parametrize("sign_south, sign_east", list(itertools.product(Sign, Sign)))
def test_priority_table_for_every_sign_pair(medium, sign_south, sign_east):
    intersection, table = medium
    south = route(intersection, "south_0", "straight")  # northbound
    east = route(intersection, "east_0", "straight")  # westbound, coming from the south car's right
    assert table.conflict[south, east] and table.conflict[east, south]
    higher = table.higher(np.array([south, east]), np.array([20.0, 20.0]), np.array([sign_south, sign_east]))
    east_first = SIGN_RANK[sign_east] > SIGN_RANK[sign_south] or sign_east == sign_south  # right wins ties
    assert higher[0, 1] == east_first  # east has priority over the south (ego) car
    assert higher[1, 0] == (not east_first)  # exactly one of the two has priority
    assert not higher[0, 0] and not higher[1, 1]


def test_priority_to_the_right_with_equal_signs_for_all_arms(medium):
    intersection, table = medium
    arms = ["east_0", "north_0", "west_0", "south_0"]
    for ego, other in itertools.permutations(arms, 2):
        a, b = route(intersection, ego, "straight"), route(intersection, other, "straight")
        if not table.conflict[a, b]:
            continue  # opposite straight routes do not cross
        higher = table.higher(np.array([a, b]), np.array([20.0, 20.0]), np.array([Sign.YIELD, Sign.YIELD]))
        ego_angle = intersection.branches[intersection.lanes[intersection.routes[a].entry_lane].branch].angle_deg
        other_angle = intersection.branches[intersection.lanes[intersection.routes[b].entry_lane].branch].angle_deg
        assert higher[0, 1] == is_right_of(ego_angle, other_angle), (ego, other)


def test_exactly_one_has_priority_for_every_conflicting_pair():
    for name in ("easy", "medium", "hard"):
        intersection = build_intersection(load_scenario(name))
        table = build_priority_table(intersection)
        count = len(intersection.routes)
        for a, b in itertools.combinations(range(count), 2):
            if not table.conflict[a, b]:
                continue
            for sa, sb in itertools.product(Sign, Sign):
                higher = table.higher(np.array([a, b]), np.array([10.0, 10.0]), np.array([sa, sb]))
                assert higher[0, 1] != higher[1, 0], (name, a, b, sa, sb)


def test_opposite_left_turn_yields_to_oncoming_car(medium):
    intersection, table = medium
    left = route(intersection, "south_0", "left")
    oncoming = route(intersection, "north_0", "straight")
    assert table.conflict[left, oncoming]
    higher = table.higher(np.array([left, oncoming]), np.array([20.0, 20.0]), np.array([Sign.NONE, Sign.NONE]))
    assert higher[0, 1] and not higher[1, 0]


def test_opposite_left_turns_do_not_conflict(medium):
    intersection, table = medium
    assert not table.conflict[route(intersection, "south_0", "left"), route(intersection, "north_0", "left")]


def test_cleared_cars_and_non_conflicting_cars_are_not_ranked(medium):
    intersection, table = medium
    south = route(intersection, "south_0", "straight")
    east = route(intersection, "east_0", "straight")
    routes = np.array([south, east])
    signs = np.array([Sign.STOP, Sign.NONE])
    past = table.zone_end[east, south] + 0.5 * VEHICLE_LENGTH + 0.1
    assert table.higher(routes, np.array([20.0, past - 0.2]), signs)[0, 1]
    assert not table.higher(routes, np.array([20.0, past]), signs)[0, 1]  # east car has cleared
    ego_past = table.zone_end[south, east] + 0.5 * VEHICLE_LENGTH + 0.1
    assert not table.higher(routes, np.array([ego_past, 20.0]), signs)[0, 1]  # ego has cleared
    # a right turn from the south and the west car's straight route never meet
    right = route(intersection, "south_0", "right")
    west = route(intersection, "west_0", "right")
    assert not table.conflict[right, west]
    assert not table.higher(np.array([right, west]), np.array([20.0, 20.0]), np.array([Sign.STOP, Sign.NONE])).any()


def test_after_a_merge_the_car_ahead_has_priority(medium):
    intersection, table = medium
    right = route(intersection, "south_0", "right")  # south -> east exit
    straight = route(intersection, "west_0", "straight")  # west -> east exit
    assert not np.isnan(table.merge_at[right, straight])
    routes = np.array([right, straight])
    signs = np.array([Sign.NONE, Sign.STOP])  # by signs the right-turning car would win
    merged_right = table.merge_at[right, straight] + VEHICLE_LENGTH + 5.0
    merged_straight = table.merge_at[straight, right] + VEHICLE_LENGTH + 15.0  # 10 m further along
    higher = table.higher(routes, np.array([merged_right, merged_straight]), signs)
    assert higher[0, 1] and not higher[1, 0]  # the stop-sign car is ahead: it leads


def test_random_signs_are_never_all_equal():
    rng = np.random.default_rng(0)
    for count in (3, 4):
        for _ in range(500):
            signs = draw_signs(rng, count)
            assert len(set(signs.tolist())) > 1
    signs = np.array([Sign.STOP, Sign.STOP, Sign.STOP, Sign.NONE], dtype=np.int8)
    for _ in range(200):
        signs[3] = redraw_one_sign(rng, signs, 3)
        assert signs[3] != Sign.STOP


def test_yield_car_sees_main_road_car_as_higher_priority(medium_road):
    """Behaviour: the obstacle view encodes who goes first (paper, Fig. 2d)."""
    sim = medium_road
    yield_car = place(sim, "south_0", "straight", s=38.0, sign=Sign.YIELD, speed=5.0)
    main_car = place(sim, "east_0", "straight", s=38.0, sign=Sign.NONE, speed=5.0)
    result = sim.step(still(sim))
    assert result.observed[[yield_car, main_car]].all()
    newest_obstacles = 2 * 4 + 3
    yield_view = result.views[yield_car, newest_obstacles]
    main_view = result.views[main_car, newest_obstacles]
    assert yield_view[40:44, 41:43].min() == EGO_OR_LOWER  # itself, white
    assert (yield_view == HIGHER_PRIORITY).sum() > 10  # the main-road car, black
    assert main_view[40:44, 41:43].min() == EGO_OR_LOWER
    assert (main_view == HIGHER_PRIORITY).sum() == 0  # nobody outranks the main road
    assert (main_view == EGO_OR_LOWER).sum() > 2 * (main_view[40:44, 41:43] == EGO_OR_LOWER).sum()


def test_route_index_helper_matches_table(medium_road):
    assert route_index(medium_road, "south_0", "left") == route(medium_road.intersection, "south_0", "left")
