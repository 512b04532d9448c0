"""Simulator episodes: ends, actions, waits, sign changes and reproducibility."""

import math

import numpy as np
import pytest

from conftest import empty_simulator, place, route_index, still
from simcore.controller import (APPROACH_DECELERATION, BLOCKER_PATIENCE_S, PATIENCE_S, SPEED_GAIN, STOP_MARGIN_M, DriverOptions,
                                ScriptedDriver, scripted_driver)
from simcore.dynamics import DT, MAX_ACCELERATION, MAX_STEERING, VEHICLE_LENGTH, WHEELBASE
from simcore.rewards import EndReason
from simcore.simulator import SimConfig, Simulator


def test_off_path_ends_the_episode_with_the_steering_penalty(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, r=1.70, speed=5.0)  # 5 cm inside the lane edge
    actions = still(sim)
    actions[slot] = (0.0, MAX_STEERING)  # steer left, out of the lane
    for _ in range(10):
        result = sim.step(actions)
        if result.terminated[slot]:
            break
    assert result.end_reason[slot] == EndReason.OFF_PATH
    assert result.reward_sa[slot] < -0.95  # r_terminal_sa = -1
    assert result.reward_acc[slot] > 0.0  # r_terminal_acc = 0: only r_speed
    assert not sim.present[slot]


def test_a_car_placed_outside_its_lane_is_off_path(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, r=-1.80, speed=0.0)  # 5 cm past the lane edge
    inside = place(sim, "north_0", "straight", s=10.0, r=1.70, speed=0.0)  # 5 cm inside it
    result = sim.step(still(sim))
    assert result.end_reason[slot] == EndReason.OFF_PATH and result.terminated[slot]
    assert result.reward_sa[slot] == pytest.approx(0.05 - 0.05 * 1.80 - 1.0, abs=1e-5)
    assert result.reward_acc[slot] == 0.0  # standing still, r_terminal_acc = 0
    assert result.end_reason[inside] == EndReason.RUNNING and not result.terminated[inside]
    assert result.episodes[0].end_reason == "off_path" and result.episodes[0].lane == "south_0"


def test_crashed_cars_end_together_and_are_seen_one_last_time(medium_road):
    sim = medium_road
    south = place(sim, "south_0", "straight", s=57.0, sign=2, speed=5.0)
    # the east car overlaps the south car and is also 1.8 m off its lane: crash takes precedence
    east = place(sim, "east_0", "straight", s=55.75, r=1.8, sign=0, speed=5.0)
    result = sim.step(still(sim))
    assert result.end_reason[south] == EndReason.CRASH and result.end_reason[east] == EndReason.CRASH
    assert result.terminated[[south, east]].all() and not result.truncated.any()
    assert result.observed[[south, east]].all()  # the final views are rendered
    assert not sim.present[[south, east]].any()
    result = sim.step(still(sim))
    assert not result.acted.any() and not result.observed.any()


def test_a_crash_summary_names_the_car_that_ran_into_priority_and_its_impact_speed(medium_road):
    sim = medium_road
    south = place(sim, "south_0", "straight", s=57.0, sign=2, speed=6.0, target_speed=9.0)  # stop sign
    east = place(sim, "east_0", "straight", s=55.75, r=1.8, sign=0, speed=4.0, target_speed=8.0)  # no sign
    assert sim.priorities(np.array([south, east]))[0, 1]  # east has priority over south
    result = sim.step(still(sim))
    by_lane = {e.lane: e for e in result.episodes}
    assert by_lane["south_0"].end_reason == by_lane["east_0"].end_reason == "crash"
    assert by_lane["south_0"].crashed_into_priority and not by_lane["east_0"].crashed_into_priority
    # still(): zero acceleration, so the speeds at impact are the speeds placed
    assert (by_lane["south_0"].final_speed_mps, by_lane["south_0"].target_speed_mps) == pytest.approx((6.0, 9.0))
    assert (by_lane["east_0"].final_speed_mps, by_lane["east_0"].target_speed_mps) == pytest.approx((4.0, 8.0))


def test_wrong_way_heading_is_off_path(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, heading_offset=math.pi * 0.6, speed=0.0)
    result = sim.step(still(sim))
    assert result.end_reason[slot] == EndReason.OFF_PATH


def test_goal_at_the_end_of_the_route(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=0.0, speed=8.0)
    length = sim.intersection.routes[sim.route[slot]].path.length
    place(sim, "south_0", "straight", s=length - 0.5, speed=8.0)
    result = sim.step(still(sim))
    assert result.end_reason[slot] == EndReason.GOAL
    assert (result.reward_acc[slot], result.reward_sa[slot]) == pytest.approx((1.0 + 0.005, 1.0 + 0.05), abs=1e-4)
    assert result.episodes[0].end_reason == "goal"


def test_time_over():
    sim = empty_simulator("easy", time_limit_s=0.3)
    slot = place(sim, "south_0", "left", s=5.0, speed=0.0)
    reasons = [sim.step(still(sim)).end_reason[slot] for _ in range(3)]
    assert reasons == [EndReason.RUNNING, EndReason.RUNNING, EndReason.TIME_OVER]


def test_bad_actions_get_clear_messages(medium_road):
    sim = medium_road
    slot = place(sim, "west_0", "straight", s=5.0, speed=5.0)
    with pytest.raises(ValueError, match=r"shape \(4, 2\)"):
        sim.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"shape"):
        sim.step(np.zeros(8))
    with pytest.raises(ValueError, match=r"got shape \(4, 3\)"):
        sim.step(np.zeros((4, 3)))
    x_before = sim.x[slot]
    for column, bad in ((1, np.nan), (1, np.inf), (0, -np.inf)):
        actions = still(sim)
        actions[slot, column] = bad
        with pytest.raises(ValueError, match="finite.*lanes.*west_0"):
            sim.step(actions)
    assert sim.x[slot] == x_before and sim.time_s == 0.0  # a refused step changes nothing
    # NaN in a row without a car is ignored: nothing drives there
    actions = still(sim)
    actions[sim.slot_names.index("north_0")] = np.nan
    sim.step(actions)


@pytest.mark.parametrize("given, clipped", [
    ((50.0, 5.0), (3.0, MAX_STEERING)),
    ((-50.0, -5.0), (-3.0, -MAX_STEERING)),
    ((1.0, 0.5), (1.0, MAX_STEERING)),
])
def test_out_of_range_actions_are_clipped(medium_road, given, clipped):
    sim = medium_road
    results = []
    for action in (given, clipped):
        sim.reset(seed=0)
        slot = place(sim, "south_0", "straight", s=5.0, speed=5.0)
        actions = still(sim)
        actions[slot] = action
        sim.step(actions)
        results.append((sim.x[slot], sim.y[slot], sim.heading[slot], sim.speed[slot]))
    assert results[0] == pytest.approx(results[1], abs=1e-12)
    # and the clipped action is what moved the car: speed and yaw follow the bicycle model
    beta = math.atan(0.5 * math.tan(clipped[1]))
    assert results[0][3] == pytest.approx(5.0 + 0.1 * clipped[0])
    assert results[0][2] - math.pi / 2 == pytest.approx(5.0 * math.sin(beta) / (0.5 * WHEELBASE) * 0.1)
    np.testing.assert_array_equal(sim.validate_actions(np.tile(given, (sim.num_slots, 1)))[0], clipped)


def test_a_new_episode_starts_at_the_route_start_with_the_papers_speeds():
    sim = Simulator("hard", SimConfig(observe=False), seed=4)
    result = sim.reset()
    assert result.started.all() and sim.present.all() and (sim.episode_count == 1).all()
    assert len(set(sim.branch_signs.tolist())) > 1  # never every arm the same
    for slot, lane_index in enumerate(sim.slot_lanes):
        lane = sim.intersection.lanes[lane_index]
        assert sim.route[slot] in lane.routes
        path = sim.intersection.routes[sim.route[slot]].path
        assert (sim.x[slot], sim.y[slot]) == pytest.approx(path.position(0.0, 0.0))
        assert sim.heading[slot] == pytest.approx(path.heading_at(0.0))
        assert (sim.s[slot], sim.r[slot], sim.steps[slot]) == (0.0, 0.0, 0)
        assert 3.0 <= sim.speed[slot] <= 6.0 and 7.0 <= sim.target_speed[slot] <= 10.0  # paper's ranges
        assert sim.sign[slot] == sim.branch_signs[lane.branch]  # both lanes of an arm share its sign
    assert np.array_equal(result.scalars[:, 0], sim.speed.astype(np.float32))
    assert np.array_equal(result.scalars[:, 1], sim.target_speed.astype(np.float32))


def test_one_agent_per_lane_and_random_waits():
    sim = Simulator("easy", SimConfig(delay_min_s=2.0, delay_max_s=4.0), seed=1)
    result = sim.reset()
    assert result.started.all() and sim.present.all()  # every lane starts at reset
    driver = ScriptedDriver(sim)
    ended_at, restarted_at = {}, {}
    for step in range(1, 400):
        result = sim.step(driver.act())
        assert sim.present.sum() <= sim.num_slots
        for slot in np.flatnonzero(result.terminated | result.truncated):
            ended_at.setdefault(int(slot), step)
        for slot in np.flatnonzero(result.started):
            if int(slot) in ended_at and int(slot) not in restarted_at:
                restarted_at[int(slot)] = step
    assert restarted_at, "a lane must start again after its wait"
    for slot, step in restarted_at.items():
        assert 20 <= step - ended_at[slot] <= 41  # waited U[2, 4] s at 10 steps per second


def test_hard_redraws_signs_and_restarts_everyone_together():
    sim = Simulator("hard", SimConfig(sign_change_interval_s=3.0, delay_min_s=50.0, delay_max_s=60.0,
                                      sign_change_restart="together"), seed=2)
    sim.reset()
    driver = ScriptedDriver(sim)
    for _ in range(29):
        result = sim.step(driver.act())
    result = sim.step(driver.act())  # t = 3.0 s
    cut = result.truncated
    assert cut.sum() == sim.present.size - result.terminated.sum()
    assert set(result.end_reason[cut].tolist()) == {EndReason.SIGN_CHANGE}
    assert not sim.present.any()
    result = sim.step(driver.act())
    assert result.started.all()  # everyone starts together at the next step, no random wait
    for lane in sim.intersection.lanes:  # both lanes of an arm share its sign
        slot = sim.slot_lanes.index(lane.index)
        assert sim.sign[slot] == sim.branch_signs[lane.branch]
    assert len(set(sim.branch_signs.tolist())) > 1


def test_hard_restarts_after_a_redraw_at_random_delays_by_default():
    """The scenario's default: after a redraw each agent waits U[delay_min, delay_max] before its
    new episode, as after any episode (paper, "Training settings"), instead of all at once."""
    sim = Simulator("hard", SimConfig(sign_change_interval_s=3.0, delay_min_s=1.0, delay_max_s=2.0), seed=2)
    assert sim.sign_restart == "delayed"
    sim.reset()
    driver = ScriptedDriver(sim)
    for _ in range(30):  # to t = 3.0 s, the redraw
        result = sim.step(driver.act())
    assert result.truncated.any() and not sim.present.any()
    redraw_s = sim.time_s
    started_s = {}
    while sim.time_s < redraw_s + 2.05:
        result = sim.step(driver.act())
        for slot in np.flatnonzero(result.started).tolist():
            started_s.setdefault(slot, sim.time_s)
    assert sorted(started_s) == list(range(sim.num_slots))  # every lane started again
    waits = np.array(list(started_s.values())) - redraw_s
    assert waits.min() >= 1.0 - 1e-9 and waits.max() <= 2.0 + DT + 1e-9  # U[1, 2] s, to the next step
    assert len(set(np.round(waits, 3))) > 3  # at their own times, not in one burst


def test_unknown_sign_change_restart_is_refused():
    with pytest.raises(ValueError, match="sign_change_restart must be one of delayed, together"):
        Simulator("hard", SimConfig(sign_change_restart="later"))


def test_lanes_option_restricts_agents():
    sim = Simulator("medium", SimConfig(lanes=("south_0",)), seed=0)
    result = sim.reset()
    assert sim.num_slots == 1 and sim.slot_names == ["south_0"] and result.views.shape[0] == 1
    with pytest.raises(ValueError, match="unknown or empty"):
        Simulator("medium", SimConfig(lanes=("south_7",)))


def test_skip_idle_jumps_to_the_next_start():
    sim = Simulator("easy", SimConfig(start_all_at_reset=False, delay_min_s=20.0, delay_max_s=30.0,
                                      skip_idle=True), seed=0)
    result = sim.reset()
    assert sim.present.any() and result.started.any()
    assert 20.0 <= sim.time_s <= 30.0


def run(seed, steps=200):
    sim = Simulator("medium", SimConfig(delay_max_s=5.0), seed=seed)
    sim.reset()
    driver = ScriptedDriver(sim)
    episodes = []
    for _ in range(steps):
        result = sim.step(driver.act())
        episodes += [(e.lane, e.turn, e.sign, e.end_reason, e.steps) for e in result.episodes]
    state = np.concatenate([sim.x, sim.y, sim.heading, sim.speed, sim.target_speed, sim.route, sim.sign,
                            sim.present, sim.episode_count, sim.return_acc, sim.return_sa])
    return state, result.views.copy(), episodes


def test_same_seed_same_run_different_seed_different_run():
    state_a, views_a, episodes_a = run(5)
    state_b, views_b, episodes_b = run(5)
    state_c, _, episodes_c = run(6)
    assert len(episodes_a) > 0  # cars did finish within 20 s
    assert np.array_equal(state_a, state_b) and np.array_equal(views_a, views_b)
    assert episodes_a == episodes_b
    assert not np.array_equal(state_a, state_c)
    assert episodes_a != episodes_c


@pytest.mark.parametrize("priority_car_before_zone_m, view_sight_yields", [
    (12.0, True),  # near: 15 m to the right, 15 m ahead, inside the 50 x 50 m the learner's views show
    (34.0, False),  # 34 m out at 8 m/s it reaches the zone within 5 s, but lies 37 m to the right
    (23.0, True),  # 26 m to the right: its centre is 1 m outside the square, its front inside it
    (25.0, False),  # 28 m to the right: more than half a car length (2.25 m) outside, none of it shows
])
def test_a_teacher_with_the_views_sight_yields_only_to_cars_it_could_see(
        medium_road, priority_car_before_zone_m, view_sight_yields):
    sim = medium_road
    south_route, east_route = route_index(sim, "south_0", "straight"), route_index(sim, "east_0", "straight")
    zone_south = sim.priority.zone_start[south_route, east_route]
    zone_east = sim.priority.zone_start[east_route, south_route]
    south = place(sim, "south_0", "straight", s=zone_south - 12.0, sign=2, speed=8.0)  # stop sign, 12 m out
    place(sim, "east_0", "straight", s=zone_east - priority_car_before_zone_m, sign=0, speed=8.0)  # no sign
    cruise = ScriptedDriver(sim, yield_to_priority=False).act()[south, 0]  # speed keeping alone
    full = ScriptedDriver(sim).act()[south, 0]
    view = ScriptedDriver(sim, sight_m=25.0).act()[south, 0]
    assert full == -3.0 and cruise > -2.0  # the privileged teacher stops for the car either way
    assert view == (full if view_sight_yields else cruise)
    # the same square moved 15 m ahead: the near car is still inside it (15 m ahead, 15 m right),
    # the far one (37 m right) still outside, at either distance
    shifted = ScriptedDriver(sim, sight_m=25.0, sight_shift_m=15.0).act()[south, 0]
    assert shifted == view
    # moved 45 m ahead, the square starts 20 m ahead of the car: it sees neither
    assert ScriptedDriver(sim, sight_m=25.0, sight_shift_m=45.0).act()[south, 0] == cruise
    with pytest.raises(ValueError, match="sight_m"):
        ScriptedDriver(sim, sight_m=0.0)
    with pytest.raises(ValueError, match="sight_shift_m"):
        ScriptedDriver(sim, sight_m=25.0, sight_shift_m=float("nan"))


def test_a_cautious_teacher_slows_before_a_zone_shared_with_a_route_that_may_have_priority(medium_road):
    sim = medium_road
    south_route, east_route = route_index(sim, "south_0", "straight"), route_index(sim, "east_0", "straight")
    zone_south = sim.priority.zone_start[south_route, east_route]
    room_m = 8.0  # from the car's front to the stop point, STOP_MARGIN_M before the zone
    s = zone_south - STOP_MARGIN_M - room_m - 0.5 * VEHICLE_LENGTH
    sim.branch_signs[:] = 0  # no sign on any arm: priority to the right alone
    south = place(sim, "south_0", "straight", s=s, sign=0, speed=8.0)  # the road is empty
    plain = ScriptedDriver(sim).act()[south, 0]
    approach_mps = 3.0
    cautious = ScriptedDriver(sim, approach_speed_mps=approach_mps).act()[south, 0]
    # the speed it aims at here: brake from it at APPROACH_DECELERATION to reach the stop point at 3 m/s
    aimed = math.sqrt(approach_mps ** 2 + 2.0 * APPROACH_DECELERATION * room_m)
    assert plain == pytest.approx(SPEED_GAIN * (0.9 * 8.0 - 8.0))
    assert cautious == pytest.approx(SPEED_GAIN * (aimed - 8.0))
    # with a stop sign on every other arm, nobody may have priority over the south car: no caution
    others = [b for b in range(len(sim.branch_signs)) if sim.intersection.branches[b].name != "south"]
    sim.branch_signs[others] = 2
    assert ScriptedDriver(sim, approach_speed_mps=approach_mps).act()[south, 0] == pytest.approx(plain)
    # judged by its own sign alone (what its views show), the east arm may be unsigned: caution again
    own = ScriptedDriver(sim, approach_speed_mps=approach_mps, approach_signs="own")
    assert own.act()[south, 0] == pytest.approx(cautious)
    with pytest.raises(ValueError, match="approach_speed_mps"):
        ScriptedDriver(sim, approach_speed_mps=-1.0)
    with pytest.raises(ValueError, match="approach_signs"):
        ScriptedDriver(sim, approach_speed_mps=approach_mps, approach_signs="some")


def test_a_teacher_judging_by_its_own_sign_slows_only_for_routes_an_unsigned_arm_would_give_priority(medium_road):
    """approach_signs="own" with no sign of its own: only routes from the right may have priority;
    with a stop sign: every route crossing its own."""
    sim = medium_road
    south_route = route_index(sim, "south_0", "straight")
    sim.branch_signs[:] = 2  # stop signs everywhere: "all" sees no route with priority over an unsigned car
    south = place(sim, "south_0", "straight", s=5.0, sign=0, speed=8.0)
    zones = {}
    for own_sign in (0, 2):
        sim.sign[south] = own_sign
        driver = ScriptedDriver(sim, approach_speed_mps=1.0, approach_signs="own")
        zones[own_sign] = set(driver._yield_zones(south, driver._route_ranks()).tolist())
    table = sim.priority
    crossing = [r for r in range(len(sim.intersection.routes)) if table.conflict[south_route, r]
                and sim.intersection.routes[r].entry_lane != sim.intersection.routes[south_route].entry_lane]
    from_right = [r for r in crossing if table.right_wins[south_route, r]]
    assert 0 < len(from_right) < len(crossing)
    assert zones[0] == {float(table.zone_start[south_route, r]) for r in from_right}
    assert zones[2] == {float(table.zone_start[south_route, r]) for r in crossing}


def test_a_teacher_that_brakes_for_blockers_stops_for_a_car_standing_in_its_zone_even_with_priority(medium_road):
    """The east car has priority (no sign, from the south car's right); the south car (stop sign)
    stands inside their conflict zone. Only with brake_for_blockers does the east car stop for it,
    and only until it has stood BLOCKER_PATIENCE_S itself."""
    sim = medium_road
    south_route, east_route = route_index(sim, "south_0", "straight"), route_index(sim, "east_0", "straight")
    table = sim.priority
    inside_s = table.zone_start[south_route, east_route] + 1.0  # centre 1 m into the zone: it occupies it
    south = place(sim, "south_0", "straight", s=inside_s, sign=2, speed=0.0)
    east = place(sim, "east_0", "straight", s=table.zone_start[east_route, south_route] - 20.0, sign=0, speed=8.0)
    assert sim.priorities(np.array([south, east]))[0, 1]  # east over south
    plain_driver = ScriptedDriver(sim)
    plain = plain_driver.act()[east, 0]
    guarded = ScriptedDriver(sim, brake_for_blockers=True)
    assert plain > -2.0  # it has the right of way: it keeps its speed
    assert not plain_driver.blocker_bound.any()  # a driver that does not brake for blockers never says it does
    gap_m = table.zone_start[east_route, south_route] - STOP_MARGIN_M - (sim.s[east] + 0.5 * VEHICLE_LENGTH)
    assert guarded.act()[east, 0] == pytest.approx(-8.0 ** 2 / (2.0 * gap_m))  # a stop at its stop point
    # the label is the braking for the blocker (crossway pretrain --blocker-weight); the south car, standing
    # in the zone it must clear, brakes for nobody
    assert guarded.blocker_bound[east] and not guarded.blocker_bound[south]
    # the same with the sight of the views (the south car is 20 m ahead and a few metres aside)
    assert scripted_driver(sim, DriverOptions(sight="view", brake_for_blockers=True)).act()[east, 0] < -2.0
    # once past the zone's start it clears it rather than stopping inside
    sim.s[south] = table.zone_end[south_route, east_route] + 0.5 * VEHICLE_LENGTH + 1.0  # the south car left it
    sim.x[south], sim.y[south] = sim.intersection.routes[south_route].path.position(sim.s[south], 0.0)
    assert guarded.act()[east, 0] == pytest.approx(plain)
    assert not guarded.blocker_bound.any()  # the flag is the last act()'s, not a memory of the one before
    # back in the zone, with the east car standing before it: it waits BLOCKER_PATIENCE_S, then goes
    sim.s[south] = inside_s
    sim.x[south], sim.y[south] = sim.intersection.routes[south_route].path.position(inside_s, 0.0)
    sim.speed[east] = 0.0  # standing at its stop point
    sim.s[east] = table.zone_start[east_route, south_route] - STOP_MARGIN_M - 0.5 * VEHICLE_LENGTH
    sim.x[east], sim.y[east] = sim.intersection.routes[east_route].path.position(sim.s[east], 0.0)
    waiting = ScriptedDriver(sim, brake_for_blockers=True)
    waiting._standing_s[east] = BLOCKER_PATIENCE_S - 0.5
    assert waiting.act()[east, 0] == -3.0
    waiting._standing_s[east] = BLOCKER_PATIENCE_S
    assert waiting.act()[east, 0] > 0.0
    # a driver without that patience waits for as long as the zone is occupied
    never = ScriptedDriver(sim, brake_for_blockers=True, blocker_patience_s=math.inf)
    never._standing_s[east] = 1000.0
    assert never.act()[east, 0] == -3.0


def test_a_driver_goes_ahead_of_a_car_with_priority_after_its_patience_and_never_without_one(medium_road):
    """The south car (stop sign) stands at its stop point; the east car (no sign, priority) comes
    at 8 m/s, 2 s from their zone. The scripted driver waits PATIENCE_S, then goes; with patience_s
    inf it waits whatever its standing time."""
    sim = medium_road
    south_route, east_route = route_index(sim, "south_0", "straight"), route_index(sim, "east_0", "straight")
    table = sim.priority
    stop_s = table.zone_start[south_route, east_route] - STOP_MARGIN_M - 0.5 * VEHICLE_LENGTH
    south = place(sim, "south_0", "straight", s=stop_s, sign=2, speed=0.0)
    east = place(sim, "east_0", "straight", s=table.zone_start[east_route, south_route] - 16.0, sign=0, speed=8.0)
    assert sim.priorities(np.array([south, east]))[0, 1]  # east over south
    for patience_s, stood_s, goes in ((PATIENCE_S, PATIENCE_S - 0.5, False), (PATIENCE_S, PATIENCE_S, True),
                                      (math.inf, 1000.0, False)):
        driver = ScriptedDriver(sim, patience_s=patience_s)
        driver._standing_s[south] = stood_s
        assert (driver.act()[south, 0] > 0.0) == goes, (patience_s, stood_s)
        # the label crossway pretrain --patience-weight counts more: going although the east car is near
        assert driver.patience_released[south] == goes and not driver.patience_released[east]
    assert scripted_driver(sim, DriverOptions(patience_s=math.inf)).patience_s == math.inf


def test_a_driver_that_waits_outside_zones_stops_before_the_first_of_overlapping_zones():
    """On hard the zones overlap: the stop point for a zone nested in another leaves the car's body
    inside the outer one. With wait_outside_zones the east car (stop sign) stops before the outer
    zone for a car with priority; once its front is past that zone's start, before the zone itself."""
    sim = empty_simulator("hard")
    ego_route = route_index(sim, "east_0", "straight")
    table = sim.priority
    driver = ScriptedDriver(sim, wait_outside_zones=True)
    starts, ends = driver._crossing_zones[ego_route]
    nested = [r for r in range(len(sim.intersection.routes)) if table.conflict[ego_route, r]
              and np.isnan(table.merge_at[ego_route, r])
              and driver._stop_before(ego_route, table.zone_start[ego_route, r], 0.0) < table.zone_start[ego_route, r]]
    assert nested  # hard has such zones
    other_route = nested[0]
    zone = table.zone_start[ego_route, other_route]
    moved = driver._stop_before(ego_route, zone, 0.0)
    assert moved in set(starts.tolist())  # the start of another crossing zone
    front = moved - STOP_MARGIN_M  # the body standing there lies outside every crossing zone
    assert not np.any((starts < front) & (ends > front - VEHICLE_LENGTH))
    assert ScriptedDriver(sim)._stop_before(ego_route, zone, 0.0) == zone  # the option off: unchanged
    # in act(): a car with priority (no sign) 20 m before its zone, the east car (stop sign) at 8 m/s
    other_lane = sim.intersection.lanes[sim.intersection.routes[other_route].entry_lane].name
    other_turn = sim.intersection.routes[other_route].turn
    half = 0.5 * VEHICLE_LENGTH
    place(sim, other_lane, other_turn, s=table.zone_start[other_route, ego_route] - 20.0 - half, sign=0, speed=8.0)
    east = place(sim, "east_0", "straight", s=moved - STOP_MARGIN_M - half - 12.0, sign=2, speed=8.0,
                 target_speed=9.0)  # free driving would accelerate
    s_front = sim.s[east] + half
    plain = ScriptedDriver(sim).act()[east, 0]
    assert plain == pytest.approx(-8.0 ** 2 / (2.0 * (zone - STOP_MARGIN_M - s_front)))
    assert ScriptedDriver(sim, wait_outside_zones=True).act()[east, 0] == pytest.approx(-8.0 ** 2 / (2.0 * 12.0))
    # past the outer zone's start it can no longer stop before it: it stops before the zone itself
    assert driver._stop_before(ego_route, zone, moved + 0.5) == zone


def test_a_driver_that_waits_outside_zones_slows_only_before_a_chain_of_zones_not_inside_it():
    """Hard's straight route from the east inner lane crosses one chain of overlapping zones. A
    stop-sign car judging by its own sign, 1 m into the chain's first zone: without the option it
    slows towards the next zone's stop point; with it, it cannot stop inside the chain, so it
    drives on at its cruising speed."""
    sim = empty_simulator("hard")
    ego_route = route_index(sim, "east_0", "straight")
    driver = ScriptedDriver(sim, approach_speed_mps=2.0, approach_signs="own", wait_outside_zones=True)
    starts, _ = driver._crossing_zones[ego_route]
    chain_start = float(starts.min())
    assert all(driver._stop_before(ego_route, z, -math.inf) == chain_start for z in starts.tolist())  # one chain
    half = 0.5 * VEHICLE_LENGTH
    east = place(sim, "east_0", "straight", s=chain_start + 1.0 - half, sign=2, speed=5.0, target_speed=8.0)
    cruising = min(SPEED_GAIN * (0.9 * 8.0 - 5.0), MAX_ACCELERATION)
    next_zone = float(starts[starts > chain_start + 1.0].min())
    aimed = math.sqrt(2.0 ** 2 + 2.0 * APPROACH_DECELERATION * (next_zone - STOP_MARGIN_M - (chain_start + 1.0)))
    plain = ScriptedDriver(sim, approach_speed_mps=2.0, approach_signs="own").act()[east, 0]
    assert plain == pytest.approx(min(SPEED_GAIN * (aimed - 5.0), cruising)) and plain < cruising
    assert driver.act()[east, 0] == pytest.approx(cruising)


def test_cars_in_a_cycle_of_priority_stop_yielding_to_each_other_with_break_wait_cycles(medium_road):
    """Three cars with yield signs on medium: south yields to east (from its right), east (turning
    left) to west (straight, from ahead), west to south (from its right). Each waits for the next:
    with break_wait_cycles they stop yielding to each other; without the third car, no cycle."""
    sim = medium_road
    east = place(sim, "east_0", "left", s=15.7, sign=1, speed=7.5, target_speed=8.4)
    west = place(sim, "west_0", "straight", s=15.8, sign=1, speed=7.4, target_speed=8.3)
    south = place(sim, "south_0", "straight", s=17.9, sign=1, speed=7.5, target_speed=9.9)
    higher = sim.priorities(np.array([south, east, west]))  # [i, j]: j has priority over i
    assert higher[0, 1] and higher[1, 2] and higher[2, 0]
    plain = ScriptedDriver(sim).act()
    untangled = ScriptedDriver(sim, break_wait_cycles=True).act()
    assert plain[south, 0] < 0.0 and plain[east, 0] < 0.0  # each brakes for the next one
    for car, target in ((south, 9.9), (east, 8.4)):  # free driving: speed kept at 0.9 of the target
        assert untangled[car, 0] == pytest.approx(SPEED_GAIN * (0.9 * target - sim.speed[car]))
    sim.present[west] = False  # no cycle left: south yields to east as before
    assert ScriptedDriver(sim, break_wait_cycles=True).act()[south, 0] == pytest.approx(ScriptedDriver(sim).act()[south, 0])


def test_driver_options_refuse_unknown_values_and_record_what_the_json_holds():
    with pytest.raises(ValueError, match="sight"):
        DriverOptions(sight="half")
    with pytest.raises(ValueError, match="approach_speed_mps"):
        DriverOptions(approach_speed_mps=-1.0)
    with pytest.raises(ValueError, match="approach_signs"):
        DriverOptions(approach_speed_mps=1.0, approach_signs="some")
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="patience_s"):
            DriverOptions(patience_s=bad)
        with pytest.raises(ValueError, match="blocker_patience_s"):
            DriverOptions(blocker_patience_s=bad)
    assert DriverOptions().record() == {"scripted_sight": None, "scripted_approach_mps": None,
                                        "scripted_approach_signs": None, "scripted_brake_for_blockers": False,
                                        "scripted_wait_outside_zones": False, "scripted_break_wait_cycles": False,
                                        "scripted_patience_s": PATIENCE_S,
                                        "scripted_blocker_patience_s": BLOCKER_PATIENCE_S}
    assert DriverOptions("view", 2.0, "own", True, True, True, math.inf, 5.0).record() == {
        "scripted_sight": "view", "scripted_approach_mps": 2.0, "scripted_approach_signs": "own",
        "scripted_brake_for_blockers": True, "scripted_wait_outside_zones": True, "scripted_break_wait_cycles": True,
        "scripted_patience_s": "never", "scripted_blocker_patience_s": 5.0}


def test_the_third_scalar_counts_how_long_each_car_has_stood():
    """StepResult.scalars[:, 2]: + 0.1 s per step while slower than 0.5 m/s, 0 once it moves or a
    new episode starts (the scripted driver's patience clock, which lags it by one step)."""
    from simcore.dynamics import DT, MAX_ACCELERATION, STANDING_MPS
    from simcore.simulator import SCALARS

    sim = Simulator("easy", SimConfig(start_all_at_reset=True), seed=0)
    result = sim.reset()
    assert result.scalars.shape == (sim.num_slots, SCALARS) and (result.scalars[:, 2] == 0).all()
    brake = np.zeros((sim.num_slots, 2))
    brake[:, 0] = -MAX_ACCELERATION
    standing_steps = np.zeros(sim.num_slots)
    for _ in range(40):  # from at most 6 m/s, 3 m/s^2 stops a car within 2 s
        result = sim.step(brake)
        on = sim.learners_present
        standing_steps = np.where(on & (sim.speed[: sim.num_slots] < STANDING_MPS), standing_steps + 1, 0)
        np.testing.assert_allclose(result.scalars[on, 2], DT * standing_steps[on], atol=1e-5)
    assert result.scalars[sim.learners_present, 2].min() > 1.5  # every car has stood for a while
    go = -brake
    result = sim.step(go)
    result = sim.step(go)
    moving = sim.learners_present & (sim.speed[: sim.num_slots] >= STANDING_MPS)
    assert moving.any() and (result.scalars[moving, 2] == 0).all()
