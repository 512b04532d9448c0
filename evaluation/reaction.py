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
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from algo.policy import ACTION_SCALE
from evaluation.parallel import run_parallel
from evaluation.table1 import OUTCOMES

APPROACH_WINDOW_M = 20.0  # an encounter starts this far before the shared conflict zone [m]
GIVE_WAY_MIN_MPS2 = 0.5  # a drop in commanded acceleration this large counts as giving way [m/s^2]
OBSTACLE_PLANES = slice(8, 12)  # channel 2 (obstacles), frames 0-3, in the [16, 84, 84] views
NEWEST_OBSTACLE_PLANE = 11
HIGHER_PRIORITY_CODE = 128  # simcore.views.HIGHER_PRIORITY
CHUNK_EPISODES = 100


@dataclass(frozen=True)
class ProbeSpec:
    scenario: str
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
    done = 0
    while done < spec.episodes:
        slots = [s for s in encounter_slots(sim)
                 if (result.views[s, NEWEST_OBSTACLE_PLANE] == HIGHER_PRIORITY_CODE).any()]
        if slots:
            views = result.views[slots]
            scalars = np.repeat(result.scalars[slots], 2, axis=0)
            both = np.stack([views, erase_priority_cars(views)], axis=1).reshape(-1, *views.shape[1:])
            mu, values = driver.heads(both, scalars)
            mu_acc = np.clip(mu[:, 0], -1.0, 1.0).reshape(-1, 2) * float(ACTION_SCALE[0])
            acceleration.extend(mu_acc.tolist())
            value.extend(values[:, 0].reshape(-1, 2).tolist())
        result = sim.step(driver.act(result))
        finished = sum(1 for e in result.episodes if e.end_reason in OUTCOMES)
        done += finished
        if progress is not None and finished:
            progress.put(finished)
    return {"acceleration": acceleration, "value": value, "episodes": done}


def summarise(parts: list[dict]) -> dict:
    acceleration = np.array([row for p in parts for row in p["acceleration"]]).reshape(-1, 2)
    value = np.array([row for p in parts for row in p["value"]]).reshape(-1, 2)
    n = len(acceleration)
    if n == 0:
        return {"encounter_steps": 0, "episodes": sum(p["episodes"] for p in parts)}
    drop = acceleration[:, 1] - acceleration[:, 0]  # how much the priority cars lower the command
    return {
        "episodes": sum(p["episodes"] for p in parts),
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


def markdown(summary: dict) -> str:
    if not summary["encounter_steps"]:
        return "No encounter steps: no car approached a zone with a priority car in view.\n"
    return (
        "| | with priority cars | priority cars erased |\n|---|---|---|\n"
        f"| mean commanded acceleration [m/s^2] | {_number(summary['acceleration_with_mps2'])} | "
        f"{_number(summary['acceleration_without_mps2'])} |\n"
        f"| mean value v_acc | {_number(summary['value_with'])} | {_number(summary['value_without'])} |\n\n"
        f"{summary['encounter_steps']} encounter steps in {summary['episodes']} episodes. The priority cars "
        f"lower the commanded acceleration by {_number(summary['mean_drop_mps2'])} m/s^2 on average; the car gives "
        f"way (a drop of at least {GIVE_WAY_MIN_MPS2} m/s^2) at {100 * summary['give_way_fraction']:.1f}% of "
        f"the steps and brakes at {100 * summary['braking_fraction']:.1f}%.\n"
    )


def run_reaction(scenario: str, checkpoint: str, episodes: int, delay_max_s: float, workers: int, seed: int,
                 out_dir: Path, command: str) -> dict:
    from evaluation.policy import load_policy
    from simcore.scenario import load_scenario

    spec = load_scenario(scenario)
    load_policy(checkpoint)  # refuse a bad checkpoint before starting workers
    if not delay_max_s >= 0:
        raise ValueError(f"--delay-max must be >= 0, got {delay_max_s}")
    chunks = [ProbeSpec(spec.name, delay_max_s, min(CHUNK_EPISODES, episodes - start), seed + start, checkpoint)
              for start in range(0, episodes, CHUNK_EPISODES)]
    started = time.monotonic()
    parts = run_parallel(run_probe, [(c,) for c in chunks], episodes, workers, f"reaction {spec.name}")
    summary = summarise(parts)
    meta = {"scenario": spec.name, "checkpoint": checkpoint, "episodes": episodes, "delay_max_s": delay_max_s,
            "seed": seed, "workers": workers, "approach_window_m": APPROACH_WINDOW_M,
            "give_way_min_mps2": GIVE_WAY_MIN_MPS2, "wall_s": round(time.monotonic() - started, 1),
            "command": command}
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = out_dir / f"reaction-{spec.name}"
    json_path = stem.with_suffix(".json")
    json_path.write_text(json.dumps({"meta": meta, "summary": summary}, indent=2))
    md_path = stem.with_suffix(".md")
    text = markdown(summary)
    md_path.write_text(f"# Reaction to priority cars, {spec.name}\n\n{command}\n\n{text}")
    return {"summary": summary, "markdown": text, "paths": [str(json_path), str(md_path)], "meta": meta}
