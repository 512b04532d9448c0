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
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import torch

from evaluation.policy import check_checkpoint
from evaluation.table1 import OUTCOMES, SIGNS, TestSpec, chunks_of, delay_schedule, start_test
from simcore.controller import DriverOptions
from simcore.scenario import ScenarioError, load_scenario

TEACHER = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                        wait_outside_zones=True, break_wait_cycles=True)


def reset_outcomes(job: TestSpec) -> dict[str, Counter]:
    """Sign -> end reason -> count of the episodes ``job``'s reset began ("cut": a redraw ended one)."""
    sim, result, act = start_test(job)
    pending = set(np.flatnonzero(result.started).tolist())
    counts: dict[str, Counter] = defaultdict(Counter)
    while pending:
        result = sim.step(act(result))
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
    checkpoint = None if args.checkpoint == "teacher" else args.checkpoint
    run_tests = None
    try:  # everything refused before the replay, not after it
        spec = load_scenario(args.scenario)
        if checkpoint is not None:
            check_checkpoint(checkpoint, spec)  # a bad file or other views
        if args.table1_json:
            run = json.loads(Path(args.table1_json).read_text())
            meta, run_tests = run["meta"], run["tests"]
            if (meta["scenario"], meta["seed"], meta["episodes_per_test"]) != (spec.name, args.seed, args.episodes):
                raise ValueError(f"{args.table1_json} is a run of {meta['scenario']} with --seed {meta['seed']} and "
                                 f"--episodes {meta['episodes_per_test']}; pass those")
    except (OSError, KeyError, ScenarioError, ValueError) as error:
        sys.exit(f"reset_starts: {error}")
    started = time.time()
    per_test: dict[float, dict[str, Counter]] = {}
    for i, delay_max_s in enumerate(delay_schedule(spec.episodes.delay_max_s)):
        test = TestSpec(spec, delay_max_s, args.episodes, args.seed + i, checkpoint, TEACHER)
        per_test[delay_max_s] = defaultdict(Counter)
        for job in chunks_of(test):
            for sign, reasons in reset_outcomes(job).items():
                per_test[delay_max_s][sign].update(reasons)
        print(f"delay_max {delay_max_s:g} s: {({s: dict(c) for s, c in per_test[delay_max_s].items()})} "
              f"({time.time() - started:.0f} s)", flush=True)
    report = {"checkpoint": args.checkpoint, "scenario": spec.name, "episodes": args.episodes, "seed": args.seed,
              "per_test": {f"{d:g}": {s: dict(c) for s, c in t.items()} for d, t in per_test.items()}}
    if run_tests is not None:
        reach = {}
        for sign in SIGNS:
            with_them = without = 0.0
            for test in run_tests:
                counts, theirs = test["counts"][sign], per_test[test["delay_max_s"]].get(sign, Counter())
                n, goals = sum(counts.values()), counts.get("goal", 0)
                counted = sum(v for k, v in theirs.items() if k != "cut")
                with_them += goals / n
                without += (goals - theirs.get("goal", 0)) / (n - counted)
            reach[sign] = {"all": round(with_them / len(run_tests), 4),
                           "without_reset": round(without / len(run_tests), 4)}
        report["reach"] = reach
    print(json.dumps(report))


if __name__ == "__main__":
    main()
