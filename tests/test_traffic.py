"""Scripted IDM traffic besides the learners (paper, "Comparison with TTC method")."""

import numpy as np
import pytest

from simcore.controller import ScriptedDriver
from simcore.dynamics import VEHICLE_LENGTH
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator, TrafficConfig
from simcore.views import HIGHER_PRIORITY

SIGNS = (("south", "stop"), ("east", "none"), ("west", "none"), ("north", "none"))
MAIN_ROAD = ("east_0", "east_1", "west_0", "west_1")


def ttc_like(max_cars=8, traffic_delay_s=5.0, **changes):
    """Hard junction, learners on the stop-sign arm, IDM traffic on the main road waiting up to
    ``traffic_delay_s`` between trips; ``changes`` go to SimConfig."""
    config = SimConfig(lanes=("south_0", "south_1"), signs=SIGNS,
                       traffic=TrafficConfig(lanes=MAIN_ROAD, max_cars=max_cars, delay_max_s=traffic_delay_s),
                       **changes)
    return Simulator("hard", config, seed=0)


def test_traffic_drives_the_main_road_centre_within_its_limits():
    sim = ttc_like(max_cars=6)
    sim.reset()
    driver = ScriptedDriver(sim)
    seen = 0
    for _ in range(300):
        sim.step(driver.act())
        traffic = sim.num_slots + np.flatnonzero(sim.present[sim.num_slots:])
        seen = max(seen, len(traffic))
        assert len(traffic) <= 6
        for v in traffic:
            lane = sim.intersection.lanes[sim.lane_of[v]]
            assert lane.name in MAIN_ROAD
            assert sim.intersection.routes[sim.route[v]].turn == "straight"
            path = sim.intersection.routes[sim.route[v]].path
            s, r = path.local_coordinates((sim.x[v], sim.y[v]))
            assert abs(r) < 1e-6 and s == pytest.approx(sim.s[v], abs=1e-6)  # exactly on the centre
            assert 0.0 <= sim.speed[v] <= sim.target_speed[v] + 1e-9
    assert seen >= 4
    assert list(sim.branch_signs) == [Sign.NONE, Sign.NONE, Sign.NONE, Sign.STOP]  # fixed, never redrawn


def test_traffic_stops_behind_a_car_standing_in_its_lane():
    # one traffic car; the learners never start on their own
    sim = ttc_like(max_cars=1, traffic_delay_s=0.0, start_all_at_reset=False, delay_min_s=1e6, delay_max_s=1e6)
    sim.reset()
    for _ in range(3):
        sim.step(np.zeros((sim.num_slots, 2)))
    v = sim.num_slots
    assert sim.present[v]
    path = sim.intersection.routes[sim.route[v]].path
    # a learner car standing on the traffic car's lane, 40 m ahead of it
    blocker = 0
    sim.x[blocker], sim.y[blocker] = path.position(sim.s[v] + 40.0, 0.0)
    sim.heading[blocker] = path.heading_at(sim.s[v] + 40.0)
    sim.speed[blocker] = 0.0
    sim.route[blocker] = sim.route[v]
    sim.s[blocker] = sim.s[v] + 40.0
    sim.present[blocker] = True
    for _ in range(250):
        actions = np.zeros((sim.num_slots, 2))
        actions[blocker, 0] = -3.0  # stay put
        result = sim.step(actions)
        assert not result.terminated[blocker], "the traffic car ran into the standing car"
    gap = sim.s[blocker] - sim.s[v] - VEHICLE_LENGTH
    assert sim.speed[v] == pytest.approx(0.0, abs=0.05)
    assert 1.0 < gap < 3.0  # about the IDM's jam distance


def test_a_stop_sign_learner_sees_main_road_traffic_as_higher_priority():
    sim = ttc_like(max_cars=12, traffic_delay_s=1.0)
    sim.reset()
    driver = ScriptedDriver(sim)
    shaded = 0
    for _ in range(200):
        result = sim.step(driver.act())
        for slot in np.flatnonzero(result.observed):
            shaded += int((result.views[slot, 11] == HIGHER_PRIORITY).sum())
    assert shaded > 0


def test_traffic_runs_are_reproducible():
    def run():
        sim = ttc_like()
        sim.reset()
        driver = ScriptedDriver(sim)
        for _ in range(150):
            sim.step(driver.act())
        return np.concatenate([sim.x, sim.y, sim.present])

    assert np.array_equal(run(), run())


@pytest.mark.parametrize("config, message", [
    (SimConfig(traffic=TrafficConfig(lanes=("nowhere_0",))), "unknown lane"),
    (SimConfig(traffic=TrafficConfig(lanes=("east_0",), turns=("right",))), "no route turning"),
    (SimConfig(traffic=TrafficConfig(lanes=("east_0",), max_cars=0)), "max_cars"),
    (SimConfig(signs=(("south", "stop"),)), "one sign for each arm"),
    (SimConfig(signs=(("south", "halt"), ("east", "none"), ("west", "none"), ("north", "none"))), "unknown sign"),
])
def test_bad_traffic_and_sign_options_are_refused(config, message):
    with pytest.raises(ValueError, match=message):
        Simulator("hard", config)


def test_equal_speeds_give_every_learner_the_same_start():
    sim = Simulator("hard", SimConfig(equal_speeds=True), seed=4)
    sim.reset()
    assert np.unique(sim.speed[: sim.num_slots]).size == 1
    assert np.unique(sim.target_speed[: sim.num_slots]).size == 1
    first = (sim.speed[0], sim.target_speed[0])
    sim.reset()
    assert (sim.speed[0], sim.target_speed[0]) != first  # drawn again at every reset


def test_traffic_on_neighbouring_and_opposite_lanes_does_not_block():
    """Only a car in the traffic car's own corridor leads it: cars one lane width to the side, on
    the next lane or driving the other way, never stop it (they once gridlocked the junction)."""
    sim = ttc_like(max_cars=12, traffic_delay_s=0.0, start_all_at_reset=False, delay_min_s=1e6, delay_max_s=1e6)
    sim.reset()
    stopped_longest = np.zeros(sim.num_vehicles)
    stopped = np.zeros(sim.num_vehicles)
    for _ in range(1500):  # 150 s of busy main road, no learner on the road
        sim.step(np.zeros((sim.num_slots, 2)))
        traffic = sim.num_slots + np.flatnonzero(sim.present[sim.num_slots:])
        standing = np.zeros(sim.num_vehicles, dtype=bool)
        standing[traffic] = sim.speed[traffic] < 0.1
        stopped = np.where(standing, stopped + 1, 0)
        stopped_longest = np.maximum(stopped_longest, stopped)
    assert stopped_longest.max() < 30  # no traffic car stood still for 3 s
    assert not sim.present[: sim.num_slots].any()
