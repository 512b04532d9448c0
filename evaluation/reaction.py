"""Does a policy look at the cars it must give way to? A counterfactual probe.

The paper's agents learn the right-of-way rule from the obstacle channel alone, where cars with
priority over the ego are drawn "black" (paper, "Environment", Fig. 3c; code 128 here). This
probe drives a scenario with the policy (Gaussian means, no noise) and, at every step where a
car approaches a conflict zone that a car with priority over it has not yet cleared, runs the
network a second time on the same views with the black cars erased (all four frames). The gap
between the two outputs is how much the priority cars change what the car does:

- an *encounter step*: ego learner e and a car o with priority over e (``PriorityTable``) such
  that e's centre is at most ``APPROACH_WINDOW_M`` before the conflict zone it shares with o,
  and o shows in e's newest obstacle frame;
- *acceleration* [m/s^2]: the mean action, clipped and scaled as the simulator applies it;
- the car *gives way* at a step when the priority cars lower its commanded acceleration by at
  least ``GIVE_WAY_MIN_MPS2``.

A policy that has learned the rule slows for priority cars (a large gap, most steps give way);
a blind one does the same with and without them (gap near zero). Table I cannot tell these apart
from a crash rate alone.

The probe also asks whether the acceleration head's critic sees danger coming: over every step
of every finished episode, the area under the ROC curve of -v_acc as a score for "this car
crashes within the next ``RISK_HORIZON_STEPS`` steps" (0.5: the value says nothing about crashes;
1: every step before a crash has a lower value than every other step).

Last, the anatomy of the crashes: how many crashing cars ran into a car with priority over them
(the car that should have given way; paper, "Reward Shaping", r_terminal = -1) and how fast
they were going at impact, as a fraction of their target speed. A car that tried to give way
and misjudged hits slowly; one that never tried hits at full speed.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from algo.policy import ACTION_SCALE
from evaluation.parallel import cache_salt, clear_partial, kept_jobs, numeric_platform, partial_dir, run_parallel
from evaluation.table1 import OUTCOMES

if TYPE_CHECKING:
    from simcore.scenario import ScenarioSpec

APPROACH_WINDOW_M = 20.0  # an encounter starts this far before the shared conflict zone [m]
GIVE_WAY_MIN_MPS2 = 0.5  # a drop in commanded acceleration this large counts as giving way [m/s^2]
OBSTACLE_PLANES = slice(8, 12)  # channel 2 (obstacles), frames 0-3, in the [16, 84, 84] views
NEWEST_OBSTACLE_PLANE = 11
HIGHER_PRIORITY_CODE = 128  # simcore.views.HIGHER_PRIORITY
CHUNK_EPISODES = 100
RISK_HORIZON_STEPS = 20  # "about to crash": within this many 0.1 s steps of the crash
FULL_SPEED_RATIO = 0.9  # a crash at this fraction of the target speed or more: no attempt to give way


@dataclass(frozen=True)
class ProbeSpec:
    scenario: ScenarioSpec | str  # the spec itself: a scenario file need not exist in the worker
    delay_max_s: float
    episodes: int
    seed: int
    checkpoint: str


def encounter_slots(sim) -> list[int]:
    """Learner slots at an encounter step (module docstring) in the simulator's current state."""
    idx = np.flatnonzero(sim.present)
    learners = [k for k, v in enumerate(idx) if v < sim.num_slots]
    if len(idx) < 2 or not learners:
        return []
    higher = sim.priorities(idx)  # [ego, other]: other has priority over ego
    table = sim.priority
    routes = sim.route[idx]
    found = []
    for k in learners:
        if not higher[k].any():
            continue
        ahead = table.zone_start[routes[k], routes] - sim.s[idx[k]]  # to each shared zone [m]
        if (higher[k] & (ahead > 0.0) & (ahead <= APPROACH_WINDOW_M)).any():
            found.append(int(idx[k]))
    return found


def roc_auc(scores: np.ndarray, labels: np.ndarray) -> float | None:
    """Area under the ROC curve (Mann-Whitney, ties at their mean rank); None without both classes."""
    labels = np.asarray(labels, dtype=bool)
    positives, negatives = int(labels.sum()), int((~labels).sum())
    if positives == 0 or negatives == 0:
        return None
    order = np.argsort(scores, kind="mergesort")
    ranks = np.empty(len(scores))
    ranks[order] = np.arange(1, len(scores) + 1)
    sorted_scores = np.asarray(scores)[order]
    # average the ranks of tied scores
    _, first, counts = np.unique(sorted_scores, return_index=True, return_counts=True)
    for start, count in zip(first[counts > 1], counts[counts > 1]):
        ranks[order[start:start + count]] = start + (count + 1) / 2.0
    return float((ranks[labels].sum() - positives * (positives + 1) / 2.0) / (positives * negatives))


def erase_priority_cars(views: np.ndarray) -> np.ndarray:
    """Copies of ``views`` [B, 16, 84, 84] with every black (priority) pixel of the obstacle planes cleared."""
    erased = views.copy()
    planes = erased[:, OBSTACLE_PLANES]
    planes[planes == HIGHER_PRIORITY_CODE] = 0
    return erased


def run_probe(spec: ProbeSpec, progress=None) -> dict:
    """One chunk of episodes in a worker: per-encounter accelerations and values, with and without."""
    import torch

    from evaluation.policy import PolicyDriver, load_policy
    from simcore.simulator import SimConfig, Simulator

    torch.set_num_threads(1)
    sim = Simulator(spec.scenario, SimConfig(delay_min_s=0.0, delay_max_s=spec.delay_max_s), seed=spec.seed)
    driver = PolicyDriver(sim, load_policy(spec.checkpoint))
    result = sim.reset()
    acceleration, value = [], []  # rows: (with, without)
    episode_values: dict[int, list[float]] = {}  # slot -> v_acc at each step of its episode
    risk_scores, risk_labels = [], []
    crashes = []  # (ran into a car with priority, speed at impact / target speed) per crashed car
    done = 0
    while done < spec.episodes:
        actions, values_now = driver.act_with_values(result)  # the "with" pass: what the cars do
        slots = [s for s in encounter_slots(sim)
                 if (result.views[s, NEWEST_OBSTACLE_PLANE] == HIGHER_PRIORITY_CODE).any()]
        if slots:
            mu, values = driver.heads(erase_priority_cars(result.views[slots]), result.scalars[slots])
            erased_acc = np.clip(mu[:, 0], -1.0, 1.0) * float(ACTION_SCALE[0])
            acceleration.extend(zip(actions[slots, 0].tolist(), erased_acc.tolist()))
            value.extend(zip(values_now[slots, 0].tolist(), values[:, 0].tolist()))
        for slot in np.flatnonzero(sim.learners_present).tolist():
            episode_values.setdefault(slot, []).append(float(values_now[slot, 0]))
        result = sim.step(actions)
        finished = 0
        for episode in result.episodes:
            history = episode_values.pop(episode.slot, [])
            if episode.end_reason not in OUTCOMES:
                continue  # cut short: its outcome is unknown
            labels = np.zeros(len(history), dtype=bool)
            if episode.end_reason == "crash":
                labels[-RISK_HORIZON_STEPS:] = True
                crashes.append((episode.crashed_into_priority, episode.final_speed_mps / episode.target_speed_mps))
            risk_scores.extend(-v for v in history)
            risk_labels.extend(labels.tolist())
            finished += 1
        done += finished
        if progress is not None and finished:
            progress.put(finished)
    return {"acceleration": acceleration, "value": value, "episodes": done,
            "risk_scores": risk_scores, "risk_labels": risk_labels, "crashes": crashes}


def crash_anatomy(crashes: list[tuple[bool, float]]) -> dict:
    """Counts and impact speeds of crashed cars, given (ran into a car with priority, speed / target) each."""
    at_fault = np.array([ratio for into_priority, ratio in crashes if into_priority], dtype=float)
    anatomy = {"crashed_cars": len(crashes), "ran_into_priority": len(at_fault)}
    if len(at_fault):
        anatomy["at_fault_speed_ratio_median"] = round(float(np.median(at_fault)), 4)
        anatomy["at_fault_full_speed_fraction"] = round(float((at_fault >= FULL_SPEED_RATIO).mean()), 4)
    return anatomy


def summarise(parts: list[dict]) -> dict:
    acceleration = np.array([row for p in parts for row in p["acceleration"]]).reshape(-1, 2)
    value = np.array([row for p in parts for row in p["value"]]).reshape(-1, 2)
    n = len(acceleration)
    labels = np.array([label for p in parts for label in p["risk_labels"]], dtype=bool)
    auc = roc_auc(np.array([score for p in parts for score in p["risk_scores"]]), labels)
    risk = {"steps": len(labels), "steps_before_a_crash": int(labels.sum()),
            "value_crash_auc": None if auc is None else round(auc, 4)}
    crashes = crash_anatomy([tuple(c) for p in parts for c in p["crashes"]])
    if n == 0:
        return {"encounter_steps": 0, "episodes": sum(p["episodes"] for p in parts), "risk": risk,
                "crashes": crashes}
    drop = acceleration[:, 1] - acceleration[:, 0]  # how much the priority cars lower the command
    return {
        "episodes": sum(p["episodes"] for p in parts),
        "risk": risk,
        "crashes": crashes,
        "encounter_steps": n,
        "acceleration_with_mps2": round(float(acceleration[:, 0].mean()), 4),
        "acceleration_without_mps2": round(float(acceleration[:, 1].mean()), 4),
        "mean_drop_mps2": round(float(drop.mean()), 4),
        "give_way_fraction": round(float((drop >= GIVE_WAY_MIN_MPS2).mean()), 4),
        "braking_fraction": round(float((acceleration[:, 0] < 0.0).mean()), 4),
        "value_with": round(float(value[:, 0].mean()), 4),
        "value_without": round(float(value[:, 1].mean()), 4),
    }


def _number(value: float) -> str:
    return f"{round(value, 3) + 0.0:.3f}"  # + 0.0: no "-0.000"


def _risk_line(risk: dict) -> str:
    if risk["value_crash_auc"] is None:
        return (f"Value and crashes: {risk['steps']} steps, {risk['steps_before_a_crash']} of them in the last "
                f"{RISK_HORIZON_STEPS} steps before a crash: no AUC without both kinds.\n")
    return (f"Value and crashes: over {risk['steps']} steps, -v_acc separates the {risk['steps_before_a_crash']} "
            f"steps in the last {RISK_HORIZON_STEPS} before a crash from the others with ROC AUC "
            f"{risk['value_crash_auc']:.3f} (0.5: the value does not see crashes coming).\n")


def _crash_line(crashes: dict) -> str:
    if not crashes["crashed_cars"]:
        return "Crashes: none.\n"
    line = (f"Crashes: {crashes['crashed_cars']} cars crashed; {crashes['ran_into_priority']} of them ran into a car "
            "with priority over them")
    if crashes["ran_into_priority"]:
        line += (f", at a median {100 * crashes['at_fault_speed_ratio_median']:.0f}% of their target speed "
                 f"({100 * crashes['at_fault_full_speed_fraction']:.0f}% of them at {100 * FULL_SPEED_RATIO:.0f}% "
                 "or more: no attempt to give way)")
    return line + ".\n"


def markdown(summary: dict) -> str:
    if not summary["encounter_steps"]:
        return ("No encounter steps: no car approached a zone with a priority car in view.\n\n"
                + _risk_line(summary["risk"]) + "\n" + _crash_line(summary["crashes"]))
    return (
        "| | with priority cars | priority cars erased |\n|---|---|---|\n"
        f"| mean commanded acceleration [m/s^2] | {_number(summary['acceleration_with_mps2'])} | "
        f"{_number(summary['acceleration_without_mps2'])} |\n"
        f"| mean value v_acc | {_number(summary['value_with'])} | {_number(summary['value_without'])} |\n\n"
        f"{summary['encounter_steps']} encounter steps in {summary['episodes']} episodes. The priority cars "
        f"lower the commanded acceleration by {_number(summary['mean_drop_mps2'])} m/s^2 on average; the car gives "
        f"way (a drop of at least {GIVE_WAY_MIN_MPS2} m/s^2) at {100 * summary['give_way_fraction']:.1f}% of "
        f"the steps and brakes at {100 * summary['braking_fraction']:.1f}%.\n\n" + _risk_line(summary["risk"])
        + "\n" + _crash_line(summary["crashes"])
    )


def run_reaction(scenario: str, checkpoint: str, episodes: int, delay_max_s: float, workers: int, seed: int,
                 out_dir: Path, command: str) -> dict:
    from evaluation.policy import check_checkpoint
    from simcore.scenario import load_scenario

    spec = load_scenario(scenario)
    check_checkpoint(checkpoint, spec)  # refuse a bad checkpoint before starting workers
    if not delay_max_s >= 0:
        raise ValueError(f"--delay-max must be >= 0, got {delay_max_s}")
    chunks = [ProbeSpec(spec, delay_max_s, min(CHUNK_EPISODES, episodes - start), seed + start, checkpoint)
              for start in range(0, episodes, CHUNK_EPISODES)]
    started = time.monotonic()
    kept, salt, jobs = partial_dir(out_dir, f"reaction-{spec.name}"), cache_salt(checkpoint), [(c,) for c in chunks]
    resumed = kept_jobs(run_probe, jobs, kept, salt)  # finished chunks of an earlier run, stopped
    parts = run_parallel(run_probe, jobs, episodes, workers, f"reaction {spec.name}",
                         cache_dir=kept, salt=salt, sizes=[c.episodes for c in chunks])
    summary = summarise(parts)
    meta = {"scenario": spec.name, "checkpoint": checkpoint, "episodes": episodes, "delay_max_s": delay_max_s,
            "seed": seed, "workers": workers, "approach_window_m": APPROACH_WINDOW_M,
            "give_way_min_mps2": GIVE_WAY_MIN_MPS2, "risk_horizon_steps": RISK_HORIZON_STEPS,
            "full_speed_ratio": FULL_SPEED_RATIO, "wall_s": round(time.monotonic() - started, 1),
            "command": command, "jobs_from_an_earlier_run": resumed, "platform": numeric_platform()}
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = out_dir / f"reaction-{spec.name}"
    json_path = stem.with_suffix(".json")
    json_path.write_text(json.dumps({"meta": meta, "summary": summary}, indent=2))
    md_path = stem.with_suffix(".md")
    text = markdown(summary)
    md_path.write_text(f"# Reaction to priority cars, {spec.name}\n\n{command}\n\n{text}")
    clear_partial(kept)
    return {"summary": summary, "markdown": text, "paths": [str(json_path), str(md_path)], "meta": meta}
