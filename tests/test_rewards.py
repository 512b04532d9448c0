"""Reward shaping (paper, "Reward Shaping"): both streams, every end reason."""

import numpy as np
import pytest

from conftest import place, still
from simcore.rewards import (
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
    (EndReason.SIGN_CHANGE, False, (0.0, 0.0)),
])
def test_terminal_values(reason, into_higher, expected):
    acc, sa = terminal_rewards(np.array([reason]), np.array([into_higher]))
    assert (acc[0], sa[0]) == expected


def test_speed_reward_is_xi_times_speed_ratio_up_to_target():
    assert speed_reward(np.array(4.0), np.array(8.0)) == pytest.approx(0.005 * 0.5)
    assert speed_reward(np.array(8.0), np.array(8.0)) == pytest.approx(0.005)
    assert speed_reward(np.array(0.0), np.array(8.0)) == 0.0
    above = speed_reward(np.array([9.0, 12.0, 16.0]), np.array(8.0))
    assert above[0] < 0.005 and above[1] < above[0] and above[2] == pytest.approx(0.0)


def test_localization_reward_penalises_distance_from_the_centre():
    assert localization_reward(np.array(0.0), np.array(0.0)) == pytest.approx(0.05)
    assert localization_reward(np.array(0.3), np.array(0.0)) == pytest.approx(0.05 * np.cos(0.3))
    assert localization_reward(np.array(0.0), np.array(1.0)) == pytest.approx(0.05 - 0.05)
    assert localization_reward(np.array(0.0), np.array(-1.0)) == pytest.approx(0.0)  # either side
    assert localization_reward(np.array(0.0), np.array(0.5)) < localization_reward(np.array(0.0), np.array(0.1))


def test_simulator_rewards_a_step_on_the_centre_line(medium_road):
    sim = medium_road
    slot = place(sim, "south_0", "straight", s=10.0, speed=4.0, target_speed=8.0)
    result = sim.step(still(sim))
    assert result.reward_acc[slot] == pytest.approx(0.005 * 4.0 / 8.0, rel=1e-5)
    assert result.reward_sa[slot] == pytest.approx(0.05, rel=1e-5)
    assert not result.terminated[slot]


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
