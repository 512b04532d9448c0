"""Time to collision as the paper's TTC baseline computes it (paper, "Comparison with TTC method").

"Considering an imaginary line aligned with the longitudinal axis of the ego-agent, the TTC is
computed as the time a traffic car reaches this line, assuming that it drives with constant
speed." A car moving parallel to the line or away from it never reaches it: infinite TTC.
"""

from __future__ import annotations

import numpy as np


def time_to_axis(ego_x: float, ego_y: float, ego_heading: float, car_x, car_y, car_heading, car_speed):
    """Seconds until each car's centre, at constant velocity, crosses the ego's longitudinal axis.

    Positions [m], headings [rad], speeds [m/s]; car arguments may be arrays. A car already on
    the line has TTC 0.
    """
    car_x, car_y = np.asarray(car_x, dtype=np.float64), np.asarray(car_y, dtype=np.float64)
    # signed distance of the car from the axis (positive on the ego's left) and its rate of change
    normal_x, normal_y = -np.sin(ego_heading), np.cos(ego_heading)
    offset = (car_x - ego_x) * normal_x + (car_y - ego_y) * normal_y
    rate = np.asarray(car_speed) * (np.cos(car_heading) * normal_x + np.sin(car_heading) * normal_y)
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(offset * rate < 0.0, -offset / rate, np.inf)
    return np.where(np.abs(offset) < 1e-9, 0.0, ttc)


def lowest_ttc(ego_x: float, ego_y: float, ego_heading: float, cars: np.ndarray) -> float:
    """The smallest TTC over traffic cars given as rows of (x, y, heading, speed); inf if none."""
    if len(cars) == 0:
        return float("inf")
    cars = np.asarray(cars, dtype=np.float64)
    return float(time_to_axis(ego_x, ego_y, ego_heading, cars[:, 0], cars[:, 1], cars[:, 2], cars[:, 3]).min())
