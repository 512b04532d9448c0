"""Delayed A3C (paper, sections "Related works" and "Neural Network Architecture").

Each agent begins its episode with a local copy of the newest global weights. Every
``update_interval`` steps (and when the episode ends) it computes n-step returns and advantages
for both reward streams, takes a gradient step on its local copy, and adds that gradient to its
episode sum. When the episode ends the whole sum goes to the learner, tagged with the version
of the weights the episode started from; the learner applies it to the global network.

This module is pure computation: no transport, no processes. ``ActorCore`` runs one simulator
with one ``EpisodeLearner`` per car on the road and hands back finished episodes' gradients.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from algo.policy import ACTION_SCALE, Policy, PolicyConfig
from algo.stacked import (GRID, HEADS, PATCH_FEATURES, after_conv1, conv1, conv1_gradients, first_layer_matrix,
                          patches)
from simcore.simulator import SCALARS, Simulator, StepResult

LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@dataclass(frozen=True)
class DA3CConfig:
    """Agent-side D-A3C settings (the paper gives none of these numbers; ours are documented)."""

    gamma: float = 0.99  # discount factor of both reward streams
    update_interval: int = 20  # steps between an agent's local updates (n of the n-step returns)
    local_learning_rate: float = 1e-3  # SGD step on the agent's local copy
    value_coef: float = 0.5  # weight of the value losses against the policy losses
    max_grad_norm: float = 40.0  # clip each local gradient to this L2 norm
    # AR(1) coefficient of each car's acceleration noise per 0.1 s step: 0 draws fresh noise every
    # step (the paper); 0.95 keeps a deviation for about 2 s, so a car sometimes brakes or speeds
    # up for long enough to change who reaches a conflict zone first (see ``ExplorationNoise``)
    noise_correlation: float = 0.0
    # weight of a cost on the squared acceleration mean, acceleration_cost * mu_acc^2 per step
    # (normalised units; not in the paper, 0 leaves it out). With the speed capped at the target
    # speed every mean above "hold" is free, so without it mu_acc drifts to tanh's +1, where the
    # exploration noise almost never brakes and tanh's slope is ~0
    # (docs/training.md#giving-way-why-our-agents-have-not-learned-it-yet)
    acceleration_cost: float = 0.0
    # lambda of generalized advantage estimation (Schulman et al. 2016) for the policy gradient; 1
    # gives the paper's A_t = R_t - v(s_t) exactly, lower values weight the critic's later estimates
    # more and the segment's far rewards less (less variance, more bias). The value target stays R_t.
    gae_lambda: float = 1.0


class ExplorationNoise:
    """Per-car Gaussian exploration noise on the acceleration, optionally correlated in time.

    The acceleration noise is AR(1): eps_t = rho * eps_{t-1} + sqrt(1 - rho^2) * sigma * xi_t,
    so each step's noise has standard deviation sigma whatever rho (a new car starts from the
    stationary law). The steering noise stays independent (rho = 0): a held steering error only
    takes the car off its path. The previous noise is part of the car's state, so given it the
    action is Gaussian around mu_t + rho * eps_{t-1} with standard deviation
    sigma * sqrt(1 - rho^2): ``step`` returns the fresh part, and the policy gradient uses
    ``log_prob_sigmas`` (paper, eq. 4 with that sigma). rho = 0 is the paper's noise.

    For rho > 0 this is an approximation: eps_{t-1} = a_{t-1} - mu_{t-1} depends on the weights,
    and the exact trajectory score would weight grad mu_t by (A_t xi_t - rho A_{t+1} xi_{t+1}).
    Keeping the first term credits mu_t with a deviation that lasts ~1/(1-rho) steps
    (docs/training.md, "--noise-correlation").
    """

    def __init__(self, slots: int, acceleration_correlation: float, rng: np.random.Generator):
        if not 0.0 <= acceleration_correlation < 1.0:
            raise ValueError(f"noise correlation must be in [0, 1), got {acceleration_correlation}")
        self.correlation = np.array([acceleration_correlation, 0.0], np.float32)  # acc, sa
        self.innovation_scale = np.sqrt(1.0 - self.correlation ** 2).astype(np.float32)
        self._rng = rng
        self.noise = np.zeros((slots, 2), np.float32)

    def start(self, slot: int, sigma: float) -> None:
        """A new episode on ``slot``: noise from the stationary law N(0, sigma^2)."""
        if self.correlation.any():  # independent noise never reads it (and keeps its random stream)
            self.noise[slot] = sigma * self._rng.standard_normal(2)

    def step(self, slots: list[int], sigma: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance the noise of ``slots``; returns (noise [len, 2], its fresh part [len, 2])."""
        innovation = (self.innovation_scale * sigma
                      * self._rng.standard_normal((len(slots), 2))).astype(np.float32)
        noise = self.correlation * self.noise[slots] + innovation
        self.noise[slots] = noise
        return noise, innovation

    def log_prob_sigmas(self, sigma: float) -> tuple[float, float]:
        """Standard deviation of each action (acc, sa) given the car's previous noise."""
        return float(sigma * self.innovation_scale[0]), float(sigma * self.innovation_scale[1])


# -- returns and losses (small pure functions, tested against hand-computed numbers) -------------


def n_step_returns(rewards: torch.Tensor, bootstrap: torch.Tensor | float, gamma: float) -> torch.Tensor:
    """R_t = r_t + gamma r_{t+1} + ... + gamma^(T-t) V(s_T) for t in [0, T) (paper, eq. A_t).

    ``rewards`` [T]; ``bootstrap`` V(s_T), 0 when the episode terminated.
    """
    returns = [0.0] * rewards.shape[0]
    running = float(bootstrap)
    for t, reward in zip(range(rewards.shape[0] - 1, -1, -1), reversed(rewards.tolist())):
        running = reward + gamma * running
        returns[t] = running
    return torch.tensor(returns, dtype=rewards.dtype)


def gae_advantages(rewards: torch.Tensor, values: torch.Tensor, bootstrap: float, gamma: float,
                   lam: float) -> torch.Tensor:
    """A_t = sum_k (gamma lam)^k delta_{t+k}, delta_t = r_t + gamma v(s_{t+1}) - v(s_t), over the
    segment, v(s_T) = ``bootstrap`` (0 when the episode terminated). lam = 1 gives R_t - v(s_t)
    (``n_step_returns``); lam = 0 the one-step TD error. ``values`` [T] are constants here."""
    values = values.detach()
    next_values = torch.cat([values[1:], values.new_tensor([float(bootstrap)])])
    deltas = (rewards + gamma * next_values - values).tolist()
    advantages = [0.0] * len(deltas)
    running = 0.0
    for t in range(len(deltas) - 1, -1, -1):
        running = deltas[t] + gamma * lam * running
        advantages[t] = running
    return torch.tensor(advantages, dtype=rewards.dtype)


def gaussian_log_prob(action: torch.Tensor, mu: torch.Tensor, sigma: float) -> torch.Tensor:
    """log N(action | mu, sigma); its gradient in mu is (action - mu) / sigma^2 (paper, eq. 4)."""
    return -((action - mu) ** 2) / (2.0 * sigma * sigma) - math.log(sigma) - LOG_SQRT_2PI


@dataclass
class StreamLoss:
    policy: torch.Tensor
    value: torch.Tensor
    advantages: torch.Tensor


def stream_loss(mu: torch.Tensor, values: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor,
                bootstrap: float, gamma: float, sigma: float, gae_lambda: float = 1.0) -> StreamLoss:
    """Policy and value loss of one stream over one segment (sums over its steps).

    Minimising ``policy`` follows eq. (1) with A_t = R_t - v(s_t): the advantage is a constant
    weight, so the gradient is -A_t (a_t - mu_t) / sigma^2 * grad mu_t. With ``gae_lambda`` < 1
    the policy's A_t is ``gae_advantages``; the value loss always regresses v(s_t) on R_t.
    """
    returns = n_step_returns(rewards, bootstrap, gamma)
    errors = returns - values
    advantages = (errors.detach() if gae_lambda == 1.0
                  else gae_advantages(rewards, values, bootstrap, gamma, gae_lambda))
    policy = -(advantages * gaussian_log_prob(actions, mu, sigma)).sum()
    value = 0.5 * (errors ** 2).sum()
    return StreamLoss(policy, value, advantages)


# -- one agent's episode ------------------------------------------------------------------------


@dataclass
class EpisodeLearner:
    """An agent during one episode: local weights, the current segment and the gradient sum.

    The segment keeps each observation as first-layer patches and, from acting, that layer's
    output for both heads, so the local update replays only the rest of the network
    (``algo.stacked``). Acting and updating use the same weights: they change only at updates.
    """

    params: dict[str, torch.Tensor]  # this agent's local weights: views into ActorCore.stacked
    base_version: int
    config: DA3CConfig
    patches: torch.Tensor  # [update_interval + 1, 441, 256] float: segment observations
    pre1: torch.Tensor  # [update_interval + 1, 441, 2 * C1] float: first layer's output, both heads
    scalars: np.ndarray  # [update_interval + 1, 3] float32: speed, target speed [m/s], standing time [s]
    actions: np.ndarray  # [update_interval, 2] float32, normalised units, unclipped samples
    rewards: np.ndarray  # [update_interval, 2] float32: R_acc, R_sa
    length: int = 0  # steps stored in the current segment
    grad_sum: dict[str, torch.Tensor] = field(default_factory=dict)
    losses: np.ndarray = field(default_factory=lambda: np.zeros(4))  # policy acc, policy sa, value acc, value sa
    updates: int = 0
    _first_layer: tuple[torch.Tensor, torch.Tensor] | None = None  # from params; reset when they change

    def observe(self, views: np.ndarray, scalars: np.ndarray) -> None:
        """The observation the next action is taken from (uint8 views [16, 84, 84], scalars [3])."""
        patches(torch.from_numpy(views), out=self.patches[self.length])
        self.scalars[self.length] = scalars

    def first_layer(self, index: int) -> None:
        """Run both heads' first layer on observation ``index`` with the local weights."""
        if self._first_layer is None:
            self._first_layer = first_layer_matrix(self.params)
        conv1(self.patches[index], *self._first_layer, out=self.pre1[index])

    def reset_weights(self, params: dict[str, torch.Tensor]) -> None:
        self.params = params
        self._first_layer = None

    def record(self, action: np.ndarray, reward_acc: float, reward_sa: float) -> None:
        self.actions[self.length] = action
        self.rewards[self.length] = (reward_acc, reward_sa)
        self.length += 1

    def update(self, sigma: float | tuple[float, float], terminal: bool) -> None:
        """Local D-A3C step over the stored segment; the next observation is at index ``length``.

        ``sigma``: the sampling standard deviation, one for both heads or (acc, sa).

        Same gradient as autograd through ``Policy`` on the whole segment (tests check it), but
        the first layer's forward pass comes from acting; only the bootstrap observation needs it.
        """
        n = self.length
        if n == 0:
            return
        cfg = self.config
        with torch.no_grad():
            self.first_layer(n)  # V(s_n) bootstraps with the weights the segment was driven with
        leaves = {name: p.detach().requires_grad_(True) for name, p in self.params.items()
                  if ".conv1." not in name}
        pre1 = self.pre1[: n + 1].detach().requires_grad_(True)
        mu, values = after_conv1(pre1.unsqueeze(0), torch.from_numpy(self.scalars[: n + 1]).unsqueeze(0),
                                 {name: leaf.unsqueeze(0) for name, leaf in leaves.items()})
        mu, values = mu[0], values[0]  # [n + 1, 2]: acc, sa
        boot = (0.0, 0.0) if terminal else values[n].tolist()
        actions = torch.from_numpy(self.actions[:n])
        rewards = torch.from_numpy(self.rewards[:n])
        sigmas = (sigma, sigma) if isinstance(sigma, (int, float)) else sigma
        acc, sa = (stream_loss(mu[:n, h], values[:n, h], actions[:, h], rewards[:, h], boot[h], cfg.gamma,
                               sigmas[h], cfg.gae_lambda)
                   for h in range(2))
        loss = acc.policy + sa.policy + cfg.value_coef * (acc.value + sa.value)
        if cfg.acceleration_cost > 0.0:
            loss = loss + cfg.acceleration_cost * mu[:n, 0].square().sum()
        loss.backward()
        grads = {name: leaf.grad for name, leaf in leaves.items()}
        grads.update(conv1_gradients(self.patches[:n], pre1.grad[:n], self.params["acc.conv1.weight"].shape))
        names = list(grads)
        grad_list = [grads[name] for name in names]
        with torch.no_grad():
            # clip to max_grad_norm, as torch.nn.utils.clip_grad_norm_ (one fused call per step)
            total = float(torch.linalg.vector_norm(torch.stack(torch._foreach_norm(grad_list))))
            scale = cfg.max_grad_norm / (total + 1e-6)
            if scale < 1.0:
                torch._foreach_mul_(grad_list, scale)
            torch._foreach_add_([self.grad_sum[name] for name in names], grad_list)
            torch._foreach_add_([self.params[name] for name in names], grad_list, alpha=-cfg.local_learning_rate)
        self._first_layer = None
        self.losses += [float(acc.policy.detach()), float(sa.policy.detach()),
                        float(acc.value.detach()), float(sa.value.detach())]
        self.updates += 1
        # the last observation opens the next segment
        self.patches[0].copy_(self.patches[n])
        self.scalars[0] = self.scalars[n]
        self.length = 0


@dataclass
class FinishedEpisode:
    """What an actor sends for one episode: the gradient sum and the episode's statistics."""

    base_version: int
    gradients: dict[str, np.ndarray]
    agent_steps: int
    summary: object  # simcore.simulator.EpisodeSummary
    mean_losses: np.ndarray  # policy acc, policy sa, value acc, value sa per update


def _runs(slots: list[int]) -> list[tuple[int, int]]:
    """Sorted slot numbers grouped into runs of neighbours, as [first, last) pairs."""
    runs: list[tuple[int, int]] = []
    for slot in slots:
        if runs and runs[-1][1] == slot:
            runs[-1] = (runs[-1][0], slot + 1)
        else:
            runs.append((slot, slot + 1))
    return runs


class ActorCore:
    """One simulator, every car a learner with its own local weights (transport-free)."""

    def __init__(self, sim: Simulator, policy_config: PolicyConfig = PolicyConfig(),
                 config: DA3CConfig = DA3CConfig(), seed: int | None = None):
        self.sim = sim
        self.config = config
        self.policy_config = policy_config
        self.global_policy = Policy(policy_config)
        self.version = -1  # no weights yet
        self.sigma = 0.65
        self._rng = np.random.default_rng(seed)
        # every slot's local weights in one tensor per parameter, [slots, ...]: neighbouring
        # agents act in one batched call over stacked parameters instead of one call each
        self.stacked = {name: p.detach().unsqueeze(0).repeat(sim.num_slots, *([1] * p.dim())).contiguous()
                        for name, p in self.global_policy.named_parameters()}
        self._learners: list[EpisodeLearner | None] = [None] * sim.num_slots
        self._spare: list[EpisodeLearner] = []
        self._result: StepResult | None = None
        self.agent_steps = 0
        self.noise = ExplorationNoise(sim.num_slots, config.noise_correlation, self._rng)

    # weights ------------------------------------------------------------------------------------

    def set_weights(self, version: int, sigma: float, tensors: dict[str, np.ndarray]) -> None:
        """New global weights: episodes that start from now on copy them."""
        with torch.no_grad():
            for name, p in self.global_policy.named_parameters():
                p.copy_(torch.from_numpy(tensors[name]))
        self.version = version
        self.sigma = sigma

    def _new_learner(self, slot: int) -> EpisodeLearner:
        """An agent starting its episode on ``slot`` with a local copy of the global weights."""
        params = {name: self.stacked[name][slot] for name in self.stacked}
        with torch.no_grad():
            for name, p in self.global_policy.named_parameters():
                params[name].copy_(p)
        if self._spare:
            learner = self._spare.pop()
            learner.reset_weights(params)
        else:
            n = self.config.update_interval
            conv1_channels = self.policy_config.conv1_channels
            learner = EpisodeLearner(
                params=params, base_version=self.version, config=self.config,
                patches=torch.zeros(n + 1, GRID * GRID, PATCH_FEATURES),
                pre1=torch.zeros(n + 1, GRID * GRID, len(HEADS) * conv1_channels),
                scalars=np.zeros((n + 1, SCALARS), np.float32),
                actions=np.zeros((n, 2), np.float32), rewards=np.zeros((n, 2), np.float32),
            )
        learner.base_version = self.version
        learner.length = 0
        learner.updates = 0
        learner.losses[:] = 0.0
        learner.grad_sum = {name: torch.zeros_like(p) for name, p in params.items()}
        return learner

    # stepping -----------------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        if self.version < 0:
            raise RuntimeError("ActorCore needs weights (set_weights) before it can act")
        self._learners = [None] * self.sim.num_slots
        self._result = self.sim.reset(seed=seed)
        self._admit(self._result)

    def _admit(self, result: StepResult) -> None:
        for slot in np.flatnonzero(result.started).tolist():
            learner = self._new_learner(slot)
            learner.observe(result.views[slot], result.scalars[slot])
            self._learners[slot] = learner
            self.noise.start(slot, self.sigma)

    def means(self, active: list[int]) -> np.ndarray:
        """Gaussian means [slots, 2] of the cars on ``active`` slots, each from its own weights.

        The first layer runs per car and its output stays in the car's segment for the update;
        the rest of the network runs once per run of neighbouring busy slots, over slices of the
        stacked weights (views, no copy).
        """
        means = np.zeros((self.sim.num_slots, 2), np.float32)
        with torch.no_grad():
            for slot in active:
                self._learners[slot].first_layer(self._learners[slot].length)
            for first, last in _runs(active):
                learners = [self._learners[slot] for slot in range(first, last)]
                params = {name: weights[first:last] for name, weights in self.stacked.items()}
                scalars = torch.from_numpy(np.stack([l.scalars[l.length] for l in learners]))[:, None]
                pre1 = torch.stack([l.pre1[l.length] for l in learners])[:, None]
                mu, _ = after_conv1(pre1, scalars, params)
                means[first:last] = mu[:, 0].numpy()
        return means

    def act(self) -> tuple[np.ndarray, np.ndarray]:
        """Sample actions for every car on the road.

        Returns (what the policy gradient sees: mu plus this step's fresh noise, in normalised
        units; simulator actions: mu plus all the noise, clipped and scaled). Without noise
        correlation both are the same sample.
        """
        centred = np.zeros((self.sim.num_slots, 2), np.float32)
        samples = np.zeros((self.sim.num_slots, 2), np.float32)
        active = [slot for slot, learner in enumerate(self._learners) if learner is not None]
        if active:
            means = self.means(active)[active]
            noise, innovation = self.noise.step(active, self.sigma)
            samples[active] = means + noise
            centred[active] = means + innovation
        return centred, np.clip(samples, -1.0, 1.0) * ACTION_SCALE

    def step(self) -> list[FinishedEpisode]:
        """One simulator step for every agent, local updates where due; returns ended episodes."""
        samples, env_actions = self.act()
        update_sigmas = self.noise.log_prob_sigmas(self.sigma)
        result = self.sim.step(env_actions)
        finished: list[FinishedEpisode] = []
        summaries = {e.slot: e for e in result.episodes}
        for slot in np.flatnonzero(result.acted).tolist():
            learner = self._learners[slot]
            learner.record(samples[slot], result.reward_acc[slot], result.reward_sa[slot])
            self.agent_steps += 1
            ended = bool(result.terminated[slot] or result.truncated[slot])
            learner.observe(result.views[slot], result.scalars[slot])
            if ended or learner.length >= self.config.update_interval:
                learner.update(update_sigmas, terminal=bool(result.terminated[slot]))
            if ended:
                finished.append(self._finish(slot, learner, summaries[slot]))
        self._admit(result)
        self._result = result
        return finished

    def _finish(self, slot: int, learner: EpisodeLearner, summary) -> FinishedEpisode:
        self._learners[slot] = None
        gradients = {name: g.numpy().copy() for name, g in learner.grad_sum.items()}
        self._spare.append(learner)
        return FinishedEpisode(learner.base_version, gradients, summary.steps, summary,
                               learner.losses / max(learner.updates, 1))
