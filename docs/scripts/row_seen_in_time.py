"""Which of the view-limited scripted driver's infractions it could have seen (docs/RESULTS.md).

    python docs/scripts/row_seen_in_time.py [--scenario easy] [--episodes 300] [--seed 0]

Drives the right-of-way test (Table II: every lane starts at once, equal speeds) with
``ScriptedDriver`` limited to the learners' views, finds every infraction
(``evaluation.right_of_way.find_infractions``) and sorts it as ``crossway evaluate right-of-way``
does (``seen_in_time``: some of the wronged car could show in the offender's view while the
offender could still stop at 3 m/s^2). It also counts, among those seen in time, the ones whose
wronged car had its *centre* in the view while the offender could still stop: up to session 11
the driver reacted only to centres, and this told its own misjudgements (centre seen) from cars
it ignored although part of them showed. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json

from evaluation.right_of_way import drive_episode, synchronised_config
from simcore.controller import ScriptedDriver, view_sight
from simcore.dynamics import VEHICLE_LENGTH
from simcore.simulator import Simulator


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="easy")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    sim = Simulator(args.scenario, synchronised_config(observe=False), seed=args.seed)
    counts = {"infractions": 0, "seen_in_time": 0, "seen_in_time_by_centre": 0}
    for _ in range(args.episodes):
        result = sim.reset()
        driver = ScriptedDriver(sim, **view_sight(sim))
        episode = drive_episode(sim, lambda _: driver.act(), result)
        for found in episode.infractions():
            counts["infractions"] += 1
            if episode.seen_in_time(found):
                counts["seen_in_time"] += 1
                # the driver's old criterion: the centre inside the square (shrink the grown square back)
                centre_extent_m = sim.spec.views.extent_m - VEHICLE_LENGTH
                counts["seen_in_time_by_centre"] += episode.seen_in_time(found, centre_extent_m)
    print(json.dumps({"scenario": sim.spec.name, "episodes": args.episodes, "seed": args.seed, **counts}))


if __name__ == "__main__":
    main()
