"""Drive a simulator's learner slots with a trained policy (no learning): for evaluation.

Every car uses the same (global) weights, so all cars on the road act in one batched forward
pass. By default the cars take the Gaussian mean; ``sigma`` > 0 samples as in training.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from algo.policy import ACTION_SCALE, Policy, load_policy, preprocess


def export_policy(checkpoint: str | Path, out: str | Path, note: str = "") -> Path:
    """Write only what evaluation needs (network sizes, weights, provenance): a small file for models/."""
    policy = load_policy(checkpoint)
    state = torch.load(Path(checkpoint), weights_only=False, map_location="cpu")
    out = Path(out)
    torch.save({"policy": policy.state_dict(), "policy_config": state["policy_config"],
                "version": state.get("version"), "agent_steps": state.get("agent_steps"),
                "run_id": state.get("run_id"), "note": note}, out)
    return out


class PolicyDriver:
    """Acts for every learner slot of a ``Simulator`` from the newest ``StepResult``."""

    def __init__(self, sim, policy: Policy, sigma: float = 0.0, seed: int | None = None):
        self.sim = sim
        self.policy = policy
        self.sigma = sigma
        self._rng = np.random.default_rng(seed)

    def act(self, result) -> np.ndarray:
        actions = np.zeros((self.sim.num_slots, 2))
        active = np.flatnonzero(self.sim.learners_present)
        if len(active) == 0:
            return actions
        views, scalars = preprocess(result.views[active], result.scalars[active])
        with torch.no_grad():
            mu_acc, _, mu_sa, _ = self.policy(views, scalars)
        means = np.stack([mu_acc.numpy(), mu_sa.numpy()], axis=1)
        if self.sigma > 0:
            means = means + self.sigma * self._rng.standard_normal(means.shape)
        actions[active] = np.clip(means, -1.0, 1.0) * ACTION_SCALE
        return actions
