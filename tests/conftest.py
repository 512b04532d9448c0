"""Shared helpers: build simulators with an empty road and place cars on it by hand."""

import numpy as np
import pytest

from simcore.simulator import SimConfig, Simulator

EMPTY_ROAD = SimConfig(start_all_at_reset=False, delay_min_s=1e6, delay_max_s=1e6)


def route_index(sim: Simulator, lane: str, turn: str) -> int:
    """Index of the route that leaves ``lane`` with ``turn``."""
    entry = next(l for l in sim.intersection.lanes if l.name == lane)
    for r in entry.routes:
        if sim.intersection.routes[r].turn == turn:
            return r
    raise KeyError(f"{lane} has no {turn} route")


def place(sim: Simulator, lane: str, turn: str, s: float, sign: int = 0, speed: float = 0.0,
          r: float = 0.0, heading_offset: float = 0.0, target_speed: float = 8.0) -> int:
    """Put a car on ``lane``'s ``turn`` route at arc length ``s`` [m]; returns its slot."""
    slot = sim.slot_names.index(lane)
    route = route_index(sim, lane, turn)
    path = sim.intersection.routes[route].path
    sim.route[slot] = route
    sim.x[slot], sim.y[slot] = path.position(s, r)
    sim.heading[slot] = path.heading_at(s) + heading_offset
    sim.speed[slot] = speed
    sim.target_speed[slot] = target_speed
    sim.sign[slot] = sign
    sim.s[slot] = s
    sim.r[slot] = r
    sim.steps[slot] = 0
    sim.present[slot] = True
    return slot


def empty_simulator(scenario: str, **changes) -> Simulator:
    from dataclasses import replace

    sim = Simulator(scenario, replace(EMPTY_ROAD, **changes), seed=0)
    sim.reset()
    assert not sim.present.any()
    return sim


def still(sim: Simulator) -> np.ndarray:
    """Zero acceleration, zero steering for every slot."""
    return np.zeros((sim.num_slots, 2))


@pytest.fixture(scope="session")
def _medium_road_simulator():
    return empty_simulator("medium")


@pytest.fixture
def medium_road(_medium_road_simulator):
    """An empty medium junction (no car on the road, no start due); built once, reset per test."""
    sim = _medium_road_simulator
    sim.reset(seed=0)
    assert not sim.present.any()
    return sim


def view_pixel(sim: Simulator, ego: int, x: float, y: float) -> tuple[int, int]:
    """(row, column) of the world point ``(x, y)`` [m] in slot ``ego``'s 84x84 view
    (ego at the centre, heading up, 50 m across)."""
    import math

    dx, dy = x - sim.x[ego], y - sim.y[ego]
    h = sim.heading[ego]
    forward = dx * math.cos(h) + dy * math.sin(h)
    left = -dx * math.sin(h) + dy * math.cos(h)
    metres_per_px = 50.0 / 84.0
    return int(math.floor(42 - forward / metres_per_px)), int(math.floor(42 - left / metres_per_px))
