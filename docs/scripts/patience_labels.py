"""How rare the hard teacher's "wait, then go" labels are (docs/imitation.md, session 29).

    python docs/scripts/patience_labels.py [--delay-max 30] [--episodes 1500] [--seed 7]

Drives hard with the hard students' teacher and counts, over every car-step, the steps where the
car stands (under ``STANDING_MPS``) for a car with priority in sight within the yield horizon
(``burst_waits.standing_reasons``), those where it has also stood out ``PATIENCE_S``, and those
where it then goes (``ScriptedDriver.patience_released``, the labels ``crossway pretrain
--patience-weight`` counts more). Prints one JSON line.
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from burst_waits import standing_reasons
from evaluation.table1 import OUTCOMES
from script_driver import HARD_TEACHER
from simcore.controller import PATIENCE_S, scripted_driver
from simcore.simulator import SimConfig, Simulator


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--delay-max", type=float, default=30.0, help="[s]")
    parser.add_argument("--episodes", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=False), seed=args.seed)
    sim.reset()
    options = HARD_TEACHER
    teacher = scripted_driver(sim, options)
    entry_lane = np.array([r.entry_lane for r in sim.intersection.routes])
    counts: collections.Counter = collections.Counter()
    done = 0
    while done < args.episodes:
        learners = np.flatnonzero(sim.learners_present).tolist()
        stood_s = teacher._standing_s.copy()  # before this act()
        actions = teacher.act()
        if learners:
            for slot, reason in standing_reasons(sim, learners, entry_lane).items():
                counts["car_steps"] += 1
                counts["released_labels"] += int(teacher.patience_released[slot])
                if "priority" in reason:
                    counts["standing_for_priority"] += 1
                    if stood_s[slot] >= PATIENCE_S - 1e-9:
                        counts["patience_out_priority"] += 1
                        counts["patience_out_priority_goes"] += int(actions[slot, 0] > 0.0)
        result = sim.step(actions)
        done += sum(e.end_reason in OUTCOMES for e in result.episodes)
    print(json.dumps({"scenario": "hard", "episodes": args.episodes, "seed": args.seed, "delay_max_s": args.delay_max,
                      "driver": options.record(), "counts": dict(counts)}))


if __name__ == "__main__":
    main()
