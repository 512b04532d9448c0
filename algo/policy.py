"""The policy network (paper, "Neural Network Architecture", Fig. 4).

Two sub-modules, one for acceleration (acc) and one for steering (sa). Each takes the 16x84x84
semantic views (4 channels x 4 frames) and the two scalars (speed, target speed) and outputs a
Gaussian mean and a state value: (mu_acc, v_acc) and (mu_sa, v_sa). Means live in normalised
action units [-1, 1] (tanh); the environment action is ``clip(mu + sigma * eps, -1, 1)`` times
3 m/s^2 or 0.2 rad. Sigma falls linearly from 0.65 to 0.05 over training (``sigma_at``).

Layer sizes (the paper gives none) are chosen for learning speed on a CPU: a 4x4 stride-4
convolution turns each 84x84 plane into 21x21 patches without overlap (a third of the cost of
the Atari 8x8 stride-4 layer), a 3x3 stride-2 convolution gives 10x10x16, and one hidden layer
of 128 units takes those features with the two scalars. Each sub-module has 212k parameters;
one forward and backward pass costs about 0.6-0.8 ms per sample on one core as torch modules
(``crossway bench actor`` measures it). Actors run the same function in the matrix form of
``algo.stacked``.
"""

from __future__ import annotations

import collections
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from algo.braking import EmergencyBraking, emergency_braking_from
from algo.entries import settings_from_entry
from simcore.dynamics import MAX_ACCELERATION, MAX_STEERING
from simcore.rightofway import SIGN_NAMES
from simcore.simulator import HISTORY
from simcore.views import CHANNELS, STOP_LINE, VIEW_EXTENT_M, YIELD_LINE

VIEW_SHAPE = (16, 84, 84)
CONV2_CELLS = 10 * 10  # the second convolution's output grid over 84 x 84 views
SPEED_SCALE = 10.0  # speeds are divided by this before entering the network [m/s]
# the standing-time input (not the paper's): clipped at STANDING_CLIP_S, then divided by STANDING_SCALE_S [s]
STANDING_SCALE_S = 10.0
STANDING_CLIP_S = 30.0
ACTION_SCALE = np.array([MAX_ACCELERATION, MAX_STEERING], dtype=np.float32)  # [m/s^2, rad]
# the view square (side, centre ahead of the car) [m] of a file that does not record one: every
# file written before checkpoints recorded it learnt from the paper's views
PAPER_VIEWS = (VIEW_EXTENT_M, 0.0)


@dataclass(frozen=True)
class PolicyConfig:
    """Sizes of one sub-module (acc and sa are identical)."""

    conv1_channels: int = 16  # 4x4 stride-4 convolution over the 16 input planes
    conv2_channels: int = 16  # 3x3 stride-2 convolution
    hidden: int = 128  # fully connected layer after the convolutions, scalars appended
    # a third scalar beside speed and target speed: how long the car has stood [s] (not in the paper;
    # a clock the four frames, 0.3 s, cannot show and the scripted teacher's patience reads)
    standing_input: bool = False

    @property
    def scalar_inputs(self) -> int:
        """Columns of ``simcore.simulator.StepResult.scalars`` the network reads (the first ones)."""
        return 3 if self.standing_input else 2


@dataclass(frozen=True)
class Caution:
    """How an output ensemble brakes where its members disagree (not in the paper; session 24).

    The acceleration's pre-activation becomes the members' mean minus ``std_factor`` times their
    sample standard deviation, mu_acc = tanh(mean_k z_k - c * std_k z_k), a lower confidence bound
    on the members' vote: a car slows where they disagree about the junction ahead and drives as
    their mean where they agree. ``fade_standing_s`` lets c fall linearly to 0 over that much
    standing time (the simulator's third scalar, under 0.5 m/s), so that a car waiting at its line
    goes on the mean once it has stood that long. ``full_from_speed_mps`` scales c by the car's
    speed, from 0 at standstill to all of it at that speed, so that a car moving off (from a stop
    line) is not held back and a car driving on is. ``signs`` limits it to the cars whose own sign
    is one of those, as their newest view shows it (``sign_in_view``: a stop line, a yield line, or
    none in sight). Steering and values keep the mean.

    A negative c is boldness (session 34): the members' mean plus |c| standard deviations, the
    eager side of their vote. ``full_below_speed_mps`` scales c the other way from
    ``full_from_speed_mps``: all of it at a standstill, falling linearly to 0 at that speed, so that
    only slow cars are touched (a car with priority dawdling at its line, docs/imitation.md, session 34).
    """

    std_factor: float  # c, in standard deviations of the members' acceleration pre-activations
    fade_standing_s: float | None = None  # [s]; None: c holds however long the car stands
    full_from_speed_mps: float | None = None  # [m/s]; None: c at every speed
    signs: tuple[str, ...] | None = None  # sign names ("none", "yield", "stop"); None: every car
    full_below_speed_mps: float | None = None  # [m/s]; None: c at every speed

    def __post_init__(self):
        if not (isinstance(self.std_factor, (int, float)) and math.isfinite(self.std_factor)):
            raise ValueError(f"caution: std_factor must be a finite number (negative: boldness), "
                             f"got {self.std_factor!r}")
        for name, unit in (("fade_standing_s", "s"), ("full_from_speed_mps", "m/s"), ("full_below_speed_mps", "m/s")):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and value > 0):
                raise ValueError(f"caution: {name} must be > 0 {unit} or None, got {value!r}")
        if self.signs is not None:
            if isinstance(self.signs, str) or not isinstance(self.signs, (tuple, list)):
                raise ValueError(f"caution: signs must be a list of sign names or None, got {self.signs!r}")
            unknown = sorted(set(self.signs) - set(SIGN_NAMES.values()))
            if unknown or not self.signs:
                raise ValueError(f"caution: signs must name some of {', '.join(SIGN_NAMES.values())}, "
                                 f"got {list(self.signs)!r}")
            object.__setattr__(self, "signs", tuple(self.signs))

    def factor(self, scalars: torch.Tensor, views: np.ndarray | None = None) -> torch.Tensor | float:
        """c for each car [B] from the simulator's scalars [B, 3] (speed [m/s], target speed [m/s],
        standing time [s]) and, when the rule reads signs, its uint8 views [B, 16, 84, 84]; only the
        columns the rule reads need be there."""
        factor = self.std_factor
        if self.signs is not None:
            if views is None:
                raise ValueError("caution by sign needs the views (the sign channel shows each car's sign)")
            shown = sign_in_view(views)
            factor = factor * torch.from_numpy(np.isin(shown, list(self.signs))).to(scalars.dtype)
        if self.fade_standing_s is not None:
            if scalars.shape[-1] < 3:
                raise ValueError(f"caution fading with standing time needs the standing-time scalar (3 columns: "
                                 f"speed, target speed, standing time), got {scalars.shape[-1]}")
            factor = factor * (1 - scalars[:, 2] / self.fade_standing_s).clamp(min=0.0)
        if self.full_from_speed_mps is not None:
            factor = factor * (scalars[:, 0] / self.full_from_speed_mps).clamp(0.0, 1.0)
        if self.full_below_speed_mps is not None:
            factor = factor * (1 - scalars[:, 0] / self.full_below_speed_mps).clamp(0.0, 1.0)
        return factor

    def record(self) -> dict:
        """The checkpoint's ``caution`` entry."""
        return asdict(self)

    def describe(self) -> str:
        """The rule in words, as notes and messages give it."""
        side = "minus" if self.std_factor >= 0 else "plus"
        return (f"acceleration {side} {abs(self.std_factor):g} standard deviations"
                + ("" if self.fade_standing_s is None else f" fading over {self.fade_standing_s:g} s standing")
                + ("" if self.full_from_speed_mps is None else f", all of it from {self.full_from_speed_mps:g} m/s")
                + ("" if self.full_below_speed_mps is None
                   else f", all of it at a standstill, none from {self.full_below_speed_mps:g} m/s")
                + ("" if self.signs is None else f", for cars at {' / '.join(self.signs)} signs only"))


def sign_in_view(views: np.ndarray) -> np.ndarray:
    """Each car's sign name [B] as its newest frame's sign channel shows it (``simcore.views``):
    "stop" where a stop line is in sight, "yield" where a yield line is, else "none" (no sign, or
    the car's line not, or no longer, in its 50 m square)."""
    plane = views[:, CHANNELS.index("sign") * HISTORY + HISTORY - 1].reshape(len(views), -1)
    stop, give_way = (plane == STOP_LINE).any(1), (plane == YIELD_LINE).any(1)
    return np.where(stop, "stop", np.where(give_way, "yield", "none"))


def caution_from(source: str, record) -> Caution:
    """The ``Caution`` of a checkpoint's ``caution`` entry; ValueError naming ``source`` when it is not one."""
    return settings_from_entry(source, "caution", Caution, record)


class SubModule(nn.Module):
    """One head of the paper's network: views and scalars to a Gaussian mean and a value."""

    def __init__(self, config: PolicyConfig):
        super().__init__()
        self.conv1 = nn.Conv2d(VIEW_SHAPE[0], config.conv1_channels, kernel_size=4, stride=4)
        self.conv2 = nn.Conv2d(config.conv1_channels, config.conv2_channels, kernel_size=3, stride=2)
        self.scalar_inputs = config.scalar_inputs
        self.hidden = nn.Linear(config.conv2_channels * CONV2_CELLS + config.scalar_inputs, config.hidden)
        self.mu = nn.Linear(config.hidden, 1)
        self.value = nn.Linear(config.hidden, 1)
        nn.init.uniform_(self.mu.weight, -3e-3, 3e-3)  # start near mu = 0: explore symmetrically
        nn.init.zeros_(self.mu.bias)

    def forward(self, views: torch.Tensor, scalars: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``scalars`` [B, >= scalar_inputs] as ``preprocess`` scales them; the first columns are read."""
        h = torch.relu(self.conv1(views))
        h = torch.relu(self.conv2(h))
        h = torch.relu(self.hidden(torch.cat([h.flatten(1), first_scalars(scalars, self.scalar_inputs)], dim=1)))
        return torch.tanh(self.mu(h)).squeeze(1), self.value(h).squeeze(1)


class Policy(nn.Module):
    """The two sub-modules; ``forward`` returns mu_acc, v_acc, mu_sa, v_sa, each [B]."""

    def __init__(self, config: PolicyConfig = PolicyConfig()):
        super().__init__()
        self.config = config
        # an output ensemble's rule for braking where its members disagree (``Caution``); applied
        # where the members run side by side (evaluation.policy.PolicyDriver), not by ``forward``
        self.caution: Caution | None = None
        # a rule braking for a car in the path ahead, read from the views (``algo.braking``); applied
        # by evaluation.policy.PolicyDriver, not by ``forward``
        self.emergency_braking: EmergencyBraking | None = None
        self.acc = SubModule(config)
        self.sa = SubModule(config)

    def forward(self, views: torch.Tensor, scalars: torch.Tensor):
        mu_acc, v_acc = self.acc(views, scalars)
        mu_sa, v_sa = self.sa(views, scalars)
        return mu_acc, v_acc, mu_sa, v_sa


def widen(policy: Policy, config: PolicyConfig, seed: int = 0) -> Policy:
    """A network of the (larger or equal) sizes ``config`` that computes exactly ``policy``'s function.

    Every old unit keeps its weights; every new unit gets the random weights a fresh network of
    those sizes would start with on its inputs and zero weights on its outputs, so it changes no
    output until training moves those (new units with zero fan-out; Chen et al. 2016, "Net2Net",
    reach the same end by copying units). The old units also get zero weights from the new units
    below them. Refuses a ``config`` smaller than the policy's in any layer.
    """
    old = policy.config
    sizes = ("conv1_channels", "conv2_channels", "hidden")
    if any(getattr(config, name) < getattr(old, name) for name in sizes) or config.scalar_inputs < old.scalar_inputs:
        raise ValueError(f"cannot widen the network {asdict(old)} to {asdict(config)}: a layer would shrink or an "
                         "input go (a network can only be widened)")
    with torch.random.fork_rng(devices=[]):  # the caller's random stream stays as it was
        torch.manual_seed(seed)
        wide = Policy(config)
    c1, c2, h = old.conv1_channels, old.conv2_channels, old.hidden
    features = CONV2_CELLS * c2  # the old hidden layer's inputs from the views; the scalars follow
    wide_features = CONV2_CELLS * config.conv2_channels
    with torch.no_grad():
        for head in ("acc", "sa"):
            new, was = getattr(wide, head), getattr(policy, head)
            new.conv1.weight[:c1] = was.conv1.weight
            new.conv1.bias[:c1] = was.conv1.bias
            new.conv2.weight[:c2] = 0.0  # old channels read nothing from new conv1 channels
            new.conv2.weight[:c2, :c1] = was.conv2.weight
            new.conv2.bias[:c2] = was.conv2.bias
            new.hidden.weight[:h] = 0.0  # old units read nothing from new conv2 channels
            new.hidden.weight[:h, :features] = was.hidden.weight[:, :features]  # channel-major, as flattened
            # speed, target speed (and standing time); a new standing-time input starts unread (zero weights)
            new.hidden.weight[:h, wide_features:wide_features + old.scalar_inputs] = was.hidden.weight[:, features:]
            new.hidden.bias[:h] = was.hidden.bias
            for out in ("mu", "value"):
                layer, old_layer = getattr(new, out), getattr(was, out)
                layer.weight.zero_()  # new hidden units' outputs start at zero
                layer.weight[:, :h] = old_layer.weight
                layer.bias.copy_(old_layer.bias)
    wide.train(policy.training)
    return wide


def ensemble(policies: list[Policy]) -> Policy:
    """One network of the paper's shape that computes the mean of ``policies``' outputs before the
    tanh: mu = tanh(mean_k z_k) where mu_k = tanh(z_k), and v = mean_k v_k.

    The members sit side by side in every layer (sizes summed) with zero weights between them, so a
    member's units read only its own units below: conv1 channels, conv2 channels and hidden units
    are each member's in turn, and the two output layers take each member's weights divided by the
    member count. A network with the standing-time input results when any member reads it; the
    members that do not read it get zero weights from it. Evaluation runs the members side by side
    (``ensemble_members``, ``member_weights``) instead of multiplying the zero blocks. An output
    ensemble, not a weight average (docs/scripts/weight_soup.py).
    """
    if not policies:
        raise ValueError("an ensemble needs at least one network")
    configs = [policy.config for policy in policies]
    config = PolicyConfig(conv1_channels=sum(c.conv1_channels for c in configs),
                          conv2_channels=sum(c.conv2_channels for c in configs),
                          hidden=sum(c.hidden for c in configs),
                          standing_input=any(c.standing_input for c in configs))
    joined = Policy(config)
    features = CONV2_CELLS * config.conv2_channels  # the hidden layer's inputs from the views; the scalars follow
    share = 1.0 / len(policies)
    with torch.no_grad():
        for parameter in joined.parameters():
            parameter.zero_()
        for head in ("acc", "sa"):
            new = getattr(joined, head)
            c1_at = c2_at = h_at = 0  # where the member's units start in each layer
            for policy in policies:
                was, sizes = getattr(policy, head), policy.config
                c1, c2, h = sizes.conv1_channels, sizes.conv2_channels, sizes.hidden
                new.conv1.weight[c1_at:c1_at + c1] = was.conv1.weight
                new.conv1.bias[c1_at:c1_at + c1] = was.conv1.bias
                new.conv2.weight[c2_at:c2_at + c2, c1_at:c1_at + c1] = was.conv2.weight
                new.conv2.bias[c2_at:c2_at + c2] = was.conv2.bias
                # the flattened conv2 output is channel-major: a member's channels are one block of it
                new.hidden.weight[h_at:h_at + h, CONV2_CELLS * c2_at:CONV2_CELLS * (c2_at + c2)] = \
                    was.hidden.weight[:, :CONV2_CELLS * c2]
                new.hidden.weight[h_at:h_at + h, features:features + sizes.scalar_inputs] = \
                    was.hidden.weight[:, CONV2_CELLS * c2:]
                new.hidden.bias[h_at:h_at + h] = was.hidden.bias
                for out in ("mu", "value"):
                    layer, old_layer = getattr(new, out), getattr(was, out)
                    layer.weight[:, h_at:h_at + h] = share * old_layer.weight
                    layer.bias.add_(share * old_layer.bias)
                c1_at, c2_at, h_at = c1_at + c1, c2_at + c2, h_at + h
    joined.eval()
    return joined


def ensemble_members(policy: Policy) -> int:
    """How many equal members ``policy`` splits into: the largest K such that, in both heads, its
    conv1 channels, conv2 channels and hidden units fall into K equal blocks in turn and no unit
    reads a unit of another block (the layout ``ensemble`` writes); 1 when no split exists.

    Any such network is the sum of its K blocks before the output tanh, so it can run as K weight
    sets at once (``member_weights``, ``evaluation.policy.PolicyDriver``) instead of multiplying
    the zero blocks of its dense layers.
    """
    config = policy.config
    sizes = (config.conv1_channels, config.conv2_channels, config.hidden)
    common = math.gcd(*sizes)
    for members in range(common, 1, -1):
        if common % members == 0 and _splits(policy, members):
            return members
    return 1


def _splits(policy: Policy, members: int) -> bool:
    config = policy.config
    c1, c2, h = (size // members for size in (config.conv1_channels, config.conv2_channels, config.hidden))
    features = CONV2_CELLS * config.conv2_channels
    for head in ("acc", "sa"):
        module = getattr(policy, head)
        conv2 = module.conv2.weight.detach().abs().sum(dim=(2, 3))  # [C2, C1]
        hidden = module.hidden.weight.detach()[:, :features].abs().reshape(config.hidden, config.conv2_channels,
                                                                            CONV2_CELLS).sum(2)  # [H, C2]
        inside_conv2 = torch.block_diag(*[torch.ones(c2, c1)] * members).bool()
        inside_hidden = torch.block_diag(*[torch.ones(h, c2)] * members).bool()
        if conv2[~inside_conv2].any() or hidden[~inside_hidden].any():
            return False
    return True


def member_weights(policy: Policy, members: int) -> dict[str, torch.Tensor]:
    """``policy``'s weights as ``members`` weight sets in ``Policy``'s names, each with a leading
    dimension ``members`` (as ``algo.stacked.after_conv1`` takes them): block k of every layer,
    with the output layers' biases shared out equally, so that the members' outputs before the
    tanh sum to the network's. ``members`` must be a split ``ensemble_members`` found."""
    config = policy.config
    c1, c2, h = (size // members for size in (config.conv1_channels, config.conv2_channels, config.hidden))
    features = CONV2_CELLS * config.conv2_channels
    sets: dict[str, list[torch.Tensor]] = collections.defaultdict(list)
    with torch.no_grad():
        for k in range(members):
            one1, one2, oneh = slice(k * c1, (k + 1) * c1), slice(k * c2, (k + 1) * c2), slice(k * h, (k + 1) * h)
            for head in ("acc", "sa"):
                module = getattr(policy, head)
                sets[f"{head}.conv1.weight"].append(module.conv1.weight[one1])
                sets[f"{head}.conv1.bias"].append(module.conv1.bias[one1])
                sets[f"{head}.conv2.weight"].append(module.conv2.weight[one2, one1])
                sets[f"{head}.conv2.bias"].append(module.conv2.bias[one2])
                hidden = module.hidden.weight[oneh]
                sets[f"{head}.hidden.weight"].append(torch.cat(
                    [hidden[:, CONV2_CELLS * k * c2:CONV2_CELLS * (k + 1) * c2], hidden[:, features:]], dim=1))
                sets[f"{head}.hidden.bias"].append(module.hidden.bias[oneh])
                for out in ("mu", "value"):
                    layer = getattr(module, out)
                    sets[f"{head}.{out}.weight"].append(layer.weight[:, oneh])
                    sets[f"{head}.{out}.bias"].append(layer.bias / members)
    return {name: torch.stack(weights).contiguous() for name, weights in sets.items()}


def preprocess(views: np.ndarray, scalars: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """uint8 views [B, 16, 84, 84] and scalars [B, 2 or 3] (speed, target speed [m/s], standing
    time [s]) to network inputs: views in [0, 1], scalars as ``scale_scalars``."""
    v = torch.from_numpy(np.ascontiguousarray(views)).float().div_(255.0)
    return v, scale_scalars(torch.from_numpy(np.ascontiguousarray(scalars, dtype=np.float32)))


def scale_scalars(scalars: torch.Tensor) -> torch.Tensor:
    """[..., 2 or 3] speed, target speed [m/s] (, standing time [s]) to the network's units:
    speeds / SPEED_SCALE, standing time clipped at STANDING_CLIP_S and / STANDING_SCALE_S."""
    scaled = scalars[..., :2] / SPEED_SCALE
    if scalars.shape[-1] < 3:
        return scaled
    standing = scalars[..., 2:3].clamp(max=STANDING_CLIP_S) / STANDING_SCALE_S
    return torch.cat([scaled, standing], dim=-1)


def first_scalars(scalars: torch.Tensor, count: int) -> torch.Tensor:
    """The first ``count`` scalar columns; a clear error when the caller passed fewer."""
    if scalars.shape[-1] < count:
        raise ValueError(f"this network reads {count} scalars (speed, target speed, standing time), got "
                         f"{scalars.shape[-1]}")
    return scalars[..., :count]


def sigma_at(agent_steps: int, decay_agent_steps: int, start: float = 0.65, end: float = 0.05) -> float:
    """Exploration sigma, linear from ``start`` to ``end`` over ``decay_agent_steps`` (paper, Fig. 4)."""
    if decay_agent_steps <= 0:
        return end
    fraction = min(1.0, max(0.0, agent_steps / decay_agent_steps))
    return start + (end - start) * fraction


def parameter_shapes(policy: nn.Module) -> dict[str, tuple[int, ...]]:
    return {name: tuple(p.shape) for name, p in policy.named_parameters()}


def save_atomically(state: dict, path: str | Path) -> Path:
    """``torch.save`` to a temporary file beside ``path``, fsync, rename: a reader, or a kill
    mid-write, sees the old file or the whole new one, never half of it."""
    path = Path(path)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(temporary, "wb") as handle:
        torch.save(state, handle)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)
    return path


def load_policy(checkpoint: str | Path) -> Policy:
    """A policy from a learner checkpoint; a clear error if the file or network does not fit.

    A file that holds ``members`` (an output ensemble as docs/scripts/ensemble.py writes it, each
    member's weights and sizes) gives the one network ``ensemble`` joins them into: the file keeps
    only the members, not the joined network's zero blocks, and may hold a ``caution`` entry
    (``Caution``), which the returned network carries for ``evaluation.policy.PolicyDriver``. Any
    checkpoint may hold an ``emergency_braking`` entry (``algo.braking.EmergencyBraking``), carried
    the same way."""
    path = Path(checkpoint)
    if not path.is_file():
        raise ValueError(f"no checkpoint file {str(path)!r}")
    try:
        state = torch.load(path, weights_only=False, map_location="cpu")
    except Exception as error:  # torch raises several types for a file that is not a checkpoint
        raise ValueError(f"{path} is not a crossway checkpoint ({type(error).__name__}: {error})") from None
    if isinstance(state, dict) and "members" in state:
        members = state["members"]
        if not isinstance(members, list) or not members:
            raise ValueError(f"{path}: an ensemble file without members")
        joined = ensemble([_policy_from(f"{path} (member {k + 1})", member) for k, member in enumerate(members)])
        if state.get("caution") is not None:
            if len(members) < 2:
                raise ValueError(f"{path}: caution needs at least two members to disagree, it has one")
            joined.caution = caution_from(str(path), state["caution"])
        joined.emergency_braking = emergency_braking_from(str(path), state.get("emergency_braking"))
        return joined
    policy = _policy_from(str(path), state)
    if isinstance(state, dict):
        policy.emergency_braking = emergency_braking_from(str(path), state.get("emergency_braking"))
    return policy


def _policy_from(source: str, state) -> Policy:
    """The network of one ``{"policy": weights, "policy_config": sizes}`` entry; ``source`` names it in errors."""
    if not isinstance(state, dict) or "policy" not in state or "policy_config" not in state:
        raise ValueError(f"{source} is not a crossway learner checkpoint (no policy or policy_config)")
    try:
        config = PolicyConfig(**state["policy_config"])
    except TypeError as error:
        raise ValueError(f"{source}: its network description does not match this crossway ({error})") from None
    policy = Policy(config)
    try:
        policy.load_state_dict(state["policy"])
    except RuntimeError as error:
        raise ValueError(f"{source}: its weights do not match the network {config} ({str(error)[:200]})") from None
    policy.eval()
    return policy


def views_record(extent_m: float, shift_m: float) -> dict[str, float]:
    """The ``views`` entry of a checkpoint: the view square its weights learnt from [m]."""
    return {"extent_m": float(extent_m), "shift_m": float(shift_m)}


def policy_views(checkpoint: str | Path) -> tuple[float, float] | None:
    """(side, centre ahead of the car) [m] of the view square a checkpoint's weights learnt from:
    ``PAPER_VIEWS`` for a file that does not record one, None for a learner checkpoint written
    before any actor reported its views (the weights have not learnt from any yet)."""
    state = torch.load(Path(checkpoint), weights_only=False, map_location="cpu")
    if not isinstance(state, dict) or "views" not in state:
        return PAPER_VIEWS
    views = state["views"]
    return None if views is None else (float(views["extent_m"]), float(views["shift_m"]))


class ViewMismatch(ValueError):
    """Weights meet inputs drawn through another view square than the one they learnt from."""


def same_views(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Two view squares are the same to a millimetre."""
    return abs(a[0] - b[0]) < 1e-3 and abs(a[1] - b[1]) < 1e-3


def describe_views(views: tuple[float, float]) -> str:
    return f"views {views[0]:g} m wide, centred {views[1]:g} m ahead of the car"


def require_views(checkpoint: str | Path, shown: tuple[float, float], scenario: str, advice: str) -> None:
    """Raise ``ViewMismatch`` (ending with ``advice``) when the checkpoint's weights learnt from
    another view square than ``shown``, the one scenario ``scenario``'s agents see."""
    learnt = policy_views(checkpoint)
    if learnt is not None and not same_views(learnt, shown):
        raise ViewMismatch(f"{checkpoint} learnt from {describe_views(learnt)}, but scenario {scenario!r} shows "
                           f"{describe_views(shown)}: {advice}")
