"""``crossway pretrain``: a warm start for D-A3C from a privileged scripted teacher (not in the paper).

One process, no transport: a simulator whose every car is labelled by ``ScriptedDriver`` (which
reads the right of way from the simulator), or by a trained policy (``PolicyTeacher``: policy
distillation, e.g. of an output ensemble into one network), and driven either by it or by the student network,
a ``DemonstrationBuffer`` and Adam on the imitation loss (``algo.imitation``). Rounds alternate
collection and training. A new episode is driven by the teacher with probability
0.5 ** (samples collected / ``teacher_half_life``): 1 at first, then less and less (DAgger, Ross
et al. 2011), so that later data come from the states the student itself reaches. The output is
an exported policy that ``crossway train --init-from`` and every ``crossway evaluate`` take.

With ``average_half_life`` set, the exported weights are an exponential moving average of the
Adam iterates (Polyak and Juditsky 1992): each step's weights count 0.5 ** (steps since / half-life)
of the average, which smooths the step-to-step noise of the last updates; the last iterate itself
is written beside it (``pretrained-last.pt``) and is also the one that drives during collection.
"""

from __future__ import annotations

import csv
import json
import time
from collections import deque
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from algo.imitation import ACCELERATION_LOSSES, BRAKE_LABEL, DemonstrationBuffer, Episode, imitation_loss, newest_frames
from algo.policy import ACTION_SCALE, Policy, PolicyConfig, load_policy, save_atomically, views_record, widen
from crossway.stopping import StopRequest, stop_handlers
from simcore.controller import BLOCKER_PATIENCE_S, PATIENCE_S, SIGHTS

PROGRESS_COLUMNS = ("wall_s", "round", "teacher_probability", "samples", "updates", "action_loss_acc",
                    "action_loss_sa", "value_loss_acc", "value_loss_sa", "student_episodes",
                    "student_reach_rate", "teacher_episodes", "teacher_reach_rate",
                    "brake_label_share",  # of the samples trained on, the share the teacher brakes hard in
                    "blocker_label_share",  # ... and the share it brakes for a car in its way in
                    "released_label_share")  # ... and the share it goes in once its patience ran out
ROLLING_EPISODES = 200  # reach rates are over each driver's last this many finished episodes


@dataclass(frozen=True)
class PretrainConfig:
    scenario: str = "easy"
    minutes: float = 10.0  # wall-clock budget [min]
    rounds: int = 0  # stop after this many rounds as well (0: only the budget stops it)
    steps_per_round: int = 500  # simulator steps collected between training phases (0.1 s each)
    reuse: float = 4.0  # expected number of times each collected sample is trained on
    batch_size: int = 64
    learning_rate: float = 3e-4  # Adam
    value_coef: float = 0.5  # weight of the value losses against the action losses
    gamma: float = 0.99  # discount of the value targets (use the one D-A3C will train with)
    # "full": the teacher yields to every car with priority; "view": only to those its views show
    teacher_sight: str = "full"
    # the teacher slows to this speed before conflict zones a car with priority may come to [m/s]; None: it does not
    teacher_approach_mps: float | None = None
    # which signs decide those zones: "all" (every arm's, privileged) or "own" (its own sign, others taken as unsigned)
    teacher_approach_signs: str = "all"
    # the teacher also stops before a conflict zone a car in sight occupies, whatever the priority
    teacher_brake_for_blockers: bool = False
    # the teacher never stops inside another route's conflict zone (before the first of overlapping ones)
    teacher_wait_outside_zones: bool = False
    # the teacher goes ahead of a car with priority that waits, through a chain of cars, for it
    teacher_break_wait_cycles: bool = False
    # the teacher stops yielding to cars with priority / braking for blockers after standing this long [s]; inf: never
    teacher_patience_s: float = PATIENCE_S
    teacher_blocker_patience_s: float = BLOCKER_PATIENCE_S
    teacher_half_life: float = 20_000.0  # samples after which the teacher drives half the new episodes
    brake_weight: float = 1.0  # weight of the teacher's hard-braking labels in the action loss (imitation_loss)
    # a further factor on the weight of the labels where the teacher brakes for a car in its way (needs
    # teacher_brake_for_blockers)
    blocker_weight: float = 1.0
    # a further factor on the weight of the labels where the teacher goes, having stood out its patience,
    # although a car with priority is near (needs a finite teacher_patience_s)
    patience_weight: float = 1.0
    # the acceleration mean's error: "squared" (fits the labels' mean) or "absolute" (their median: where
    # the views cannot tell a going state from a braking one, the commoner decision, not a compromise)
    acceleration_loss: str = "squared"
    # draw training samples with probability ~ (student's acceleration error + floor) ** this; 0: uniformly
    # (algo.imitation's prioritized sampling)
    priority_exponent: float = 0.0
    buffer_samples: int = 40_000  # replay capacity, 28 KB per sample
    delay_max_s: float | None = None  # waits between a lane's episodes (None: the scenario's)
    seed: int = 0
    init_from: Path | None = None  # start from these weights (a checkpoint or an exported policy)
    torch_threads: int = 2
    # export an exponential moving average of the weights over Adam steps with this half-life (None: the last weights)
    average_half_life: float | None = None
    # the network's sizes (conv1 channels, conv2 channels, hidden units); with init_from, the loaded
    # network is widened to them keeping its function (algo.policy.widen). None: the file's, or the default
    network: tuple[int, int, int] | None = None
    # give the network a third scalar input, the time the car has stood [s] (algo.policy.PolicyConfig);
    # a loaded network gets it with zero weights (unread until training moves them). Not the paper's
    standing_input: bool = False
    # distil a trained policy instead (an output ensemble, docs/scripts/ensemble.py): its Gaussian means
    # are the labels and the scripted teacher's options above do not apply. None: the scripted teacher
    teacher_checkpoint: Path | None = None
    # drive the episodes the student would drive with this fixed trained policy instead (such as the
    # output ensemble the student will join): the labels then come from the states the policy that will
    # be deployed meets (DAgger on its distribution, not the student's own). None: the student drives
    driver_checkpoint: Path | None = None


# the scripted teacher's settings; a policy teacher (teacher_checkpoint) refuses any of them changed
SCRIPTED_TEACHER_FIELDS = ("teacher_sight", "teacher_approach_mps", "teacher_approach_signs",
                           "teacher_brake_for_blockers", "teacher_wait_outside_zones", "teacher_break_wait_cycles",
                           "teacher_patience_s", "teacher_blocker_patience_s", "blocker_weight", "patience_weight")


def scripted_teacher_changes(config: PretrainConfig) -> list[str]:
    """The scripted teacher's settings (``SCRIPTED_TEACHER_FIELDS``) that ``config`` changes from their defaults."""
    return [name for name in SCRIPTED_TEACHER_FIELDS if getattr(config, name) != getattr(PretrainConfig, name)]


def check_config(config: PretrainConfig, name=lambda field: field) -> None:
    """Refuse settings a run cannot use, before anything is built; ``name(field)`` names a setting in the
    messages (the ``crossway pretrain`` command passes its flags). An unknown approach_signs is
    ``DriverOptions``' to refuse (the command's choices never pass one)."""

    def finite_positive(value) -> bool:
        return 0.0 < value < float("inf")  # False for nan

    if not config.minutes > 0:  # inf: only the rounds stop the run
        raise ValueError(f"{name('minutes')} must be > 0, got {config.minutes}")
    if config.rounds < 0:
        raise ValueError(f"{name('rounds')} must be >= 0, got {config.rounds}")
    for field in ("steps_per_round", "batch_size", "buffer_samples", "torch_threads"):
        if getattr(config, field) < 1:
            raise ValueError(f"{name(field)} must be >= 1, got {getattr(config, field)}")
    for field in ("reuse", "learning_rate"):
        if not finite_positive(getattr(config, field)):
            raise ValueError(f"{name(field)} must be > 0, got {getattr(config, field)}")
    if not 0.0 <= config.value_coef < float("inf"):
        raise ValueError(f"{name('value_coef')} must be >= 0, got {config.value_coef}")
    if not 0.0 < config.gamma <= 1.0:
        raise ValueError(f"{name('gamma')} must be in (0, 1], got {config.gamma}")
    if config.teacher_sight not in SIGHTS:
        raise ValueError(f"{name('teacher_sight')} must be one of {SIGHTS}, got {config.teacher_sight!r}")
    if config.teacher_approach_mps is not None and not finite_positive(config.teacher_approach_mps):
        raise ValueError(f"{name('teacher_approach_mps')} must be a speed > 0 m/s, got {config.teacher_approach_mps}")
    if config.teacher_approach_signs != "all" and config.teacher_approach_mps is None:
        raise ValueError(f"{name('teacher_approach_signs')} goes with {name('teacher_approach_mps')}")
    for field in ("teacher_patience_s", "teacher_blocker_patience_s"):
        if not getattr(config, field) > 0:
            raise ValueError(f"{name(field)} must be > 0 s ('inf': never), got {getattr(config, field)}")
    if not config.teacher_half_life > 0:
        raise ValueError(f"{name('teacher_half_life')} must be > 0 samples, got {config.teacher_half_life}")
    if not config.brake_weight > 0:
        raise ValueError(f"{name('brake_weight')} must be > 0, got {config.brake_weight}")
    if not finite_positive(config.blocker_weight):
        raise ValueError(f"{name('blocker_weight')} must be > 0, got {config.blocker_weight}")
    if config.blocker_weight != 1.0 and not config.teacher_brake_for_blockers:
        raise ValueError(f"{name('blocker_weight')} weighs the teacher's braking for blockers: it goes with "
                         f"{name('teacher_brake_for_blockers')}")
    if not finite_positive(config.patience_weight):
        raise ValueError(f"{name('patience_weight')} must be > 0, got {config.patience_weight}")
    if config.patience_weight != 1.0 and config.teacher_patience_s == float("inf"):
        raise ValueError(f"{name('patience_weight')} weighs the teacher's going once its patience ran out: it "
                         f"needs a finite {name('teacher_patience_s')}")
    if config.acceleration_loss not in ACCELERATION_LOSSES:
        raise ValueError(f"{name('acceleration_loss')} must be one of {ACCELERATION_LOSSES}, "
                         f"got {config.acceleration_loss!r}")
    if not 0.0 <= config.priority_exponent < float("inf"):
        raise ValueError(f"{name('priority_exponent')} must be >= 0 (0: uniform sampling), "
                         f"got {config.priority_exponent}")
    if config.average_half_life is not None and not finite_positive(config.average_half_life):
        raise ValueError(f"{name('average_half_life')} must be > 0 Adam steps, got {config.average_half_life}")
    if config.delay_max_s is not None and not config.delay_max_s >= 0:
        raise ValueError(f"{name('delay_max_s')} must be >= 0 s, got {config.delay_max_s}")
    if config.network is not None and (len(config.network) != 3 or min(config.network) < 1):
        raise ValueError(f"{name('network')} must be three sizes >= 1, got {config.network}")
    changed = scripted_teacher_changes(config)
    if config.teacher_checkpoint is not None and changed:
        raise ValueError(f"{', '.join(name(field) for field in changed)} shape the scripted teacher; a policy "
                         f"teacher ({name('teacher_checkpoint')}) takes none of them")


def fixed_policy_driver(sim, checkpoint: Path, role: str):
    """A trained policy driving ``sim`` as ``crossway evaluate`` drives it (Gaussian means, an
    ensemble's members side by side, its caution applied); ValueError, naming its ``role``, when it
    learnt from another view square than the scenario's."""
    from algo.policy import policy_views
    from evaluation.policy import PolicyDriver

    views = policy_views(checkpoint)
    if views != (sim.spec.views.extent_m, sim.spec.views.shift_m):
        raise ValueError(f"{role} {checkpoint} learnt from a {views[0]:g} m view square "
                         f"{views[1]:g} m ahead; scenario {sim.spec.name!r} shows {sim.spec.views.extent_m:g} m "
                         f"{sim.spec.views.shift_m:g} m ahead")
    return PolicyDriver(sim, load_policy(checkpoint))


class PolicyTeacher:
    """A trained policy as the teacher (policy distillation): its Gaussian means, as ``crossway
    evaluate`` drives it (``evaluation.policy.PolicyDriver``, an ensemble's members side by side
    and its caution applied), label every car. It never brakes "for a blocker" in the scripted
    driver's sense, so ``blocker_bound`` stays False, nor does it wait out a patience
    (``patience_released``)."""

    def __init__(self, sim, checkpoint: Path):
        self.driver = fixed_policy_driver(sim, checkpoint, "teacher")
        self.blocker_bound = np.zeros(sim.num_slots, dtype=bool)
        self.patience_released = np.zeros(sim.num_slots, dtype=bool)

    def act(self, result) -> np.ndarray:
        return self.driver.act(result)


def _config_dict(config: PretrainConfig) -> dict:
    """The settings as JSON-friendly values (paths as text)."""
    return {k: str(v) if isinstance(v, Path) else v for k, v in asdict(config).items()}


def _reach_rate(outcomes) -> float | None:
    if not outcomes:
        return None
    return round(sum(o == "goal" for o in outcomes) / len(outcomes), 4)


class Pretrainer:
    """Collection and training, one round at a time; ``run_pretrain`` loops until the budget is spent."""

    def __init__(self, config: PretrainConfig):
        from simcore.controller import DriverOptions, scripted_driver
        from simcore.simulator import SimConfig, Simulator

        check_config(config)
        teacher_options = DriverOptions(  # refuses an unknown approach_signs
            sight=config.teacher_sight, approach_speed_mps=config.teacher_approach_mps,
            approach_signs=config.teacher_approach_signs, brake_for_blockers=config.teacher_brake_for_blockers,
            wait_outside_zones=config.teacher_wait_outside_zones, break_wait_cycles=config.teacher_break_wait_cycles,
            patience_s=config.teacher_patience_s, blocker_patience_s=config.teacher_blocker_patience_s)
        self.config = config
        torch.manual_seed(config.seed)
        torch.set_num_threads(config.torch_threads)
        sizes = {} if config.network is None else dict(zip(("conv1_channels", "conv2_channels", "hidden"),
                                                            config.network))
        if config.init_from is not None:
            self.policy = load_policy(config.init_from)
            wanted = replace(self.policy.config, **sizes,
                             standing_input=self.policy.config.standing_input or config.standing_input)
            if wanted != self.policy.config:
                self.policy = widen(self.policy, wanted, seed=config.seed)
        else:
            self.policy = Policy(PolicyConfig(**sizes, standing_input=config.standing_input))
        self.policy.train()
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=config.learning_rate)
        # the moving average of the weights (average_half_life), starting at the initial ones
        self.averaged: dict[str, torch.Tensor] | None = None
        if config.average_half_life is not None:
            self.averaged = {name: p.detach().clone() for name, p in self.policy.named_parameters()}
        sim_config = SimConfig() if config.delay_max_s is None else SimConfig(delay_max_s=config.delay_max_s)
        self.sim = Simulator(config.scenario, sim_config, seed=config.seed)
        if config.teacher_checkpoint is None:
            self.teacher = scripted_driver(self.sim, teacher_options)
            self._teacher_actions = lambda result: self.teacher.act()  # it reads the simulator itself
        else:
            self.teacher = PolicyTeacher(self.sim, Path(config.teacher_checkpoint))
            self._teacher_actions = self.teacher.act
        # who drives the episodes the teacher does not: a fixed policy, or the student (None)
        self.driver = None if config.driver_checkpoint is None else fixed_policy_driver(
            self.sim, Path(config.driver_checkpoint), "driver")
        self.buffer = DemonstrationBuffer(config.buffer_samples, config.gamma, config.priority_exponent)
        self.rng = np.random.default_rng(config.seed)
        self.result = self.sim.reset()
        slots = self.sim.num_slots
        self.episodes = [Episode.empty() for _ in range(slots)]
        self.by_teacher = np.ones(slots, dtype=bool)  # who drives each slot's current episode
        self.round = 0
        self.updates = 0
        # each driver's last finished episodes (end reasons), for the rolling reach rates
        self.outcomes: dict[str, deque[str]] = {d: deque(maxlen=ROLLING_EPISODES) for d in ("student", "teacher")}
        self.episodes_finished = {"student": 0, "teacher": 0}

    @property
    def teacher_probability(self) -> float:
        """Probability that the teacher drives a new episode (DAgger's beta)."""
        return 0.5 ** (self.buffer.added / self.config.teacher_half_life)

    def collect(self, steps: int) -> None:
        """Drive ``steps`` simulator steps, labelling every car's observation with the teacher's action."""
        from evaluation.policy import PolicyDriver

        sim = self.sim
        student = PolicyDriver(sim, self.policy)
        stand_in = student if self.driver is None else self.driver  # drives where the teacher does not
        for _ in range(steps):
            result = self.result
            for slot in np.flatnonzero(result.started):
                self.by_teacher[slot] = self.rng.random() < self.teacher_probability
            teacher_actions = self._teacher_actions(result)  # once per step: the scripted one keeps waiting times
            actions = teacher_actions.copy()
            present = np.flatnonzero(sim.learners_present)
            prioritized = self.config.priority_exponent > 0  # then the student's error is measured on every car
            errors = None
            driving = bool((~self.by_teacher[present]).any())
            if driving:
                driven = stand_in.act(result)
                actions[~self.by_teacher] = driven[~self.by_teacher]
            if prioritized:  # the error is the student's own, whoever drives
                student_actions = driven if driving and stand_in is student else student.act(result)
            frames = newest_frames(result.views[present])
            targets = np.clip(teacher_actions[present] / ACTION_SCALE, -1.0, 1.0).astype(np.float32)
            if prioritized:
                errors = np.abs(student_actions[present, 0] / ACTION_SCALE[0] - targets[:, 0])
            for k, slot in enumerate(present.tolist()):
                episode = self.episodes[slot]
                episode.frames.append(frames[k].copy())
                episode.scalars.append(result.scalars[slot].copy())
                episode.targets.append(targets[k])
                episode.blocker.append(bool(self.teacher.blocker_bound[slot]))
                episode.released.append(bool(self.teacher.patience_released[slot]))
                if errors is not None:
                    episode.errors.append(float(errors[k]))
            self.result = result = sim.step(actions)
            for slot in present.tolist():
                self.episodes[slot].rewards.append((float(result.reward_acc[slot]), float(result.reward_sa[slot])))
            for summary in result.episodes:
                slot = summary.slot
                self.buffer.add(self.episodes[slot], terminal=bool(result.terminated[slot]))
                self.episodes[slot] = Episode.empty()
                if result.terminated[slot]:
                    driver = "teacher" if self.by_teacher[slot] else "student"
                    self.outcomes[driver].append(summary.end_reason)
                    self.episodes_finished[driver] += 1

    def train(self, updates: int) -> dict:
        """``updates`` Adam steps on minibatches drawn from the buffer (uniformly, or by the student's
        error: ``priority_exponent``); mean losses and the share of hard-braking labels drawn."""
        totals: dict[str, float] = {}
        for _ in range(updates):
            indices = self.buffer.sample_indices(self.config.batch_size, self.rng)
            batch = self.buffer.batch(indices)
            loss, metrics, errors = imitation_loss(self.policy, batch, self.config.value_coef,
                                                   self.config.brake_weight, return_errors=True,
                                                   blocker_weight=self.config.blocker_weight,
                                                   patience_weight=self.config.patience_weight,
                                                   acceleration_loss=self.config.acceleration_loss)
            self.buffer.update_priorities(indices, errors)
            metrics["brake_label_share"] = float((batch["targets"][:, 0] <= BRAKE_LABEL).mean())
            metrics["blocker_label_share"] = float(batch["blocker"].mean())
            metrics["released_label_share"] = float(batch["released"].mean())
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), 40.0)
            self.optimizer.step()
            self.updates += 1
            if self.averaged is not None:
                self._update_average()
            for name, value in metrics.items():
                totals[name] = totals.get(name, 0.0) + value
        return {name: value / max(updates, 1) for name, value in totals.items()}

    def _update_average(self) -> None:
        """average <- decay * average + (1 - decay) * weights, decay = 0.5 ** (1 / half-life)."""
        decay = 0.5 ** (1.0 / self.config.average_half_life)
        with torch.no_grad():
            for name, p in self.policy.named_parameters():
                self.averaged[name].mul_(decay).add_(p.detach(), alpha=1.0 - decay)

    def run_round(self) -> dict:
        before = self.buffer.added
        probability = self.teacher_probability
        self.collect(self.config.steps_per_round)
        new_samples = self.buffer.added - before
        updates = int(round(self.config.reuse * new_samples / self.config.batch_size))
        losses = self.train(updates) if updates else {}
        row = {"round": self.round, "teacher_probability": round(probability, 4), "samples": self.buffer.added,
               "updates": self.updates, **{k: round(v, 5) for k, v in losses.items()},
               "student_episodes": self.episodes_finished["student"],
               "student_reach_rate": _reach_rate(self.outcomes["student"]),
               "teacher_episodes": self.episodes_finished["teacher"],
               "teacher_reach_rate": _reach_rate(self.outcomes["teacher"])}
        self.round += 1
        return row

    def export(self, path: Path, note: str, averaged: bool = True) -> Path:
        """Write the policy to ``path``: the moving average of the weights when there is one and
        ``averaged``, else the last weights."""
        path.parent.mkdir(parents=True, exist_ok=True)
        state = self.policy.state_dict()
        if averaged and self.averaged is not None:
            state = {**state, **{name: value.clone() for name, value in self.averaged.items()}}
        return save_atomically({"policy": state, "policy_config": asdict(self.policy.config),
                                "version": 0, "agent_steps": 0, "note": note,
                                "views": views_record(self.sim.spec.views.extent_m, self.sim.spec.views.shift_m),
                                "pretrain": {**_config_dict(self.config), "samples": self.buffer.added,
                                             "updates": self.updates, "rounds": self.round}}, path)


def _sizes(config: PolicyConfig) -> str:
    inputs = ", reads its standing time" if config.standing_input else ""
    return f"{config.conv1_channels},{config.conv2_channels},{config.hidden} (conv1, conv2, hidden per head){inputs}"


def _fmt(rate: float | None) -> str:
    return "  -  " if rate is None else f"{100 * rate:5.1f}%"


def run_pretrain(config: PretrainConfig, out_dir: Path, command: str, log=print, save_every_s: float = 300.0) -> Path:
    """Rounds until ``config.minutes`` have passed (or ``config.rounds`` are done); writes
    ``pretrained.pt``, ``pretrain.json`` and ``progress.csv``.

    ``save_every_s``: also write the policy (and its last weights) every so often during the
    run, so that a run killed outright loses at most that much (0: only at the end). Ctrl-C and
    SIGTERM stop it after writing the policy as it is."""
    out_dir.mkdir(parents=True, exist_ok=True)
    trainer = Pretrainer(config)
    approach = ("" if config.teacher_approach_mps is None else
                f", approach {config.teacher_approach_mps:g} m/s by {config.teacher_approach_signs} signs")
    approach += ", brakes for blockers" if config.teacher_brake_for_blockers else ""
    approach += ", waits outside zones" if config.teacher_wait_outside_zones else ""
    approach += ", breaks wait cycles" if config.teacher_break_wait_cycles else ""
    approach += f", patience {config.teacher_patience_s:g} s"
    if config.teacher_brake_for_blockers:
        approach += f" (for blockers {config.teacher_blocker_patience_s:g} s)"
    teacher = (f"ScriptedDriver (sight: {config.teacher_sight}{approach})" if config.teacher_checkpoint is None
               else f"the policy {config.teacher_checkpoint} (its Gaussian means)")
    driver = "" if config.driver_checkpoint is None else f", the other episodes driven by {config.driver_checkpoint}"
    log(f"pretrain {config.scenario}: teacher {teacher}{driver}, "
        f"network {_sizes(trainer.policy.config)}, buffer {config.buffer_samples} samples "
        f"({trainer.buffer.nbytes / 2**20:.0f} MiB), {config.acceleration_loss} acceleration error, "
        f"{config.minutes:g} min")
    started = time.monotonic()
    deadline = started + 60.0 * config.minutes
    progress_path = out_dir / "progress.csv"
    last_save = started

    def save(note: str) -> Path:
        path = trainer.export(out_dir / "pretrained.pt", note)
        if trainer.averaged is not None:
            trainer.export(out_dir / "pretrained-last.pt", note + " (the last weights, not their average)",
                           averaged=False)
        return path

    with progress_path.open("w", newline="") as handle, stop_handlers(StopRequest()) as stop:
        writer = csv.DictWriter(handle, fieldnames=PROGRESS_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        try:
            while time.monotonic() < deadline and not (config.rounds and trainer.round >= config.rounds):
                row = trainer.run_round()
                row["wall_s"] = round(time.monotonic() - started, 1)
                writer.writerow(row)
                handle.flush()
                elapsed = int(row["wall_s"])
                losses = (f"action loss {row['action_loss_acc']:.4f}/{row['action_loss_sa']:.4f}  value loss "
                          f"{row['value_loss_acc']:.4f}/{row['value_loss_sa']:.4f}" if "action_loss_acc" in row
                          else "no update yet (episodes enter the buffer when they end)")
                log(f"pretrain {elapsed // 60:02d}:{elapsed % 60:02d}  round {row['round']}  teacher drives "
                    f"{100 * row['teacher_probability']:3.0f}%  samples {row['samples']:,}  "
                    f"updates {row['updates']:,}  "
                    f"{losses}  reach (last {ROLLING_EPISODES}): student {_fmt(row['student_reach_rate'])} "
                    f"teacher {_fmt(row['teacher_reach_rate'])}")
                if save_every_s > 0 and time.monotonic() - last_save >= save_every_s:
                    save(f"{command}: a snapshot after {trainer.round} rounds, {trainer.buffer.added:,} samples, "
                         f"{trainer.updates:,} updates, {(time.monotonic() - started) / 60:.1f} min")
                    last_save = time.monotonic()
                stop.check()
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: keep what was learnt, as crossway train does
            log("pretrain: interrupted, writing the policy as it is")
    wall = time.monotonic() - started
    note = (f"{command}: {trainer.round} rounds, {trainer.buffer.added:,} samples, {trainer.updates:,} updates, "
            f"{wall / 60:.1f} min")
    path = save(note)
    if trainer.averaged is not None:
        log(f"pretrain: {path.name} holds the weights' moving average (half-life "
            f"{config.average_half_life:g} Adam steps), pretrained-last.pt the last weights")
    (out_dir / "pretrain.json").write_text(json.dumps(
        {"command": command, "wall_s": round(wall, 1), "rounds": trainer.round, "samples": trainer.buffer.added,
         "updates": trainer.updates, "config": _config_dict(config)}, indent=2))
    log(f"wrote {path} and {progress_path} ({wall / 60:.1f} min)")
    return path
