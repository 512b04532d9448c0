"""Drive a simulator's learner slots with a trained policy (no learning): for evaluation.

Every car uses the same (global) weights, so all cars on the road act in one batched forward
pass. By default the cars take the Gaussian mean; ``sigma`` > 0 samples as in training.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from algo.braking import EmergencyBraking
from algo.policy import (ACTION_SCALE, Policy, PolicyConfig, ensemble_members, load_policy, member_weights,
                         require_views, save_atomically)
from algo.stacked import conv2_matrices, first_layer_matrix, forward_distinct, forward_full


def check_checkpoint(checkpoint: str | Path, spec) -> None:
    """Refuse, before any worker starts, a checkpoint that does not load or whose weights learnt
    from another view square than the one the agents of scenario ``spec`` see: the same pixels
    would then show the junction at another scale or place, and its numbers would mean nothing."""
    load_policy(checkpoint)
    require_views(checkpoint, (spec.views.extent_m, spec.views.shift_m), spec.name,
                  "evaluate it on a scenario file whose [views] table matches (docs/simulator.md)")


def export_policy(checkpoint: str | Path, out: str | Path, note: str = "",
                  emergency_braking: EmergencyBraking | None | bool = True) -> Path:
    """Write only what evaluation needs (network sizes, weights, provenance): a small file for models/.

    ``emergency_braking``: True keeps the checkpoint's own rule (``algo.braking``), a rule replaces
    it, None or False leaves it out."""
    policy = load_policy(checkpoint)
    state = torch.load(Path(checkpoint), weights_only=False, map_location="cpu")
    out = Path(out)
    # an ensemble keeps its members (algo.policy.load_policy joins them), not the joined zero blocks
    weights = ({"members": state["members"], "caution": state.get("caution")} if "members" in state
               else {"policy": policy.state_dict(), "policy_config": state["policy_config"]})
    exported = {**weights, "version": state.get("version"), "agent_steps": state.get("agent_steps"),
                "run_id": state.get("run_id"), "note": note}
    rule = policy.emergency_braking if emergency_braking is True else (emergency_braking or None)
    if rule is not None:
        exported["emergency_braking"] = rule.record()
    if "views" in state:  # a file without the record reads as the paper's views (algo.policy.policy_views)
        exported["views"] = state["views"]
    return save_atomically(exported, out)


class PolicyDriver:
    """Acts for every learner slot of a ``Simulator`` from the newest ``StepResult``.

    The network runs in the matrix form of ``algo.stacked`` (the same function as ``Policy``,
    about twice as fast on a CPU as its convolution modules for these layer shapes). A network
    that splits into K equal blocks (an output ensemble, ``algo.policy.ensemble``) runs as K
    weight sets at once, whose outputs before the tanh add up: the same function without the
    dense layers' zero blocks. A network wider than one of the paper's sizes (an ensemble)
    multiplies only the distinct patches and windows of the views (``algo.stacked.forward_distinct``).
    An ensemble with a ``caution`` (``algo.policy.Caution``) takes its acceleration as the members'
    mean minus that many standard deviations of their votes. A network with an
    ``emergency_braking`` rule (``algo.braking``) brakes for a car in a car's path ahead as its views
    show it, whatever the network says; ``braked_car_steps`` counts where it did.
    """

    def __init__(self, sim, policy: Policy, sigma: float = 0.0, seed: int | None = None,
                 members: int | None = None):
        self.sim = sim
        self.policy = policy
        self.sigma = sigma
        self._rng = np.random.default_rng(seed)
        # weight sets to run side by side: the split ensemble_members finds, unless given (1: the joined network)
        self.members = ensemble_members(policy) if members is None else members
        if self.members > 1 and ensemble_members(policy) % self.members:
            raise ValueError(f"the network does not split into {self.members} equal members")
        self.caution = policy.caution  # how the members' acceleration votes combine (None: their mean)
        if self.caution is not None and self.members < 2:
            raise ValueError("the network's caution (algo.policy.Caution) needs its members side by side; "
                             "it does not apply to the joined network (members=1)")
        self._params = member_weights(policy, self.members)  # K weight sets (K = 1: the network itself)
        # one first-layer matrix for every member and head, columns ordered member by member
        # (acc channels, then sa channels, as after_conv1 takes each member's)
        matrix, bias = first_layer_matrix({name: w.reshape(-1, *w.shape[2:]) for name, w in self._params.items()
                                           if "conv1" in name})
        channels = self._params["acc.conv1.weight"].shape[1]
        order = torch.arange(2 * self.members * channels).reshape(2, self.members, channels).transpose(0, 1).flatten()
        self._first_layer = (matrix[:, order].contiguous(), bias[order].contiguous())
        self._second_layer = conv2_matrices(self._params)
        # grouping equal patches pays once the first layer is wider than one network of the paper's
        # sizes ('crossway bench policy': about 1.9x for nine members, level for one)
        self._distinct = matrix.shape[1] > 2 * PolicyConfig().conv1_channels
        self.emergency_braking = policy.emergency_braking
        self.braked_car_steps = 0  # car-steps where the emergency braking overrode the network

    def heads(self, views: np.ndarray, scalars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Means and values [B, 2] (acc, sa) for uint8 views [B, 16, 84, 84] and speeds [B, 2] m/s."""
        k = self.members
        with torch.no_grad():
            speeds = torch.from_numpy(np.ascontiguousarray(scalars, dtype=np.float32))
            views_t = torch.from_numpy(np.ascontiguousarray(views))
            if self._distinct:
                pre_mu, values = forward_distinct(views_t, speeds, self._params, self._first_layer, self._second_layer)
            else:
                pre_mu, values = forward_full(views_t, speeds, self._params, self._first_layer)  # [K, N, 2] each
            if self.caution is None:
                mu = torch.tanh(pre_mu.sum(0))
            else:  # the members' own pre-activations; acceleration: mean - c * std (algo.policy.Caution)
                z = pre_mu * k
                pre = z.mean(0)
                pre[:, 0] = pre[:, 0] - self.caution.factor(speeds, views) * z[:, :, 0].std(0)
                mu = torch.tanh(pre)
        return mu.numpy().astype(np.float64), values.sum(0).numpy().astype(np.float64)

    def act(self, result) -> np.ndarray:
        """Actions [slots, 2] (m/s^2, rad) for the cars on the road; zeros elsewhere."""
        return self.act_with_values(result)[0]

    def act_with_values(self, result) -> tuple[np.ndarray, np.ndarray]:
        """``act``'s actions and the value estimates [slots, 2] (v_acc, v_sa) they were taken with."""
        actions = np.zeros((self.sim.num_slots, 2))
        values = np.zeros((self.sim.num_slots, 2))
        active = np.flatnonzero(self.sim.learners_present)
        if len(active) == 0:
            return actions, values
        means, values[active] = self.heads(result.views[active], result.scalars[active])
        if self.sigma > 0:
            means = means + self.sigma * self._rng.standard_normal(means.shape)
        actions[active] = np.clip(means, -1.0, 1.0) * ACTION_SCALE
        if self.emergency_braking is not None:
            views = self.sim.spec.views
            actions[active, 0], braked = self.emergency_braking.apply(
                result.views[active], result.scalars[active, 0], actions[active, 0], views.extent_m, views.shift_m)
            self.braked_car_steps += int(braked.sum())
        return actions, values
