"""What the students' teacher would do where a policy's stop-sign cars stand (session 32).

    python docs/scripts/stand_labels.py [--checkpoint CKPT] [--stop-episodes 300] [--delay-max 10] [--seed 2]

Drives the hard junction (delay_min 0) with the trained policy ``--checkpoint`` (Gaussian means, as
``crossway evaluate``), or with the teacher itself when none is given, and at every step asks the
hard students' teacher (the scripted driver limited to the views, slowing to 2 m/s by its own sign,
braking for blockers, waiting outside zones, breaking cycles, patience 4 s) what it would do. For
every stop-sign car standing (under ``STANDING_MPS``) it files the step by whether the teacher would
go (acceleration > 0), whether the driving policy goes, and whether the teacher goes only because
its patience ran out (``ScriptedDriver.patience_released``); by the car's place (before its line or
past it) and ``burst_waits.py``'s reason for standing. Stops after ``--stop-episodes`` stop-sign
episodes ended in the goal, a crash or a time-over, and prints one JSON line (counts per outcome).
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from burst_waits import standing_reasons
from script_driver import HARD_TEACHER, ScriptDriver, add_checkpoint_argument, needs_views
from simcore.controller import STANDING_MPS, scripted_driver
from simcore.dynamics import VEHICLE_LENGTH
from simcore.rightofway import Sign
from simcore.simulator import SimConfig, Simulator



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stop-episodes", type=int, default=300)
    parser.add_argument("--delay-max", type=float, default=10.0, help="[s]")
    parser.add_argument("--seed", type=int, default=2)
    add_checkpoint_argument(parser)
    args = parser.parse_args()

    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=needs_views(args)),
                    seed=args.seed)
    result = sim.reset()
    teacher = scripted_driver(sim, HARD_TEACHER)  # asked every step (it keeps its own standing clocks)
    policy = ScriptDriver(sim, HARD_TEACHER, args.checkpoint) if args.checkpoint is not None else None
    entry_lane = np.array([r.entry_lane for r in sim.intersection.routes])
    line_s = np.array([r.junction_entry_s for r in sim.intersection.routes])
    stands: dict[int, list] = collections.defaultdict(list)  # slot -> (place, reason, teacher go, policy go, released)
    tally: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    done = 0
    while done < args.stop_episodes:
        teacher_actions = teacher.act()
        released = teacher.patience_released.copy()
        actions = teacher_actions if policy is None else policy.act(result)
        standing = np.flatnonzero(sim.learners_present & (sim.speed[: sim.num_slots] < STANDING_MPS)
                                  & (sim.sign[: sim.num_slots] == Sign.STOP)).tolist()
        for slot, reason in (standing_reasons(sim, standing, entry_lane).items() if standing else ()):
            front_past_line_m = sim.s[slot] + 0.5 * VEHICLE_LENGTH - line_s[sim.route[slot]]
            stands[slot].append(("before_line" if front_past_line_m < 0.5 else "past_line", reason,
                                 teacher_actions[slot, 0] > 0, actions[slot, 0] > 0, bool(released[slot])))
        result = sim.step(actions)
        for episode in result.episodes:
            rows = stands.pop(episode.slot, [])
            if episode.sign != "stop" or episode.end_reason not in ("goal", "crash", "time_over"):
                continue
            done += 1
            counts = tally[episode.end_reason]
            counts["episodes"] += 1
            for place, reason, teacher_goes, policy_goes, after_patience in rows:
                for key in ("all", place, f"{place}/{reason}"):
                    counts[f"{key}/standing_steps"] += 1
                    counts[f"{key}/teacher_goes"] += teacher_goes
                    counts[f"{key}/policy_goes"] += policy_goes
                    counts[f"{key}/teacher_goes_policy_holds"] += teacher_goes and not policy_goes
                    counts[f"{key}/teacher_goes_after_its_patience"] += after_patience
    print(json.dumps({"driver": args.checkpoint or "the teacher", "delay_max_s": args.delay_max, "seed": args.seed,
                      "stop_episodes": done, "by_outcome": {outcome: {k: int(v) for k, v in sorted(counts.items())}
                                                            for outcome, counts in sorted(tally.items())}}))


if __name__ == "__main__":
    main()
