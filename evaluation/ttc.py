"""Time to collision as the paper's TTC baseline computes it (paper, "Comparison with TTC method").

"Considering an imaginary line aligned with the longitudinal axis of the ego-agent, the TTC is
computed as the time a traffic car reaches this line, assuming that it drives with constant
speed." A car moving parallel to the line or away from it never reaches it: infinite TTC.
"""

from __future__ import annotations

import numpy as np


def time_to_axis(ego_x: float, ego_y: float, ego_heading: float, car_x, car_y, car_heading, car_speed,
                 ego_half_width_m: float = 0.0, car_half_length_m: float = 0.0, car_half_width_m: float = 0.0,
                 ahead_only: bool = False):
    """Seconds until each car, at constant velocity, reaches the ego's longitudinal axis.

    Positions [m], headings [rad], speeds [m/s]; car arguments may be arrays. With the default
    zero sizes this is the paper's definition for the cars' centres and a line. With sizes, the
    line is the strip the ego's body sweeps (``ego_half_width_m`` either side) and a car reaches
    it with the nearest edge of its body; a car whose body is on the strip has TTC 0, standing
    or not (a car stopped across the ego's path is a car it would hit). ``ahead_only`` ignores
    cars whose centre is behind the ego's.
    """
    car_x, car_y = np.asarray(car_x, dtype=np.float64), np.asarray(car_y, dtype=np.float64)
    car_heading = np.asarray(car_heading, dtype=np.float64)
    # signed distance of the car from the axis (positive on the ego's left) and its rate of change
    normal_x, normal_y = -np.sin(ego_heading), np.cos(ego_heading)
    offset = (car_x - ego_x) * normal_x + (car_y - ego_y) * normal_y
    rate = np.asarray(car_speed) * (np.cos(car_heading) * normal_x + np.sin(car_heading) * normal_y)
    # half the car body's extent across the axis, and the gap between body and strip
    relative = car_heading - ego_heading
    extent = car_half_length_m * np.abs(np.sin(relative)) + car_half_width_m * np.abs(np.cos(relative))
    gap = np.abs(offset) - extent - ego_half_width_m
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(offset * rate < 0.0, gap / np.abs(rate), np.inf)
    touching = gap <= 1e-9 if (ego_half_width_m or car_half_length_m or car_half_width_m) else np.abs(offset) < 1e-9
    ttc = np.where(touching, 0.0, ttc)
    if ahead_only:
        along = (car_x - ego_x) * np.cos(ego_heading) + (car_y - ego_y) * np.sin(ego_heading)
        ttc = np.where(along > 0.0, ttc, np.inf)
    return ttc


def lowest_ttc(ego_x: float, ego_y: float, ego_heading: float, cars: np.ndarray, **sizes) -> float:
    """The smallest TTC over traffic cars given as rows of (x, y, heading, speed); inf if none.
    ``sizes``: the keyword arguments of ``time_to_axis`` after the cars."""
    if len(cars) == 0:
        return float("inf")
    cars = np.asarray(cars, dtype=np.float64)
    return float(time_to_axis(ego_x, ego_y, ego_heading, cars[:, 0], cars[:, 1], cars[:, 2], cars[:, 3],
                              **sizes).min())


class TTCDriver:
    """The paper's rule-based baseline for the learner slots of a ``Simulator``.

    Each car decelerates to stop at its stop line, then waits until the lowest TTC over all
    traffic cars exceeds ``threshold_s`` and goes at +3 m/s^2 along its route's centre (pure
    pursuit steering: the baseline does not predict steering). Once going it does not stop again.
    TTC counts car bodies, not centres, and only cars ahead (``time_to_axis`` with sizes): a car
    standing across the ego's path, e.g. queued in the junction, has TTC 0, not infinity.
    """

    def __init__(self, sim, threshold_s: float, stop_margin_m: float = 0.5):
        if not threshold_s > 0:
            raise ValueError(f"the TTC threshold must be > 0 s, got {threshold_s}")
        self.sim = sim
        self.threshold_s = threshold_s
        self.stop_margin_m = stop_margin_m  # stop with the front this far before the line [m]
        self.going = np.zeros(sim.num_slots, dtype=bool)

    def act(self) -> np.ndarray:
        import math

        from simcore.dynamics import MAX_ACCELERATION, MAX_STEERING, VEHICLE_LENGTH, VEHICLE_WIDTH, WHEELBASE

        sim = self.sim
        actions = np.zeros((sim.num_slots, 2))
        self.going[~sim.learners_present] = False
        traffic = sim.num_slots + np.flatnonzero(sim.present[sim.num_slots:])
        cars = np.stack([sim.x[traffic], sim.y[traffic], sim.heading[traffic], sim.speed[traffic]], axis=1)
        for slot in np.flatnonzero(sim.learners_present).tolist():
            route = sim.intersection.routes[sim.route[slot]]
            speed = sim.speed[slot]
            lookahead = max(6.0, 1.2 * speed)
            tx, ty = route.path.position(sim.s[slot] + lookahead, 0.0)
            alpha = math.atan2(ty - sim.y[slot], tx - sim.x[slot]) - sim.heading[slot]
            steering = math.atan2(2.0 * WHEELBASE * math.sin(alpha), lookahead)
            to_line = route.junction_entry_s - self.stop_margin_m - (sim.s[slot] + 0.5 * VEHICLE_LENGTH)
            if not self.going[slot]:
                stopped = speed < 0.1 and to_line < 1.0
                ttc = lowest_ttc(sim.x[slot], sim.y[slot], sim.heading[slot], cars,
                                 ego_half_width_m=0.5 * VEHICLE_WIDTH, car_half_length_m=0.5 * VEHICLE_LENGTH,
                                 car_half_width_m=0.5 * VEHICLE_WIDTH, ahead_only=True)
                if stopped and ttc > self.threshold_s:
                    self.going[slot] = True
            if self.going[slot]:
                acceleration = MAX_ACCELERATION
            elif to_line > 0.05:
                acceleration = -speed * speed / (2.0 * to_line)  # constant deceleration to the line
                if speed < 1.0 and to_line > 2.0:
                    acceleration = 1.0  # creep up to the line
            else:
                acceleration = -MAX_ACCELERATION
            actions[slot] = (np.clip(acceleration, -MAX_ACCELERATION, MAX_ACCELERATION),
                             np.clip(steering, -MAX_STEERING, MAX_STEERING))
        return actions
