"""Learning from a privileged teacher: a replay buffer of demonstrations and the imitation loss.

Not in the paper, which learns from rewards alone. A scripted driver that reads the simulator's
right of way (``simcore.controller.ScriptedDriver``) labels the states the learners see with the
actions it would take; the network learns to map its semantic views to those actions (the
"learning by cheating" scheme of Chen et al. 2019: a privileged agent teaches a sensorimotor
one), and its value heads learn the discounted returns of the episodes driven. Data are
collected DAgger-style (Ross et al. 2011): the states come from episodes driven by the teacher
or by the student itself, the labels always from the teacher. The result is a starting point
for D-A3C (``crossway train --init-from``), which then learns from rewards as in the paper.

The buffer stores each observed frame once: a car's four-frame history overlaps its previous
step's by three frames, so a sample keeps only its newest frame [4 channels, 84, 84] and finds
the three before it among the samples of the same episode, which are stored contiguously
(an episode enters the buffer whole, when it ends). 28 KB per sample instead of 113 KB.

Sampling is uniform by default. With a priority exponent alpha > 0 it is prioritized by the
student's error (Schaul et al. 2016's proportional prioritized replay, applied to imitation
as hard-example mining): sample i is drawn with probability proportional to
(|mu_acc,i - a_acc,i| + PRIORITY_FLOOR)^alpha, the error measured when the student drove past
it and again each time it is trained on. No importance weights undo the bias: the point is to
fit the rare decisions (a hard brake, a late go) the uniform mean lets the network blur.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from algo.policy import Policy, preprocess
from simcore.simulator import SCALARS

CHANNELS = 4  # navigable space, path, obstacles, traffic sign (simcore.views)
HISTORY = 4  # frames per channel in an observation, oldest first
FRAME_SHAPE = (CHANNELS, 84, 84)
# added to every acceleration error before it becomes a priority [normalised units; 0.05 = 0.15 m/s^2]:
# a sample the student already fits keeps a chance to be drawn again and show it has drifted
PRIORITY_FLOOR = 0.05


def newest_frames(views: np.ndarray) -> np.ndarray:
    """The newest frame of each channel, [N, 4, 84, 84], from observations [N, 16, 84, 84] (c*4 + k)."""
    return views[:, HISTORY - 1::HISTORY]


def discounted_returns(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """R_t = r_t + gamma R_{t+1} with R after the last step 0, per column of ``rewards`` [T, K]."""
    returns = np.zeros_like(rewards, dtype=np.float64)
    running = np.zeros(rewards.shape[1:], dtype=np.float64)
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + gamma * running
        returns[t] = running
    return returns.astype(np.float32)


@dataclass
class Episode:
    """One car's episode as collected: a frame, scalars and a teacher label per step."""

    frames: list[np.ndarray]  # each [4, 84, 84] uint8
    scalars: list[np.ndarray]  # each [3] float32: speed, target speed [m/s], standing time [s]
    targets: list[np.ndarray]  # each [2] float32: the teacher's action in normalised units [-1, 1]
    rewards: list[tuple[float, float]]  # (r_acc, r_sa) per step
    # per step, |student's acceleration mean - teacher's label| (normalised units) when measured; empty: not
    errors: list[float] = field(default_factory=list)
    # per step, whether the teacher's label is its braking for a car in its way (ScriptedDriver.blocker_bound);
    # empty: not recorded (all False)
    blocker: list[bool] = field(default_factory=list)
    # per step, whether the teacher's label is its going after standing out its patience although a car
    # with priority is near (ScriptedDriver.patience_released); empty: not recorded (all False)
    released: list[bool] = field(default_factory=list)

    @classmethod
    def empty(cls) -> "Episode":
        return cls([], [], [], [], [], [], [])

    def __len__(self) -> int:
        return len(self.frames)


class DemonstrationBuffer:
    """A first-in first-out store of whole episodes, sampled by step: uniformly, or by the
    student's error when ``priority_exponent`` > 0 (module docstring).

    ``add`` takes a finished episode; ``terminal`` says whether it ended by itself (goal, crash,
    off path, time over), so that its discounted returns are exact value targets. An episode cut
    short (a sign change, or collection stopping) keeps its action labels but trains no value.
    """

    def __init__(self, capacity: int, gamma: float, priority_exponent: float = 0.0):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 sample, got {capacity}")
        if not 0.0 < gamma <= 1.0:
            raise ValueError(f"gamma must be in (0, 1], got {gamma}")
        if not 0.0 <= priority_exponent < float("inf"):
            raise ValueError(f"priority_exponent must be >= 0 (0: uniform sampling), got {priority_exponent}")
        self.capacity = capacity
        self.gamma = gamma
        self.priority_exponent = priority_exponent
        # (error + PRIORITY_FLOOR) ** priority_exponent per row; used only when priority_exponent > 0
        self.priorities = np.ones(capacity, dtype=np.float64)
        self.frames = np.zeros((capacity, *FRAME_SHAPE), dtype=np.uint8)
        self.scalars = np.zeros((capacity, SCALARS), dtype=np.float32)
        self.targets = np.zeros((capacity, 2), dtype=np.float32)
        self.blocker = np.zeros(capacity, dtype=bool)  # the label is the teacher's braking for a blocker
        self.released = np.zeros(capacity, dtype=bool)  # ... its going once its patience ran out
        self.returns = np.zeros((capacity, 2), dtype=np.float32)
        self.value_known = np.zeros(capacity, dtype=bool)
        self.episode_start = np.zeros(capacity, dtype=np.int64)  # absolute index of the episode's first step
        self.added = 0  # samples ever added; sample i lives at row i % capacity while i >= added - capacity

    def __len__(self) -> int:
        return min(self.added, self.capacity)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.frames, self.scalars, self.targets, self.blocker, self.released,
                                      self.returns, self.value_known, self.episode_start, self.priorities))

    def add(self, episode: Episode, terminal: bool) -> None:
        n = len(episode)
        if n == 0:
            return
        if n > self.capacity:  # keep the newest steps; their history reaches back at most 3 of them
            episode = Episode(episode.frames[-self.capacity:], episode.scalars[-self.capacity:],
                              episode.targets[-self.capacity:], episode.rewards[-self.capacity:],
                              episode.errors[-self.capacity:], episode.blocker[-self.capacity:],
                              episode.released[-self.capacity:])
            n = self.capacity
        if episode.errors and len(episode.errors) != n:
            raise ValueError(f"an episode of {n} steps with {len(episode.errors)} errors: one per step, or none")
        for name in ("blocker", "released"):
            flags = getattr(episode, name)
            if flags and len(flags) != n:
                raise ValueError(f"an episode of {n} steps with {len(flags)} {name} flags: one per step, or none")
        rows = np.arange(self.added, self.added + n) % self.capacity
        if self.priority_exponent > 0:
            if episode.errors:
                self.priorities[rows] = self._priority(np.asarray(episode.errors, dtype=np.float64))
            else:  # not measured: as likely as the likeliest stored sample, so that it is measured soon
                self.priorities[rows] = self.priorities[self._stored_rows()].max() if len(self) else 1.0
        self.frames[rows] = np.stack(episode.frames)
        self.scalars[rows] = np.stack(episode.scalars)
        self.targets[rows] = np.stack(episode.targets)
        self.blocker[rows] = np.asarray(episode.blocker, dtype=bool) if episode.blocker else False
        self.released[rows] = np.asarray(episode.released, dtype=bool) if episode.released else False
        if terminal:
            self.returns[rows] = discounted_returns(np.asarray(episode.rewards, dtype=np.float64), self.gamma)
        self.value_known[rows] = terminal
        self.episode_start[rows] = self.added
        self.added += n

    def sample_indices(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        """Absolute indices of ``batch`` samples whose whole history is still stored."""
        oldest = max(0, self.added - self.capacity)
        # a sample's history reaches at most 3 steps back: once the oldest samples have been
        # overwritten, the first three still stored may miss part of theirs
        low = oldest + (HISTORY - 1 if self.added > self.capacity else 0)
        if self.added - low <= 0:
            raise ValueError("the buffer holds no sample with its whole history yet")
        if self.priority_exponent == 0:
            return rng.integers(low, self.added, size=batch)
        cumulative = np.cumsum(self.priorities[np.arange(low, self.added) % self.capacity])
        picks = np.searchsorted(cumulative, rng.random(batch) * cumulative[-1], side="right")
        return low + np.minimum(picks, len(cumulative) - 1)

    def update_priorities(self, indices: np.ndarray, errors: np.ndarray) -> None:
        """Set the priorities of the samples at absolute ``indices`` from the student's acceleration
        errors [normalised units] just measured on them (no effect under uniform sampling)."""
        if self.priority_exponent > 0:
            self.priorities[np.asarray(indices) % self.capacity] = self._priority(np.asarray(errors, np.float64))

    def _priority(self, errors: np.ndarray) -> np.ndarray:
        return (np.abs(errors) + PRIORITY_FLOOR) ** self.priority_exponent

    def _stored_rows(self) -> np.ndarray:
        return np.arange(max(0, self.added - self.capacity), self.added) % self.capacity

    def observations(self, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Views [B, 16, 84, 84] uint8 (c*4 + k, k = 3 newest) and scalars [B, 3] of the samples."""
        start = self.episode_start[indices % self.capacity]
        history = np.maximum(indices[:, None] - np.arange(HISTORY - 1, -1, -1)[None, :], start[:, None])  # [B, k]
        frames = self.frames[history % self.capacity]  # [B, k, c, 84, 84]
        views = frames.transpose(0, 2, 1, 3, 4).reshape(len(indices), CHANNELS * HISTORY, 84, 84)
        return views, self.scalars[indices % self.capacity]

    def batch(self, indices: np.ndarray) -> dict[str, np.ndarray]:
        views, scalars = self.observations(indices)
        rows = indices % self.capacity
        return {"views": views, "scalars": scalars, "targets": self.targets[rows], "blocker": self.blocker[rows],
                "released": self.released[rows], "returns": self.returns[rows], "value_known": self.value_known[rows]}


# a teacher label at or below this (normalised units: -1.5 m/s^2) is a hard braking decision
BRAKE_LABEL = -0.5
ACCELERATION_LOSSES = ("squared", "absolute")  # imitation_loss: the mean or the median of the labels


def imitation_loss(policy: Policy, batch: dict[str, np.ndarray], value_coef: float,
                   brake_weight: float = 1.0, return_errors: bool = False, blocker_weight: float = 1.0,
                   patience_weight: float = 1.0, acceleration_loss: str = "squared"):
    """Mean squared error of both means against the teacher's actions (normalised units), plus
    ``value_coef`` times that of both values against the discounted returns where they are known.

    ``acceleration_loss`` "absolute" takes the acceleration mean's absolute error instead of its
    square: the minimiser is then the labels' (weighted) median, not their mean. Where the views
    cannot tell apart states in which the teacher goes and states in which it brakes, the squared
    error's answer is a compromise between the two (a car that neither goes nor stops), the absolute
    error's is the more common of them.

    ``brake_weight`` > 1 counts each sample whose acceleration label is a hard braking decision
    (``BRAKE_LABEL``) that many times in the acceleration error's weighted mean: those samples are
    few (7% of car-steps on hard) and decide the crashes. ``blocker_weight`` multiplies the weight
    of each sample whose label is the teacher's braking for a car standing in its way
    (``batch["blocker"]``; a batch without that key has none): in the hard student's crossing
    crashes the car with priority did not brake for the car already in their zone (docs/imitation.md,
    session 21). ``patience_weight`` does the same for each sample whose label is the teacher going
    once it has stood out its patience although a car with priority is near (``batch["released"]``):
    0.2% of the hard teacher's car-steps, the "wait, then go" the students have not learnt (session 29).

    Returns the loss and its parts as floats; with ``return_errors`` also each sample's
    |mu_acc - label| [B] (normalised units), the priorities of prioritized sampling."""
    if acceleration_loss not in ACCELERATION_LOSSES:
        raise ValueError(f"acceleration_loss must be one of {ACCELERATION_LOSSES}, got {acceleration_loss!r}")
    views, scalars = preprocess(batch["views"], batch["scalars"])
    mu_acc, v_acc, mu_sa, v_sa = policy(views, scalars)
    targets = torch.from_numpy(batch["targets"])
    returns = torch.from_numpy(batch["returns"])
    known = torch.from_numpy(batch["value_known"]).float()
    weights = torch.where(targets[:, 0] <= BRAKE_LABEL, brake_weight, 1.0)
    if blocker_weight != 1.0 and "blocker" in batch:
        weights = weights * torch.where(torch.from_numpy(batch["blocker"]), blocker_weight, 1.0)
    if patience_weight != 1.0 and "released" in batch:
        weights = weights * torch.where(torch.from_numpy(batch["released"]), patience_weight, 1.0)
    error_acc = mu_acc - targets[:, 0]
    per_sample = error_acc.abs() if acceleration_loss == "absolute" else error_acc ** 2
    action_loss_acc = (weights * per_sample).sum() / weights.sum()
    action_loss_sa = ((mu_sa - targets[:, 1]) ** 2).mean()
    count = known.sum().clamp(min=1.0)
    value_loss_acc = (known * (v_acc - returns[:, 0]) ** 2).sum() / count
    value_loss_sa = (known * (v_sa - returns[:, 1]) ** 2).sum() / count
    loss = action_loss_acc + action_loss_sa + value_coef * (value_loss_acc + value_loss_sa)
    metrics = {name: float(value.detach()) for name, value in (
        ("action_loss_acc", action_loss_acc), ("action_loss_sa", action_loss_sa),
        ("value_loss_acc", value_loss_acc), ("value_loss_sa", value_loss_sa))}
    if return_errors:
        return loss, metrics, error_acc.detach().abs().numpy()
    return loss, metrics
