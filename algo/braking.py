"""Emergency braking read from the views: brake for a car in the ego's own path (not in the paper).

The hard students crash mostly in pairs where each car made a mistake: one did not give way, and
the other, with the right of way, drove on into the car already in its path (docs/imitation.md,
"What the best hard student's crashes look like"). The scripted teacher brakes for such a car; the
students seldom learnt to. ``EmergencyBraking`` is a rule on top of a trained policy that reads
only what the policy reads, the four frames of its own views and its speed:

- the *gap* is the distance [m] from the middle of the ego's front to the nearest pixel ahead
  that shows a car (obstacles channel, any shade) on the ego's path corridor (path channel), in
  the newest frame and in the oldest (0.3 s before);
- the *closing speed* is how fast that gap shrank over those 0.3 s [m/s], or the ego's speed
  when either frame shows no car on the path ahead;
- a car moving at 0.5 m/s or more brakes when the gap less ``margin_m`` is shorter than what
  the closing speed needs to stop at ``deceleration_mps2`` after ``reaction_s``:
  ``gap - margin < closing^2 / (2 deceleration) + closing * reaction``. It then takes the lower of
  the policy's acceleration and ``-closing^2 / (2 (gap - margin))``, bounded to 1-3 m/s^2 (3, the
  action's limit, once the gap is within the margin);
- a car standing (under 0.5 m/s) with a car on its path within ``margin_m`` does not accelerate.

The rule knows nothing of the right of way and nothing the views do not show; it is a fixed
function of the observation, as a driver-assistance system would be. It is stored with the
weights (a checkpoint's ``emergency_braking`` entry) and ``evaluation.policy.PolicyDriver``
applies it to every car it drives. It uses numpy only.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np

from algo.entries import settings_from_entry
from simcore.dynamics import DT, MAX_ACCELERATION, VEHICLE_LENGTH
from simcore.simulator import HISTORY
from simcore.views import CHANNELS, PATH, VIEW_SIZE_PX

MOVING_MPS = 0.5  # below this a car stands (simcore.simulator.STANDING_MPS)
SEARCH_M = 20.0  # pixels this far from the ego's front at most are searched [m]
FRONT_CLEARANCE_M = 0.3  # pixels must lie this far ahead of the ego's front (its own body is not in its way) [m]
MIN_BRAKING_MPS2 = 1.0  # the least deceleration the rule commands once it acts [m/s^2]


@lru_cache(maxsize=8)
def _searched_pixels(extent_m: float, shift_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The view pixels searched for a car (ahead of the ego's front by FRONT_CLEARANCE_M, within
    SEARCH_M of it), as flat indices into an 84 x 84 plane, and their distances [m] from the middle
    of the ego's front, for a view square ``extent_m`` wide whose centre lies ``shift_m`` ahead of
    the car (``simcore.views``: the car points up, row 0 is farthest ahead). About a quarter of
    the plane at the default sizes."""
    metres_per_px = extent_m / VIEW_SIZE_PX
    centres = (VIEW_SIZE_PX / 2.0 - np.arange(VIEW_SIZE_PX) - 0.5) * metres_per_px
    forward, left = np.meshgrid(centres + shift_m, centres, indexing="ij")
    front = 0.5 * VEHICLE_LENGTH
    distance = np.hypot(np.maximum(forward - front, 0.0), left)
    searched = np.flatnonzero((forward > front + FRONT_CLEARANCE_M) & (distance < SEARCH_M))
    return searched, distance.ravel()[searched]


def path_gaps(views: np.ndarray, frame: int, extent_m: float = 50.0, shift_m: float = 0.0) -> np.ndarray:
    """For uint8 views [B, 16, 84, 84]: the distance [m] from each ego's front to the nearest car
    on its path ahead in frame ``frame`` (0 the oldest, 3 the newest); inf where there is none."""
    searched, distance = _searched_pixels(float(extent_m), float(shift_m))
    if len(views) == 0 or len(searched) == 0:
        return np.full(len(views), np.inf)
    planes = views[:, [CHANNELS.index("path") * HISTORY + frame, CHANNELS.index("obstacles") * HISTORY + frame]]
    path, cars = planes.reshape(len(views), 2, -1)[:, :, searched].transpose(1, 0, 2)
    return np.where((path == PATH) & (cars != 0), distance, np.inf).min(axis=1)


@dataclass(frozen=True)
class EmergencyBraking:
    """Brake for a car on the ego's path ahead, seen in the views (module docstring)."""

    margin_m: float = 1.5  # gap kept to the car in the path [m]
    reaction_s: float = 0.5  # time the trigger allows before braking would start [s]
    deceleration_mps2: float = 2.0  # braking the trigger distance assumes [m/s^2]

    def __post_init__(self):
        for name, low in (("margin_m", 0.0), ("reaction_s", 0.0), ("deceleration_mps2", 0.1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < low:
                raise ValueError(f"emergency braking: {name} must be a number >= {low:g}, got {value!r}")
        if self.deceleration_mps2 > MAX_ACCELERATION:
            raise ValueError(f"emergency braking: deceleration_mps2 must not exceed the action's limit "
                             f"{MAX_ACCELERATION:g} m/s^2, got {self.deceleration_mps2!r}")

    def apply(self, views: np.ndarray, speeds_mps: np.ndarray, acceleration_mps2: np.ndarray,
              extent_m: float = 50.0, shift_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The accelerations [B] (m/s^2) after the rule, and where it braked [B] bool, for uint8
        views [B, 16, 84, 84] drawn through a square ``extent_m`` wide centred ``shift_m`` ahead,
        the cars' speeds [B] and the policy's accelerations [B]."""
        now = path_gaps(views, HISTORY - 1, extent_m, shift_m)
        before = path_gaps(views, 0, extent_m, shift_m)
        speeds = np.asarray(speeds_mps, dtype=np.float64)
        seen = np.isfinite(now) & np.isfinite(before)
        with np.errstate(invalid="ignore"):
            closing = np.where(seen, (before - now) / ((HISTORY - 1) * DT), speeds)
        closing = np.maximum(closing, 0.0)
        room = now - self.margin_m
        moving = speeds >= MOVING_MPS
        brakes = moving & (closing > MOVING_MPS) & (
            room < closing * closing / (2.0 * self.deceleration_mps2) + closing * self.reaction_s)
        need = np.where(room > 0.1, closing * closing / (2.0 * np.maximum(room, 0.1)), MAX_ACCELERATION)
        need = np.clip(need, MIN_BRAKING_MPS2, MAX_ACCELERATION)
        out = np.array(acceleration_mps2, dtype=np.float64)
        out[brakes] = np.minimum(out[brakes], -need[brakes])
        holds = ~moving & (now < self.margin_m)
        out[holds] = np.minimum(out[holds], 0.0)
        return out, brakes

    def record(self) -> dict:
        """The checkpoint's ``emergency_braking`` entry."""
        return asdict(self)

    def describe(self) -> str:
        return (f"emergency braking for a car on the path ahead (margin {self.margin_m:g} m, reaction "
                f"{self.reaction_s:g} s, {self.deceleration_mps2:g} m/s^2)")


def emergency_braking_from(source: str, record) -> EmergencyBraking | None:
    """The rule of a checkpoint's ``emergency_braking`` entry (None: no rule); ValueError naming
    ``source`` when the entry is not one."""
    return None if record is None else settings_from_entry(source, "emergency_braking", EmergencyBraking, record)
