"""The learner's algorithm core: global network, optimizer, staleness rule, sigma schedule.

Pure and testable without processes (Sample Factory's learner/learner-worker split): the process
shell in ``learner.service`` feeds it decoded pushes and publishes what it returns.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch

from algo.policy import (Policy, PolicyConfig, ViewMismatch, describe_views, parameter_shapes, same_views, sigma_at,
                         views_record)


@dataclass(frozen=True)
class LearnerConfig:
    """Global-network settings."""

    learning_rate: float = 2.5e-4  # Adam on the global network
    max_staleness: int = 50  # refuse gradients computed on weights older than this many versions
    sigma_start: float = 0.65  # exploration sigma at the start (paper, Fig. 4)
    sigma_end: float = 0.05  # ... and at the end of its linear decay (paper, Fig. 4)
    sigma_decay_agent_steps: int = 5_000_000  # agent-steps over which sigma falls
    max_grad_norm: float = 100.0  # clip each episode's gradient sum to this L2 norm


class StaleGradient(Exception):
    """A push computed on weights older than the learner accepts."""


class LearnerCore:
    def __init__(self, config: LearnerConfig = LearnerConfig(), policy_config: PolicyConfig = PolicyConfig(),
                 seed: int = 0):
        torch.manual_seed(seed)
        self.config = config
        self.policy_config = policy_config
        self.policy = Policy(policy_config)
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=config.learning_rate)
        self.version = 0
        self.agent_steps = 0  # agent-steps behind every applied gradient: drives the sigma schedule
        self.shapes = parameter_shapes(self.policy)
        # the view square (side, centre ahead of the car) [m] the weights learn from: fixed by the
        # first push that says it, kept in checkpoints; None until then
        self.views: tuple[float, float] | None = None

    @property
    def sigma(self) -> float:
        c = self.config
        return sigma_at(self.agent_steps, c.sigma_decay_agent_steps, c.sigma_start, c.sigma_end)

    def staleness(self, base_version: int) -> int:
        return self.version - base_version

    def apply(self, gradients: dict[str, np.ndarray], base_version: int, agent_steps: int) -> int:
        """Apply one episode's gradient sum; returns the new version. Shapes must already match."""
        staleness = self.staleness(base_version)
        if staleness > self.config.max_staleness or staleness < 0:
            raise StaleGradient(f"computed on version {base_version}, learner at {self.version}")
        for name, p in self.policy.named_parameters():
            p.grad = torch.from_numpy(gradients[name])
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.config.max_grad_norm)
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        self.version += 1
        self.agent_steps += agent_steps
        return self.version

    def check_views(self, extent_m: float, shift_m: float) -> None:
        """Fix the run's view square on the first push that reports one (extent > 0); raise
        ``ViewMismatch`` for a push whose square differs: its agents see the junction through
        other pixels, so its gradient belongs to another network's inputs."""
        if not extent_m > 0:
            return  # the sender does not say
        if self.views is None:
            self.views = (float(extent_m), float(shift_m))
        elif not same_views(self.views, (extent_m, shift_m)):
            raise ViewMismatch(f"the actor's agents see {describe_views((extent_m, shift_m))}; this run learns from "
                               f"{describe_views(self.views)}")

    def init_weights(self, policy: Policy) -> None:
        """Start from another policy's weights (a curriculum across scenarios); version stays 0."""
        if asdict(policy.config) != asdict(self.policy_config):
            raise ValueError(f"initial weights are for the network {asdict(policy.config)}, "
                             f"not this learner's {asdict(self.policy_config)}")
        self.policy.load_state_dict(policy.state_dict())

    def weights(self) -> dict[str, np.ndarray]:
        return {name: p.detach().numpy().copy() for name, p in self.policy.named_parameters()}

    # checkpoints --------------------------------------------------------------------------------

    def state_dict(self) -> dict:
        return {
            "version": self.version, "agent_steps": self.agent_steps, "policy": self.policy.state_dict(),
            "optimizer": self.optimizer.state_dict(), "config": asdict(self.config),
            "policy_config": asdict(self.policy_config),
            "views": views_record(*self.views) if self.views is not None else None,
        }

    def load_state_dict(self, state: dict) -> None:
        if state.get("policy_config") != asdict(self.policy_config):
            raise ValueError(f"checkpoint network {state.get('policy_config')} does not match "
                             f"this learner's {asdict(self.policy_config)}")
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.version = int(state["version"])
        self.agent_steps = int(state["agent_steps"])
        views = state.get("views")  # absent in checkpoints written before it existed
        self.views = (float(views["extent_m"]), float(views["shift_m"])) if views else None
