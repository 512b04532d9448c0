"""Reward shaping (paper, "Reward Shaping"): both streams, every end reason."""

import numpy as np
import pytest

from conftest import place, still
from simcore.rewards import (
    TERMINAL_REASONS,
    EndReason,
    localization_reward,
    speed_reward,
    terminal_rewards,
)
from simcore.rightofway import Sign


@pytest.mark.parametrize("reason, into_higher, expected", [
    (EndReason.GOAL, False, (1.0, 1.0)),
    (EndReason.OFF_PATH, False, (0.0, -1.0)),
    (EndReason.TIME_OVER, False, (-1.0, 0.0)),
    (EndReason.CRASH, True, (-1.0, 0.0)),  # into a car with priority ("black")
    (EndReason.CRASH, False, (-0.5, 0.0)),  # into a car without ("white")
    (EndReason.RUNNING, False, (0.0, 0.0)),
    (EndReason.SIGN_CHANGE, False, (0.0, 0.0)),  # truncated: no terminal reward
    (EndReason.HORIZON, False, (0.0, 0.0)),
])
def test_terminal_values(reason, into_higher, expected):
    acc, sa = terminal_rewards(np.array([reason]), np.array([into_higher]))
    assert (acc[0], sa[0]) == expected


def test_terminal_rewards_are_vectorised_and_the_flag_only_matters_for_crashes():
    reasons = np.array([EndReason.GOAL, EndReason.CRASH, EndReason.CRASH, EndReason.OFF_PATH,
                        EndReason.TIME_OVER, EndReason.RUNNING], dtype=np.int8)
    into_higher = np.array([True, True, False, True, True, True])
    acc, sa = terminal_rewards(reasons, into_higher)
    assert acc.tolist() == [1.0, -1.0, -0.5, 0.0, -1.0, 0.0]
    assert sa.tolist() == [1.0, 0.0, 0.0, -1.0, 0.0, 0.0]
    assert set(TERMINAL_REASONS) == {EndReason.GOAL, EndReason.CRASH, EndReason.OFF_PATH, EndReason.TIME_OVER}


def test_speed_reward_is_xi_times_speed_ratio():
    assert speed_reward(np.array(4.0), np.array(8.0)) == pytest.approx(0.005 * 0.5)
    assert speed_reward(np.array(8.0), np.array(8.0)) == pytest.approx(0.005)
    assert speed_reward(np.array(0.0), np.array(8.0)) == 0.0


def test_cars_never_exceed_their_target_speed(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=5.0, speed=7.9, target_speed=8.0)
    actions = still(sim)
    actions[slot, 0] = 3.0  # full throttle
    for _ in range(5):
        result = sim.step(actions)
        assert sim.speed[slot] <= 8.0
    assert sim.speed[slot] == pytest.approx(8.0)
    assert result.reward_acc[slot] == pytest.approx(0.005, rel=1e-5)


def test_speed_reward_uses_each_cars_own_target():
    speeds, targets = np.array([7.0, 7.0, 3.0, 10.0]), np.array([7.0, 10.0, 9.0, 10.0])
    assert speed_reward(speeds, targets) == pytest.approx(0.005 * speeds / targets)
    assert speed_reward(speeds, targets) == pytest.approx([0.005, 0.0035, 0.005 / 3, 0.005])


def test_localization_reward_penalises_distance_from_the_centre():
    assert localization_reward(np.array(0.0), np.array(0.0)) == pytest.approx(0.05)
    assert localization_reward(np.array(0.3), np.array(0.0)) == pytest.approx(0.05 * np.cos(0.3))
    assert localization_reward(np.array(0.0), np.array(1.0)) == pytest.approx(0.05 - 0.05)
    assert localization_reward(np.array(0.0), np.array(-1.0)) == pytest.approx(0.0)  # either side
    assert localization_reward(np.array(0.0), np.array(0.5)) < localization_reward(np.array(0.0), np.array(0.1))
    headings, distances = np.meshgrid(np.linspace(-1.5, 1.5, 7), np.linspace(-1.75, 1.75, 5))
    assert localization_reward(headings, distances) == pytest.approx(
        0.05 * np.cos(headings) - 0.05 * np.abs(distances))
    assert localization_reward(np.array(0.4), np.array(0.0)) == localization_reward(np.array(-0.4), np.array(0.0))


def test_simulator_rewards_a_step_on_the_centre_line(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, speed=4.0, target_speed=8.0)
    result = sim.step(still(sim))
    assert result.acted[slot]
    assert result.reward_acc[slot] == pytest.approx(0.005 * 4.0 / 8.0, rel=1e-5)
    assert result.reward_sa[slot] == pytest.approx(0.05, rel=1e-5)
    assert not result.terminated[slot]


def test_simulator_penalises_an_offset(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, r=-1.0, speed=4.0, target_speed=8.0)
    result = sim.step(still(sim))
    assert result.reward_acc[slot] == pytest.approx(0.005 * 4.0 / 8.0, rel=1e-5)
    assert result.reward_sa[slot] == pytest.approx(0.05 - 0.05 * 1.0, abs=1e-6)


def test_a_car_above_its_target_speed_is_capped(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, speed=12.0, target_speed=8.0)
    result = sim.step(still(sim))
    assert sim.speed[slot] == 8.0  # placed above its target speed, it is brought down to it
    assert result.reward_acc[slot] == pytest.approx(0.005, rel=1e-5)  # never more than xi


def test_crash_rewards_depend_on_priority(medium_road):
    sim = medium_road
    # the stop-sign car drives into the main-road car's side in the middle of the junction
    south = place(sim, "south_0", "straight", s=57.5 - 0.5, sign=Sign.STOP, speed=5.0)
    east = place(sim, "east_0", "straight", s=57.5 - 1.75, sign=Sign.NONE, speed=5.0)
    result = sim.step(still(sim))
    assert result.end_reason[south] == EndReason.CRASH and result.end_reason[east] == EndReason.CRASH
    assert result.terminated[south] and result.terminated[east]
    assert result.reward_acc[south] == pytest.approx(-1.0 + 0.005 * 5.0 / 8.0, rel=1e-5)
    assert result.reward_acc[east] == pytest.approx(-0.5 + 0.005 * 5.0 / 8.0, rel=1e-5)
    assert result.reward_sa[south] == pytest.approx(0.05, abs=1e-3)  # r_terminal_sa = 0 for a crash
    assert {e.end_reason for e in result.episodes} == {"crash"}


@pytest.mark.parametrize("sign_south, sign_east, south_black", [
    (Sign.YIELD, Sign.YIELD, True),  # equal signs: east is on the south car's right
    (Sign.NONE, Sign.STOP, False),  # the sign beats the rule
])
def test_crash_rewards_follow_right_of_way(medium_road, sign_south, sign_east, south_black):
    sim = medium_road
    south = place(sim, "south_0", "straight", s=57.0, sign=sign_south, speed=5.0)
    east = place(sim, "east_0", "straight", s=55.75, sign=sign_east, speed=5.0)
    result = sim.step(still(sim))
    assert result.end_reason[south] == EndReason.CRASH and result.end_reason[east] == EndReason.CRASH
    speed_part = 0.005 * 5.0 / 8.0
    assert result.reward_acc[south] == pytest.approx((-1.0 if south_black else -0.5) + speed_part, rel=1e-5)
    assert result.reward_acc[east] == pytest.approx((-0.5 if south_black else -1.0) + speed_part, rel=1e-5)
