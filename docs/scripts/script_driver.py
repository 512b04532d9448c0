"""The driver a docs script drives with: the scripted driver, or a trained policy (``--checkpoint``).

Both act from the newest ``StepResult`` and keep how long each car has stood (under
``STANDING_MPS``, the scripted driver's own count), so a script can print the same things for
either. A policy needs the views, so the script must build its ``Simulator`` with
``observe=needs_views(args)``.
"""

from __future__ import annotations

import argparse

import numpy as np

from simcore.controller import STANDING_MPS, DriverOptions, scripted_driver
from simcore.dynamics import DT

# the hard students' teacher: the scripted driver limited to the views, slowing to 2 m/s by its own
# sign, braking for blockers, waiting outside zones, breaking cycles, its default 4 s / 8 s patience
HARD_TEACHER = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                             wait_outside_zones=True, break_wait_cycles=True)


def add_checkpoint_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", default=None,
                        help="drive with this trained policy (a checkpoint or models/*.pt) instead of the scripted "
                             "driver; the driver options are then ignored")


def needs_views(args: argparse.Namespace) -> bool:
    return args.checkpoint is not None


class ScriptDriver:
    def __init__(self, sim, options: DriverOptions, checkpoint: str | None = None):
        self.sim = sim
        self.checkpoint = checkpoint
        if checkpoint is None:
            self._scripted = scripted_driver(sim, options)
            self.options = options
        else:
            from evaluation.policy import PolicyDriver, check_checkpoint
            from algo.policy import load_policy

            check_checkpoint(checkpoint, sim.spec)
            self._policy = PolicyDriver(sim, load_policy(checkpoint))
            self._standing = np.zeros(sim.num_slots)

    def act(self, result) -> np.ndarray:
        """Actions [slots, 2] (m/s^2, rad) for the cars on the road after ``result``."""
        if self.checkpoint is None:
            return self._scripted.act()
        learners = self.sim.learners_present
        standing = learners & (self.sim.speed[: self.sim.num_slots] < STANDING_MPS)
        self._standing = np.where(standing, self._standing + DT, 0.0)
        return self._policy.act(result)

    def standing_s(self, slot: int) -> float:
        """How long the car in ``slot`` has stood [s] (0 for a slot that is not a learner's)."""
        if slot >= self.sim.num_slots:
            return 0.0
        return float(self._scripted._standing_s[slot] if self.checkpoint is None else self._standing[slot])

    def record(self) -> dict:
        """What drove, for the script's JSON."""
        return {"checkpoint": self.checkpoint} if self.checkpoint is not None else self.options.record()
