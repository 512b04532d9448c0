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
``STANDING_MPS``); the drivers' average speed; per sign, the mean speed in 4 m stretches from 8 m
before the sign's line to 12 m past it (the car's centre); and what the stop-sign cars stood for,
in seconds per stop-sign episode, each standing step under every reason ``burst_waits.py`` finds
for it: a car in a zone ahead ("blocker"), or a car with priority near its zone, by that car's sign
and motion ("priority NONE slow": under 3 m/s; "standing": under ``STANDING_MPS``), or "other". If
the policy's stop-sign cars run out of time as often among the teacher's cars as among its own,
their waiting is theirs; if the teacher's stop-sign cars run out of time among the policy's cars,
it is the traffic's.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys

import numpy as np

from burst_waits import sight_and_priority, standing_for
from script_driver import HARD_TEACHER, ScriptDriver
from simcore.controller import STANDING_MPS, scripted_driver
from simcore.dynamics import DT
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator

OUTCOMES = ("goal", "crash", "time_over")
PROFILE_FROM_M, PROFILE_TO_M, PROFILE_STEP_M = -8.0, 12.0, 4.0  # around the sign's line [m]
SLOW_MPS = 3.0  # a car with priority under this speed is "slow" in the stood-for reasons [m/s]


def motion(speed_mps: float) -> str:
    return "standing" if speed_mps < STANDING_MPS else "slow" if speed_mps < SLOW_MPS else "moving"


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
    teacher = scripted_driver(sim, HARD_TEACHER)
    policy = ScriptDriver(sim, HARD_TEACHER, args.checkpoint)
    stood_s: dict[int, float] = collections.defaultdict(float)
    entry_lane = np.array([r.entry_lane for r in sim.intersection.routes])
    line_s = np.array([r.junction_entry_s for r in sim.intersection.routes])
    stood_for = collections.Counter()  # reason -> standing steps of counted stop-sign episodes
    stood_for_now: dict[int, collections.Counter] = collections.defaultdict(collections.Counter)  # slot -> ...
    bins = int((PROFILE_TO_M - PROFILE_FROM_M) / PROFILE_STEP_M)
    profile_sum, profile_steps = np.zeros((3, bins)), np.zeros((3, bins))  # [sign, stretch]
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
        standing = learners & (speed < STANDING_MPS)
        for slot in np.flatnonzero(standing).tolist():
            stood_s[slot] += DT
        at_stop = np.flatnonzero(standing & (sim.sign[:n] == Sign.STOP)).tolist()
        if at_stop:
            idx, higher, sight = sight_and_priority(sim)
            for slot in at_stop:
                found = standing_for(sim, slot, idx, higher, sight, entry_lane)
                reasons = {"blocker" if kind == "blocker" else
                           f"priority {Sign(int(sim.sign[other])).name if other < n else 'not a learner'} "
                           f"{motion(float(sim.speed[other]))}" for kind, other in found}
                stood_for_now[slot].update(reasons or {"other"})
        on_road = np.flatnonzero(learners)
        stretch = np.floor((sim.s[on_road] - line_s[sim.route[on_road]] - PROFILE_FROM_M) / PROFILE_STEP_M)
        inside = (stretch >= 0) & (stretch < bins)
        rows, cols = sim.sign[on_road][inside].astype(int), stretch[inside].astype(int)
        np.add.at(profile_sum, (rows, cols), speed[on_road][inside])
        np.add.at(profile_steps, (rows, cols), 1)
        for who, mask in (("policy", learners & by_policy), ("teacher", learners & ~by_policy)):
            speed_sum[who] += float(speed[mask].sum())
            speed_steps[who] += int(mask.sum())
        result = sim.step(actions)
        for episode in result.episodes:
            standing = stood_s.pop(episode.slot, 0.0)
            reasons = stood_for_now.pop(episode.slot, None)
            if episode.end_reason not in OUTCOMES:
                continue  # cut by a sign redraw
            counts = by_sign[episode.sign]
            counts[episode.end_reason] += 1
            counts[f"{episode.end_reason}/stood_s"] += standing
            if episode.sign == "stop":
                stood_for.update(reasons or {})
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
                                         for who in speed_sum if speed_steps[who]},
                      "speed_by_place_mps": {Sign(sign).name: {
                          f"{PROFILE_FROM_M + k * PROFILE_STEP_M:+g}..{PROFILE_FROM_M + (k + 1) * PROFILE_STEP_M:+g} m":
                          round(profile_sum[sign, k] / profile_steps[sign, k], 2)
                          for k in range(bins) if profile_steps[sign, k]} for sign in range(3)},
                      "stop_sign_stood_for_s_per_episode": {reason: round(steps * DT / done, 3)
                                                            for reason, steps in sorted(stood_for.items())}}))


if __name__ == "__main__":
    main()
