"""A scripted driver: pure-pursuit path following, speed keeping and a simple right-of-way rule.

It reads the simulator's state directly (privileged information a learner never gets) and
exists so that anyone can watch the simulator, benchmark it and test it without a trained
model. It is not the paper's TTC baseline.
"""

from __future__ import annotations

import math

import numpy as np

from simcore.dynamics import MAX_ACCELERATION, MAX_STEERING, VEHICLE_LENGTH, WHEELBASE
from simcore.simulator import Simulator

STOP_MARGIN_M = 2.0  # stop this far before a conflict zone [m]
FOLLOW_GAP_M = 8.0  # keep at least this gap to a car ahead [m]


class ScriptedDriver:
    """Acts for every slot of a ``Simulator``; ``act()`` returns a ``[slots, 2]`` action array."""

    def __init__(self, sim: Simulator, speed_fraction: float = 0.9, yield_to_priority: bool = True):
        self.sim = sim
        self.speed_fraction = speed_fraction  # cruise at this fraction of the target speed
        self.yield_to_priority = yield_to_priority

    def act(self) -> np.ndarray:
        sim = self.sim
        actions = np.zeros((sim.num_slots, 2))
        idx = np.flatnonzero(sim.present)
        if len(idx) == 0:
            return actions
        higher = sim.priorities(idx) if self.yield_to_priority else np.zeros((len(idx),) * 2, bool)
        table = sim.priority
        for a, slot in enumerate(idx.tolist()):
            path = sim._route_paths[sim.route[slot]]
            speed = sim.speed[slot]
            lookahead = max(6.0, 1.2 * speed)
            tx, ty = path.position(min(sim.s[slot] + lookahead, path.length + lookahead), 0.0)
            alpha = math.atan2(ty - sim.y[slot], tx - sim.x[slot]) - sim.heading[slot]
            steering = math.atan2(2.0 * WHEELBASE * math.sin(alpha), lookahead)
            desired = self.speed_fraction * sim.target_speed[slot]
            acceleration = 1.5 * (desired - speed)
            # stop before a conflict zone while a car with priority has not cleared it
            for b, other in enumerate(idx.tolist()):
                if not higher[a, b]:
                    continue
                zone_start = table.zone_start[sim.route[slot], sim.route[other]]
                gap = zone_start - STOP_MARGIN_M - (sim.s[slot] + 0.5 * VEHICLE_LENGTH)
                if gap < 0.0 and sim.s[slot] + 0.5 * VEHICLE_LENGTH > zone_start:
                    continue  # already inside: better to clear it
                braking = -speed * speed / (2.0 * max(gap, 0.5))
                if gap < 3.0 * speed + 5.0:
                    acceleration = min(acceleration, braking if gap > 0.5 else -MAX_ACCELERATION)
            actions[a if False else slot] = (acceleration, steering)
        np.clip(actions[:, 0], -MAX_ACCELERATION, MAX_ACCELERATION, out=actions[:, 0])
        np.clip(actions[:, 1], -MAX_STEERING, MAX_STEERING, out=actions[:, 1])
        return actions
