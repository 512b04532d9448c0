"""Outcomes of the episodes a Table I run begins at each job's reset (session 35).

    python docs/results/reset-starts/reset_starts.py CHECKPOINT|teacher [--scenario hard] [--episodes 3000]
        [--seed 0] [--table1-json TABLE1.json]

``crossway evaluate table1`` runs each test in jobs of at most 500 episodes, each on a fresh
simulator whose reset starts every lane at once (eight cars on hard). Since session 35 the
protocol counts those episodes apart ("reset" in its "By how the episodes began" table); this
script finds them for a run made before that, without running it again: it replays every job of
the protocol exactly as ``evaluation.table1.run_test`` does (same seeds, same driver, same
steps) only until the episodes begun at the reset have ended, and prints their outcomes per test
and sign. ``teacher`` drives the hard students' view-limited teacher. With ``--table1-json`` (that
run's output) it also prints, per sign, the run's test-averaged reach with and without them.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter, defaultdict

import numpy as np
import torch

from evaluation.policy import PolicyDriver, load_policy
from evaluation.table1 import OUTCOMES, SIGNS, TestSpec, chunks_of, delay_schedule
from simcore.controller import DriverOptions, scripted_driver
from simcore.simulator import SimConfig, Simulator
from simcore.scenario import load_scenario

TEACHER = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                        wait_outside_zones=True, break_wait_cycles=True)


def reset_outcomes(job: TestSpec, policy) -> dict[str, Counter]:
    """Sign -> end reason -> count of the episodes ``job``'s reset began ("cut": a redraw ended one)."""
    sim = Simulator(job.scenario, SimConfig(delay_min_s=0.0, delay_max_s=job.delay_max_s, observe=policy is not None),
                    seed=job.seed)
    result = sim.reset()
    if policy is not None:
        driver = PolicyDriver(sim, policy)
        act = lambda: driver.act(result)  # noqa: E731 - reads the newest result, as run_test's
    else:
        act = scripted_driver(sim, TEACHER).act
    pending = set(np.flatnonzero(result.started).tolist())
    counts: dict[str, Counter] = defaultdict(Counter)
    while pending:
        result = sim.step(act())
        for episode in result.episodes:
            if episode.slot in pending:
                pending.discard(episode.slot)
                counts[episode.sign][episode.end_reason if episode.end_reason in OUTCOMES else "cut"] += 1
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", help="a policy checkpoint, or 'teacher' for the view-limited scripted teacher")
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--episodes", type=int, default=3000, help="per test, as the run's --episodes")
    parser.add_argument("--seed", type=int, default=0, help="the run's --seed")
    parser.add_argument("--table1-json", default=None, help="the run's table1-S.json: also print reaches without them")
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    torch.set_num_threads(1)
    spec = load_scenario(args.scenario)
    policy = None if args.checkpoint == "teacher" else load_policy(args.checkpoint)
    started = time.time()
    per_test: dict[float, dict[str, Counter]] = {}
    for i, delay_max_s in enumerate(delay_schedule(spec.episodes.delay_max_s)):
        test = TestSpec(spec, delay_max_s, args.episodes, args.seed + i, None, TEACHER)
        per_test[delay_max_s] = defaultdict(Counter)
        for job in chunks_of(test):
            for sign, reasons in reset_outcomes(job, policy).items():
                per_test[delay_max_s][sign].update(reasons)
        print(f"delay_max {delay_max_s:g} s: {({s: dict(c) for s, c in per_test[delay_max_s].items()})} "
              f"({time.time() - started:.0f} s)", flush=True)
    report = {"checkpoint": args.checkpoint, "scenario": spec.name, "episodes": args.episodes, "seed": args.seed,
              "per_test": {f"{d:g}": {s: dict(c) for s, c in t.items()} for d, t in per_test.items()}}
    if args.table1_json:
        tests = json.loads(open(args.table1_json).read())["tests"]
        reach = {}
        for sign in SIGNS:
            with_them = without = 0.0
            for test in tests:
                counts, theirs = test["counts"][sign], per_test[test["delay_max_s"]].get(sign, Counter())
                n, goals = sum(counts.values()), counts.get("goal", 0)
                counted = sum(v for k, v in theirs.items() if k != "cut")
                with_them += goals / n
                without += (goals - theirs.get("goal", 0)) / (n - counted)
            reach[sign] = {"all": round(with_them / len(tests), 4), "without_reset": round(without / len(tests), 4)}
        report["reach"] = reach
    print(json.dumps(report))


if __name__ == "__main__":
    main()
