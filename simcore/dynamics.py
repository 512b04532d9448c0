"""Vehicle dynamics and footprints: small pure functions on plain arrays.

Kinematic bicycle model (paper, "Training settings", ref. [bicycle]) with the reference point
at the centre of the wheelbase, as in HighwayEnv's ``Vehicle``: slip angle
``beta = atan(tan(steering) / 2)``, velocity along ``heading + beta``, yaw rate
``speed * sin(beta) / (wheelbase / 2)``. All functions accept floats or numpy arrays.
"""

from __future__ import annotations

import numpy as np

DT = 0.1  # simulation step: the network acts every 100 ms [s] (paper, "Training settings")
STANDING_MPS = 0.5  # a car slower than this stands: the scripted driver's patience and the standing-time input count [m/s]
MAX_STEERING = 0.2  # [rad] (paper, "Training settings")
MAX_ACCELERATION = 3.0  # [m/s^2] (paper, "Training settings")
MAX_SPEED = 20.0  # physical cap; agents are rewarded for staying at or under target speed [m/s]
VEHICLE_LENGTH = 4.5  # [m]
VEHICLE_WIDTH = 1.8  # [m]
WHEELBASE = 2.7  # [m]
INITIAL_SPEED_RANGE = (3.0, 6.0)  # [m/s] (paper, "Training settings")
TARGET_SPEED_RANGE = (7.0, 10.0)  # [m/s] (paper, "Training settings")


def bicycle_step(x, y, heading, speed, acceleration, steering, dt: float = DT):
    """Advance the kinematic bicycle by ``dt`` seconds; returns ``(x, y, heading, speed)``.

    Units: x, y [m], heading [rad], speed [m/s], acceleration [m/s^2], steering [rad].
    Speed is clamped to [0, MAX_SPEED]: the model does not drive backwards.
    """
    beta = np.arctan(0.5 * np.tan(steering))
    direction = heading + beta
    x_next = x + speed * np.cos(direction) * dt
    y_next = y + speed * np.sin(direction) * dt
    heading_next = heading + speed * np.sin(beta) / (0.5 * WHEELBASE) * dt
    speed_next = np.clip(speed + acceleration * dt, 0.0, MAX_SPEED)
    return x_next, y_next, heading_next, speed_next


def turning_radius(steering: float) -> float:
    """Closed-form radius [m] of the circle the reference point follows at constant steering [rad] (either sign)."""
    beta = np.arctan(0.5 * np.tan(steering))
    return float(abs(0.5 * WHEELBASE / np.sin(beta)))


def box_corners(x, y, heading, length: float = VEHICLE_LENGTH, width: float = VEHICLE_WIDTH) -> np.ndarray:
    """Corners of oriented boxes, shape [N, 4, 2], counter-clockwise from front-left... [m]."""
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    y = np.atleast_1d(np.asarray(y, dtype=np.float64))
    heading = np.atleast_1d(np.asarray(heading, dtype=np.float64))
    c, s = np.cos(heading), np.sin(heading)
    half_l, half_w = 0.5 * length, 0.5 * width
    # local corners (forward, left): front-left, rear-left, rear-right, front-right
    local = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])
    cx = x[:, None] + local[None, :, 0] * c[:, None] - local[None, :, 1] * s[:, None]
    cy = y[:, None] + local[None, :, 0] * s[:, None] + local[None, :, 1] * c[:, None]
    return np.stack([cx, cy], axis=-1)


def boxes_overlap(corners_a: np.ndarray, corners_b: np.ndarray) -> np.ndarray:
    """Separating-axis test between pairs of oriented boxes, each [N, 4, 2]; returns [N] bool."""
    overlap = np.ones(corners_a.shape[0], dtype=bool)
    for corners in (corners_a, corners_b):
        # two edge directions per box are its two candidate separating axes
        for edge in (corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 1]):
            axis = np.stack([-edge[:, 1], edge[:, 0]], axis=-1)  # [N, 2]
            proj_a = np.einsum("nkd,nd->nk", corners_a, axis)
            proj_b = np.einsum("nkd,nd->nk", corners_b, axis)
            separated = (proj_a.max(axis=1) < proj_b.min(axis=1)) | (proj_b.max(axis=1) < proj_a.min(axis=1))
            overlap &= ~separated
    return overlap
