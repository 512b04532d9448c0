"""Reward shaping (paper, section "Reward Shaping"): two streams, one per network head.

    R_acc = r_speed + r_terminal_acc          (paper, eq. R_acc)
    R_sa  = r_localization + r_terminal_sa    (paper, eq. R_sa)

Pure functions on numpy arrays; no simulator state.
"""

from __future__ import annotations

import enum

import numpy as np

XI = 0.005  # weight of r_speed (paper: xi = 0.005)
PHI = 0.05  # weight of the heading term of r_localization (paper: phi = 0.05)
PSI = 0.05  # weight of the distance term of r_localization (paper: psi = 0.05)


class EndReason(enum.IntEnum):
    """Why an episode ended. Values are stable: they travel in episode statistics."""

    RUNNING = 0
    GOAL = 1  # reached the end of its route (terminal)
    CRASH = 2  # footprint overlapped another car's (terminal)
    OFF_PATH = 3  # centre left its route corridor, or heading off by more than 90 deg (terminal)
    TIME_OVER = 4  # ran past the scenario's time limit (terminal: the paper rewards it -1)
    SIGN_CHANGE = 5  # cut short when the signs were redrawn ("hard"); truncated, no terminal reward
    HORIZON = 6  # cut short by the environment's step budget; truncated, no terminal reward


END_REASON_NAMES = {reason: reason.name.lower() for reason in EndReason}
TERMINAL_REASONS = (EndReason.GOAL, EndReason.CRASH, EndReason.OFF_PATH, EndReason.TIME_OVER)

# r_terminal per end reason, (acceleration stream, steering stream) (paper, "Reward Shaping")
TERMINAL_REWARD = {
    EndReason.GOAL: (1.0, 1.0),
    EndReason.OFF_PATH: (0.0, -1.0),
    EndReason.TIME_OVER: (-1.0, 0.0),
    # crash: -1 against a car with priority over the ego ("black"), -0.5 otherwise ("white")
    EndReason.CRASH: (-0.5, 0.0),
}
CRASH_INTO_HIGHER_PRIORITY = -1.0


def speed_reward(speed: np.ndarray, target_speed: np.ndarray) -> np.ndarray:
    """r_speed = xi * speed / target_speed (paper, eq. r_speed).

    The simulator caps every car's speed at its target speed, "the maximum velocity the vehicle
    should not exceed" (paper, "Training settings"), so this lies in [0, xi].
    """
    return XI * (speed / target_speed)


def localization_reward(heading_error: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """r_localization = phi * cos(h_a - h_p) - psi * d (paper, eq. r_localization).

    The paper prints ``+ psi * d``, which would reward leaving the centre line; its text calls the
    term a penalisation for differing from the centre, so the distance term is subtracted here.
    """
    return PHI * np.cos(heading_error) - PSI * np.abs(distance)


def terminal_rewards(reasons: np.ndarray, crashed_into_higher: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r_terminal for both streams, given end reasons [N] and whether a crash hit a "black" car [N]."""
    acc = np.zeros(reasons.shape, dtype=np.float64)
    sa = np.zeros(reasons.shape, dtype=np.float64)
    for reason, (value_acc, value_sa) in TERMINAL_REWARD.items():
        mask = reasons == reason
        acc[mask] = value_acc
        sa[mask] = value_sa
    acc[(reasons == EndReason.CRASH) & crashed_into_higher] = CRASH_INTO_HIGHER_PRIORITY
    return acc, sa
