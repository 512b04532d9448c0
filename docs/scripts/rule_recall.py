"""How often a network alone brakes where the emergency braking would (session 41).

    python docs/scripts/rule_recall.py --checkpoint CKPT [--delay-max 10] [--episodes 300] [--seed 7]

Drives the hard junction with the trained policy ``--checkpoint`` alone (its ``emergency_braking``
entry, if any, is not applied) and asks, every step and for every car, what the emergency braking
of ``algo.braking`` (the checkpoint's settings, else the defaults) would have commanded. Prints one
JSON line: the car-steps; the share where the rule would have overridden the network; over those,
the network's and the rule's mean accelerations [m/s^2] and the share where the network already
brakes within ``--tolerance`` m/s^2 of the rule ("recall"); the mean amount [m/s^2] the rule
takes off the network's acceleration per car-step; and the episodes' outcomes. A network
taught the rule's braking (``crossway pretrain --teacher-checkpoint`` the same network with the
rule) should override less and agree more than the one it started from.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys

import numpy as np

from algo.braking import EmergencyBraking
from algo.policy import load_policy
from evaluation.policy import PolicyDriver, check_checkpoint
from evaluation.table1 import OUTCOMES
from simcore.simulator import SimConfig, Simulator


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--delay-max", type=float, default=10.0, help="longest wait between a lane's episodes [s]")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--tolerance", type=float, default=0.5, help="[m/s^2]")
    args = parser.parse_args()

    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max), seed=args.seed)
    try:
        check_checkpoint(args.checkpoint, sim.spec)
        policy = load_policy(args.checkpoint)
    except ValueError as error:
        sys.exit(f"rule_recall: {error}")
    rule = policy.emergency_braking or EmergencyBraking()
    policy.emergency_braking = None  # the network alone drives
    driver = PolicyDriver(sim, policy)
    views = sim.spec.views
    result = sim.reset()
    car_steps = fires = agreed = 0
    network_sum = rule_sum = correction = 0.0
    outcomes: collections.Counter = collections.Counter()
    while sum(outcomes.values()) < args.episodes:
        actions = driver.act(result)
        active = np.flatnonzero(sim.learners_present)
        if len(active):
            network = actions[active, 0]
            ruled, _ = rule.apply(result.views[active], result.scalars[active, 0], network,
                                  views.extent_m, views.shift_m)
            overridden = ruled < network - 1e-9
            car_steps += len(active)
            fires += int(overridden.sum())
            agreed += int((overridden & (network <= ruled + args.tolerance)).sum())
            network_sum += float(network[overridden].sum())
            correction += float((network - ruled).sum())
            rule_sum += float(ruled[overridden].sum())
        result = sim.step(actions)
        outcomes.update(e.end_reason for e in result.episodes if e.end_reason in OUTCOMES)
    episodes = sum(outcomes.values())
    print(json.dumps({
        "checkpoint": args.checkpoint, "delay_max_s": args.delay_max, "seed": args.seed, "rule": rule.record(),
        "car_steps": car_steps, "override_share": round(fires / car_steps, 5),
        "network_mean_mps2": round(network_sum / max(fires, 1), 3), "rule_mean_mps2": round(rule_sum / max(fires, 1), 3),
        "recall": round(agreed / max(fires, 1), 4),
        "correction_mps2_per_car_step": round(correction / car_steps, 5), "tolerance_mps2": args.tolerance,
        "episodes": episodes, "outcomes": {k: round(v / episodes, 4) for k, v in sorted(outcomes.items())}}))


if __name__ == "__main__":
    main()
