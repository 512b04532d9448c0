"""Whose driving makes hard's stop-sign cars wait: a policy and its teacher in one junction (session 33).

    python docs/scripts/mixed_traffic.py --checkpoint CKPT --policy-drives stop|others|all|none
        [--stop-episodes 300] [--delay-max 10] [--seed 2]

Drives the hard junction (delay_min 0) with two drivers at once: the trained policy ``--checkpoint``
(Gaussian means, as ``crossway evaluate``) and the hard students' teacher (the scripted driver
limited to the views, slowing to 2 m/s by its own sign, braking for blockers, waiting outside
zones, breaking cycles, patience 4 s). ``--policy-drives`` says which cars the policy drives, by
the sign of their entry lane at each step: ``stop`` (the stop-sign cars; the teacher drives the
rest), ``others`` (every car but those), ``all`` or ``none``. Both drivers act every step for every
car, so their frames and clocks stay whole whichever of them drives. Stops after
``--stop-episodes`` stop-sign episodes ended in the goal, a crash or a time-over, and prints one
JSON line: per sign, the episodes by outcome and the mean seconds a car stood (under
``STANDING_MPS``), and the drivers' average speed. If the policy's stop-sign cars run out of time
as often among the teacher's cars as among its own, their waiting is theirs; if the teacher's
stop-sign cars run out of time among the policy's cars, it is the traffic's.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys

import numpy as np

from script_driver import ScriptDriver
from simcore.controller import STANDING_MPS, DriverOptions, scripted_driver
from simcore.dynamics import DT
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator

TEACHER = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                        wait_outside_zones=True, break_wait_cycles=True)
OUTCOMES = ("goal", "crash", "time_over")


def policy_mask(sign: np.ndarray, policy_drives: str) -> np.ndarray:
    """[slots] bool: the cars the policy drives, by their sign (see the module's docstring)."""
    at_stop = sign == Sign.STOP
    return {"stop": at_stop, "others": ~at_stop, "all": np.ones_like(at_stop), "none": np.zeros_like(at_stop)}[
        policy_drives]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", required=True, help="the trained policy (a checkpoint or models/*.pt)")
    parser.add_argument("--policy-drives", choices=("stop", "others", "all", "none"), required=True)
    parser.add_argument("--stop-episodes", type=int, default=300)
    parser.add_argument("--delay-max", type=float, default=10.0, help="[s]")
    parser.add_argument("--seed", type=int, default=2)
    args = parser.parse_args()

    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=True), seed=args.seed)
    result = sim.reset()
    teacher = scripted_driver(sim, TEACHER)
    policy = ScriptDriver(sim, TEACHER, args.checkpoint)
    stood_s: dict[int, float] = collections.defaultdict(float)
    by_sign: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    speed_sum = {"policy": 0.0, "teacher": 0.0}
    speed_steps = {"policy": 0, "teacher": 0}
    done = 0
    while done < args.stop_episodes:
        teacher_actions = teacher.act()
        policy_actions = policy.act(result)
        n = sim.num_slots
        learners = sim.learners_present
        by_policy = policy_mask(sim.sign[:n], args.policy_drives)
        actions = np.where(by_policy[:, None], policy_actions, teacher_actions)
        speed = sim.speed[:n]
        for slot in np.flatnonzero(learners & (speed < STANDING_MPS)).tolist():
            stood_s[slot] += DT
        for who, mask in (("policy", learners & by_policy), ("teacher", learners & ~by_policy)):
            speed_sum[who] += float(speed[mask].sum())
            speed_steps[who] += int(mask.sum())
        result = sim.step(actions)
        for episode in result.episodes:
            standing = stood_s.pop(episode.slot, 0.0)
            if episode.end_reason not in OUTCOMES:
                continue  # cut by a sign redraw
            counts = by_sign[episode.sign]
            counts[episode.end_reason] += 1
            counts[f"{episode.end_reason}/stood_s"] += standing
            if episode.sign == "stop":
                done += 1
                if done % 100 == 0:
                    print(f"{done} of {args.stop_episodes} stop-sign episodes", file=sys.stderr, flush=True)
    report = {}
    for sign, counts in sorted(by_sign.items()):
        total = sum(counts[o] for o in OUTCOMES)
        report[sign] = {"episodes": total, **{o: counts[o] for o in OUTCOMES},
                        "reach": round(counts["goal"] / total, 4),
                        **{f"{o}_mean_stood_s": round(counts[f"{o}/stood_s"] / counts[o], 2)
                           for o in OUTCOMES if counts[o]}}
    print(json.dumps({"checkpoint": args.checkpoint, "policy_drives": args.policy_drives,
                      "delay_max_s": args.delay_max, "seed": args.seed, "by_sign": report,
                      "mean_speed_mps": {who: round(speed_sum[who] / speed_steps[who], 3)
                                         for who in speed_sum if speed_steps[who]}}))


if __name__ == "__main__":
    main()
