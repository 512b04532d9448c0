"""Simulator episodes: ends, actions, waits, sign changes and reproducibility."""

import math

import numpy as np
import pytest

from conftest import empty_simulator, place, still
from simcore.controller import ScriptedDriver
from simcore.dynamics import MAX_STEERING
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
    for bad in (np.nan, np.inf):
        actions = still(sim)
        actions[slot, 1] = bad
        with pytest.raises(ValueError, match="finite.*west_0"):
            sim.step(actions)
    # NaN in a row without a car is ignored: nothing drives there
    actions = still(sim)
    actions[sim.slot_names.index("north_0")] = np.nan
    sim.step(actions)


def test_out_of_range_actions_are_clipped():
    results = []
    for steering, acceleration in ((5.0, 50.0), (MAX_STEERING, 3.0)):
        sim = empty_simulator("medium")
        slot = place(sim, "south_0", "straight", s=5.0, speed=5.0)
        actions = still(sim)
        actions[slot] = (acceleration, steering)
        sim.step(actions)
        results.append((sim.x[slot], sim.y[slot], sim.heading[slot], sim.speed[slot]))
    assert results[0] == pytest.approx(results[1])


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
    sim = Simulator("hard", SimConfig(sign_change_interval_s=3.0, delay_min_s=50.0, delay_max_s=60.0), seed=2)
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
    for _ in range(steps):
        result = sim.step(driver.act())
    return np.concatenate([sim.x, sim.y, sim.speed]), result.views.copy()


def test_same_seed_same_run_different_seed_different_run():
    state_a, views_a = run(5)
    state_b, views_b = run(5)
    state_c, _ = run(6)
    assert np.array_equal(state_a, state_b) and np.array_equal(views_a, views_b)
    assert not np.array_equal(state_a, state_c)
