"""One Table I test with the stop-sign cars driven by one policy and the other cars by another (session 34).

    python docs/scripts/sign_split.py --stop-checkpoint A.pt --other-checkpoint B.pt
        [--scenario hard] [--delay-max 10] [--episodes 3000] [--seed 0]

Runs ``evaluation.table1.run_test`` in this process, chunk by chunk as ``crossway evaluate table1
--sweep-up-to 10`` runs the protocol's first test (500-episode chunks, seeds S, S + 1000, ...), with
its policy driver replaced: each step, the cars whose newest view shows a stop line
(``algo.policy.sign_in_view``, what a learner's sign channel shows) act on ``--stop-checkpoint``,
the others (no sign, a yield line, or no line in sight yet) on ``--other-checkpoint``, each as
``crossway evaluate`` drives it (Gaussian means, an ensemble's members side by side, its caution
applied). Prints one JSON line: the test's counts per sign and end reason, its reach per sign and
the wall time. With the same checkpoint for both it is that checkpoint's own test, up to float
rounding of the smaller batches.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

import evaluation.policy
from algo.policy import ACTION_SCALE, load_policy, sign_in_view
from evaluation.table1 import TestSpec, chunks_of, merge_chunks, run_test
from simcore.scenario import ScenarioError, load_scenario

PolicyDriver = evaluation.policy.PolicyDriver  # the plain driver, kept before run_test's is replaced


class SignSplitDriver:
    """``PolicyDriver``'s ``act`` with two policies: stop-sign cars (by their view) on one, the rest on the other."""

    def __init__(self, sim, stop_checkpoint: str, other_checkpoint: str):
        self.sim = sim
        self.at_stop = PolicyDriver(sim, load_policy(stop_checkpoint))
        self.others = PolicyDriver(sim, load_policy(other_checkpoint))

    def act(self, result) -> np.ndarray:
        actions = np.zeros((self.sim.num_slots, 2))
        active = np.flatnonzero(self.sim.learners_present)
        if len(active) == 0:
            return actions
        views, scalars = result.views[active], result.scalars[active]
        at_stop = sign_in_view(views) == "stop"
        means = np.zeros((len(active), 2))
        for cars, driver in ((at_stop, self.at_stop), (~at_stop, self.others)):
            if cars.any():
                means[cars] = driver.heads(views[cars], scalars[cars])[0]
        actions[active] = np.clip(means, -1.0, 1.0) * ACTION_SCALE
        return actions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stop-checkpoint", required=True, help="drives the cars whose view shows a stop line")
    parser.add_argument("--other-checkpoint", required=True, help="drives every other car")
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--delay-max", type=float, default=10.0, help="the test's delay_max [s]")
    parser.add_argument("--episodes", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0, help="the test's seed, as --seed of crossway evaluate table1")
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    try:
        spec = load_scenario(args.scenario)
        for checkpoint in (args.stop_checkpoint, args.other_checkpoint):
            evaluation.policy.check_checkpoint(checkpoint, spec)  # a bad file or other views: refused before driving
    except (ScenarioError, ValueError) as error:
        sys.exit(f"sign_split: {error}")
    evaluation.policy.PolicyDriver = lambda sim, _policy: SignSplitDriver(sim, args.stop_checkpoint,
                                                                          args.other_checkpoint)
    started = time.monotonic()
    parts, done = [], 0
    for chunk in chunks_of(TestSpec(spec, args.delay_max, args.episodes, args.seed, args.stop_checkpoint)):
        parts.append(run_test(chunk))
        done += chunk.episodes
        print(f"sign_split: {done}/{args.episodes} episodes, {time.monotonic() - started:.0f} s",
              file=sys.stderr, flush=True)
    test = merge_chunks(parts)[0]
    reach = {sign: round(c.get("goal", 0) / sum(c.values()), 4) for sign, c in test["counts"].items()}
    print(json.dumps({"stop_checkpoint": args.stop_checkpoint, "other_checkpoint": args.other_checkpoint,
                      "delay_max_s": args.delay_max, "seed": args.seed, "counts": test["counts"], "reach": reach,
                      "wall_s": round(time.monotonic() - started, 1)}))


if __name__ == "__main__":
    main()
