"""Right of way: the priority table for every sign pair, priority to the right, conflicts,
and what the obstacle view makes of it."""

import itertools

import numpy as np
import pytest

from conftest import place, route_index, still, view_pixel
from simcore.dynamics import VEHICLE_LENGTH
from simcore.rightofway import (
    CONFLICT_DISTANCE,
    SIGN_RANK,
    Sign,
    build_priority_table,
    draw_signs,
    is_right_of,
    redraw_one_sign,
    sign_outranks,
)
from simcore.scenario import build_intersection, load_scenario

EGO_OR_LOWER, HIGHER_PRIORITY = 255, 128  # the paper's white and black

# written out independently of SIGN_RANK: none (main road) over yield over stop
ORDER = {Sign.NONE: 2, Sign.YIELD: 1, Sign.STOP: 0}
NEWEST_OBSTACLES = 2 * 4 + 3


@pytest.fixture(scope="module")
def medium():
    intersection = build_intersection(load_scenario("medium"))
    return intersection, build_priority_table(intersection)


@pytest.fixture(scope="module")
def tables():
    out = {}
    for name in ("easy", "medium", "hard"):
        intersection = build_intersection(load_scenario(name))
        out[name] = (intersection, build_priority_table(intersection))
    return out


def route(intersection, lane, turn):
    entry = next(l for l in intersection.lanes if l.name == lane)
    return next(r for r in entry.routes if intersection.routes[r].turn == turn)


def rank(table, routes, s, signs):
    return table.higher(np.asarray(routes), np.asarray(s, dtype=float), np.asarray(signs))


def test_sign_order_is_none_over_yield_over_stop():
    for a, b in itertools.product(Sign, Sign):
        assert sign_outranks(a, b) == (ORDER[a] > ORDER[b]), (a, b)
    assert [SIGN_RANK[int(s)] for s in Sign] == [ORDER[s] for s in Sign]


def test_right_arm_geometry():
    assert is_right_of(270.0, 0.0)  # entering from the south, the east arm is on the right
    assert is_right_of(0.0, 90.0)  # entering from the east, the north arm is on the right
    assert not is_right_of(0.0, 270.0)
    assert not is_right_of(270.0, 180.0)  # left
    assert not is_right_of(270.0, 90.0)  # opposite


def test_conflict_zone_of_two_crossing_straight_routes(medium):
    intersection, table = medium
    south = route(intersection, "south_0", "straight")  # x = +1.75, northbound
    east = route(intersection, "east_0", "straight")  # y = +1.75, westbound
    # the centre lines cross at (1.75, 1.75): 57.5 + 1.75 m along the south route,
    # 57.5 - 1.75 m along the east one
    for ego, other, crossing in ((south, east, 59.25), (east, south, 55.75)):
        s, r = intersection.routes[ego].path.local_coordinates((1.75, 1.75))
        assert (s, r) == pytest.approx((crossing, 0.0))
        assert table.conflict[ego, other]
        assert table.zone_start[ego, other] == pytest.approx(crossing - CONFLICT_DISTANCE, abs=0.3)
        assert table.zone_end[ego, other] == pytest.approx(crossing + CONFLICT_DISTANCE, abs=0.3)
        assert np.isnan(table.merge_at[ego, other])  # they cross, they do not merge


@pytest.mark.parametrize("sign_south, sign_east", list(itertools.product(Sign, Sign)))
def test_priority_table_for_every_sign_pair(medium, sign_south, sign_east):
    intersection, table = medium
    south = route(intersection, "south_0", "straight")  # northbound
    east = route(intersection, "east_0", "straight")  # westbound, coming from the south car's right
    assert table.conflict[south, east] and table.conflict[east, south]
    higher = rank(table, [south, east], [20.0, 20.0], [sign_south, sign_east])
    if sign_south == sign_east:
        east_first = True  # priority to the right
    else:
        east_first = ORDER[sign_east] > ORDER[sign_south]
    assert higher[0, 1] == east_first  # east has priority over the south (ego) car
    assert higher[1, 0] == (not east_first)  # exactly one of the two has priority
    assert not higher[0, 0] and not higher[1, 1]
    # the same pair listed the other way round gives the same answer
    swapped = rank(table, [east, south], [20.0, 20.0], [sign_east, sign_south])
    assert swapped[1, 0] == east_first and swapped[0, 1] == (not east_first)


def test_priority_to_the_right_with_equal_signs_for_all_arms(medium):
    intersection, table = medium
    arms = ["east_0", "north_0", "west_0", "south_0"]
    checked = 0
    for ego, other in itertools.permutations(arms, 2):
        a, b = route(intersection, ego, "straight"), route(intersection, other, "straight")
        if not table.conflict[a, b]:
            assert {ego[:-2], other[:-2]} in ({"east", "west"}, {"north", "south"})  # opposite arms
            continue
        for sign in Sign:
            higher = rank(table, [a, b], [20.0, 20.0], [sign, sign])
            ego_angle = intersection.branches[intersection.lanes[intersection.routes[a].entry_lane].branch].angle_deg
            other_angle = intersection.branches[intersection.lanes[intersection.routes[b].entry_lane].branch].angle_deg
            assert higher[0, 1] == is_right_of(ego_angle, other_angle), (ego, other)
            checked += 1
    assert checked == 8 * 3


def test_priority_to_the_right_in_the_t_junction(tables):
    intersection, table = tables["easy"]
    south_left = route(intersection, "south_0", "left")  # northbound, turning west
    east_straight = route(intersection, "east_0", "straight")  # from the south car's right
    west_straight = route(intersection, "west_0", "straight")  # from the south car's left
    higher = rank(table, [south_left, east_straight, west_straight], [20.0] * 3, [Sign.YIELD] * 3)
    assert higher[0, 1] and not higher[1, 0]  # east is on the right: it goes first
    assert higher[2, 0] and not higher[0, 2]  # the south car is on the west car's right


def test_exactly_one_has_priority_for_every_conflicting_pair(tables):
    for name, (intersection, table) in tables.items():
        count = len(intersection.routes)
        pairs = 0
        for a, b in itertools.combinations(range(count), 2):
            if not table.conflict[a, b]:
                assert not table.conflict[b, a]  # conflict is symmetric
                continue
            pairs += 1
            for sa, sb in itertools.product(Sign, Sign):
                higher = rank(table, [a, b], [10.0, 10.0], [sa, sb])
                assert higher[0, 1] != higher[1, 0], (name, a, b, sa, sb)
        assert pairs > 0


def test_non_conflicting_routes_are_never_ranked(medium):
    intersection, table = medium
    count = len(intersection.routes)
    free = [(a, b) for a, b in itertools.permutations(range(count), 2) if not table.conflict[a, b]]
    assert len(free) > 10
    a, b = np.array(free).T
    for sa, sb in itertools.product(Sign, Sign):
        for s in (10.0, 45.0, 60.0):
            for i in range(len(a)):
                higher = rank(table, [a[i], b[i]], [s, s], [sa, sb])
                assert not higher.any(), (a[i], b[i], sa, sb, s)


def test_opposite_left_turn_yields_to_oncoming_car(medium):
    intersection, table = medium
    for turn in ("straight", "right"):
        left = route(intersection, "south_0", "left")
        oncoming = route(intersection, "north_0", turn)
        assert table.conflict[left, oncoming], turn
        for sign in Sign:
            higher = rank(table, [left, oncoming], [20.0, 20.0], [sign, sign])
            assert higher[0, 1] and not higher[1, 0], (turn, sign)
        # a better sign still wins over the rule
        higher = rank(table, [left, oncoming], [20.0, 20.0], [Sign.NONE, Sign.STOP])
        assert higher[1, 0] and not higher[0, 1]


def test_opposite_left_turns_do_not_conflict(medium):
    intersection, table = medium
    assert not table.conflict[route(intersection, "south_0", "left"), route(intersection, "north_0", "left")]


def test_cleared_cars_and_non_conflicting_cars_are_not_ranked(medium):
    intersection, table = medium
    south = route(intersection, "south_0", "straight")
    east = route(intersection, "east_0", "straight")
    routes = [south, east]
    signs = [Sign.STOP, Sign.NONE]
    past = table.zone_end[east, south] + 0.5 * VEHICLE_LENGTH  # the east car's rear leaves the zone
    assert rank(table, routes, [20.0, past - 0.1], signs)[0, 1]
    assert not rank(table, routes, [20.0, past + 0.1], signs).any()  # east car has cleared
    ego_past = table.zone_end[south, east] + 0.5 * VEHICLE_LENGTH + 0.1
    assert not rank(table, routes, [ego_past, 20.0], signs).any()  # ego has cleared
    # a right turn from the south and the west car's right turn never meet
    right = route(intersection, "south_0", "right")
    west = route(intersection, "west_0", "right")
    assert not table.conflict[right, west]
    assert not rank(table, [right, west], [20.0, 20.0], [Sign.STOP, Sign.NONE]).any()


def test_after_a_merge_the_car_ahead_has_priority(medium):
    intersection, table = medium
    right = route(intersection, "south_0", "right")  # south -> east exit
    straight = route(intersection, "west_0", "straight")  # west -> east exit
    assert not np.isnan(table.merge_at[right, straight])
    routes = [right, straight]
    signs = [Sign.NONE, Sign.STOP]  # by signs the right-turning car would win
    assert rank(table, routes, [20.0, 20.0], signs)[1, 0]  # before the merge: signs decide
    merged_right = table.merge_at[right, straight] + VEHICLE_LENGTH + 5.0
    merged_straight = table.merge_at[straight, right] + VEHICLE_LENGTH + 15.0  # 10 m further along
    higher = rank(table, routes, [merged_right, merged_straight], signs)
    assert higher[0, 1] and not higher[1, 0]  # the stop-sign car is ahead: it leads
    # the other way round: the main-road car ahead keeps its priority
    higher = rank(table, routes, [merged_right + 20.0, merged_straight], signs)
    assert higher[1, 0] and not higher[0, 1]
    # a car less than a length into the shared lane has not cleared the merge zone: signs still rule
    just_merged = table.merge_at[straight, right] + 0.5 * VEHICLE_LENGTH + 0.5 * VEHICLE_LENGTH
    higher = rank(table, routes, [table.merge_at[right, straight] - 3.0, just_merged], signs)
    assert higher[1, 0] and not higher[0, 1]
    # the follower still approaching the merge yields to the car already on the shared lane
    higher = rank(table, routes, [table.merge_at[right, straight] - 3.0, merged_straight], signs)
    assert higher[0, 1] and not higher[1, 0]


def test_random_signs_are_never_all_equal():
    rng = np.random.default_rng(0)
    for count in (3, 4):
        seen = np.zeros((count, len(Sign)), dtype=int)
        for _ in range(1000):
            signs = draw_signs(rng, count)
            assert len(set(signs.tolist())) > 1
            assert set(signs.tolist()) <= {0, 1, 2}
            seen[np.arange(count), signs] += 1
        assert (seen > 150).all()  # every arm gets every sign


def test_redrawing_one_sign_never_makes_all_equal():
    rng = np.random.default_rng(1)
    signs = np.array([Sign.STOP, Sign.STOP, Sign.STOP, Sign.NONE], dtype=np.int8)
    for _ in range(200):
        signs[3] = redraw_one_sign(rng, signs, 3)
        assert signs[3] != Sign.STOP
    values = set()
    for _ in range(2000):
        signs = rng.integers(0, 3, size=int(rng.integers(3, 5))).astype(np.int8)
        branch = int(rng.integers(len(signs)))
        new = redraw_one_sign(rng, signs, branch)
        signs[branch] = new
        assert len(set(signs.tolist())) > 1, signs
        values.add(new)
    assert values == {0, 1, 2}


def test_yield_car_sees_main_road_car_as_higher_priority(medium_road):
    """Behaviour: the obstacle view encodes who goes first (paper, Fig. 2d)."""
    sim = medium_road
    yield_car = place(sim, "south_0", "straight", s=38.0, sign=Sign.YIELD, speed=5.0)
    main_car = place(sim, "east_0", "straight", s=38.0, sign=Sign.NONE, speed=5.0)
    result = sim.step(still(sim))
    assert not result.terminated.any()
    assert result.observed[[yield_car, main_car]].all()
    yield_view = result.views[yield_car, NEWEST_OBSTACLES]
    main_view = result.views[main_car, NEWEST_OBSTACLES]
    assert set(np.unique(yield_view).tolist()) == {0, HIGHER_PRIORITY, EGO_OR_LOWER}
    assert (yield_view[39:45, 41:43] == EGO_OR_LOWER).all()  # itself, white, at the centre
    # the main-road car, black, where it is: ahead and to the right of the northbound yield car
    row, col = view_pixel(sim, yield_car, sim.x[main_car], sim.y[main_car])
    assert row < 42 < col
    assert (yield_view[row - 1:row + 2, col - 1:col + 2] == HIGHER_PRIORITY).all()
    black = np.argwhere(yield_view == HIGHER_PRIORITY)
    assert len(black) > 10 and (black[:, 0] < 42).all() and (black[:, 1] > 42).all()

    assert set(np.unique(main_view).tolist()) == {0, EGO_OR_LOWER}  # nobody outranks the main road
    assert (main_view[39:45, 41:43] == EGO_OR_LOWER).all()
    row, col = view_pixel(sim, main_car, sim.x[yield_car], sim.y[yield_car])
    assert row < 42 and col < 42  # the yield car is ahead-left of the westbound car
    assert (main_view[row - 1:row + 2, col - 1:col + 2] == EGO_OR_LOWER).all()


def test_route_index_helper_matches_table(medium_road):
    assert route_index(medium_road, "south_0", "left") == route(medium_road.intersection, "south_0", "left")
