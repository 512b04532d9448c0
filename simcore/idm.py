"""The Intelligent Driver Model (Treiber, Hennecke and Helbing, 2000) for scripted traffic.

Paper, "Comparison with TTC method": traffic cars follow the centre of their paths and control
their speed with the IDM. The acceleration of a car at speed ``v`` behind a leader at net gap
``s`` (bumper to bumper) closing in at ``dv = v - v_leader`` is

    a = a_max * (1 - (v / v0)^delta - (s*(v, dv) / s)^2)
    s*(v, dv) = s0 + v T + v dv / (2 sqrt(a_max b))

With no leader the interaction term vanishes. In steady following (dv = 0, a = 0) the gap is
``s_e(v) = (s0 + v T) / sqrt(1 - (v / v0)^delta)`` (``equilibrium_gap``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class IDMParameters:
    """Treiber's city-traffic values, except a_max, kept within the paper's 3 m/s^2 limit."""

    time_gap_s: float = 1.5  # T: desired time headway [s]
    minimum_gap_m: float = 2.0  # s0: jam distance, kept when stopped behind a car [m]
    max_acceleration: float = 1.5  # a_max [m/s^2]
    comfortable_deceleration: float = 2.0  # b [m/s^2]
    exponent: float = 4.0  # delta: how the free-road acceleration falls towards v0
    max_deceleration: float = 6.0  # physical braking limit applied to the result [m/s^2]


def desired_gap(speed, closing_speed, p: IDMParameters = IDMParameters()):
    """s*(v, dv) [m]; never below the jam distance s0."""
    braking_scale = 2.0 * math.sqrt(p.max_acceleration * p.comfortable_deceleration)
    dynamic = speed * p.time_gap_s + speed * closing_speed / braking_scale
    return p.minimum_gap_m + np.maximum(0.0, dynamic)


def idm_acceleration(speed, desired_speed, gap=np.inf, closing_speed=0.0, p: IDMParameters = IDMParameters()):
    """IDM acceleration [m/s^2] for speed [m/s], desired speed v0 [m/s], net gap [m] to the
    leader (inf: free road) and closing speed v - v_leader [m/s]; arrays broadcast."""
    speed = np.asarray(speed, dtype=np.float64)
    free = 1.0 - (speed / desired_speed) ** p.exponent
    gap = np.maximum(np.asarray(gap, dtype=np.float64), 1e-3)
    interaction = np.where(np.isinf(gap), 0.0, (desired_gap(speed, closing_speed, p) / gap) ** 2)
    return np.clip(p.max_acceleration * (free - interaction), -p.max_deceleration, p.max_acceleration)


def equilibrium_gap(speed: float, desired_speed: float, p: IDMParameters = IDMParameters()) -> float:
    """Net gap [m] at which a car following a leader of equal speed neither speeds up nor brakes."""
    if not 0.0 <= speed < desired_speed:
        raise ValueError(f"steady following needs 0 <= speed < desired speed, got {speed}, {desired_speed}")
    return (p.minimum_gap_m + speed * p.time_gap_s) / math.sqrt(1.0 - (speed / desired_speed) ** p.exponent)
