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

import numpy as np

from evaluation.right_of_way import Pose, find_infractions, seen_in_time
from simcore.controller import ScriptedDriver, view_sight
from simcore.dynamics import DT, VEHICLE_LENGTH
from simcore.simulator import SimConfig, Simulator


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="easy")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    config = SimConfig(start_all_at_reset=True, delay_min_s=1e9, delay_max_s=1e9, sign_change_interval_s=0.0,
                       equal_speeds=True, observe=False)
    sim = Simulator(args.scenario, config, seed=args.seed)
    limit = int(sim.time_limit_s / DT) + 2
    extent, shift = sim.spec.views.extent_m, sim.spec.views.shift_m
    counts = {"infractions": 0, "seen_in_time": 0, "seen_in_time_by_centre": 0}
    for _ in range(args.episodes):
        sim.reset()
        driver = ScriptedDriver(sim, **view_sight(sim))
        n = sim.num_slots
        routes, signs = sim.route[:n].copy(), sim.sign[:n].copy()
        tracks = np.full((5, n, limit), np.nan)
        tracks[:, :, 0] = sim.x[:n], sim.y[:n], sim.heading[:n], sim.s[:n], sim.speed[:n]
        step = 0
        while sim.learners_present.any() and step + 1 < limit:
            result = sim.step(driver.act())
            step += 1
            for row, values in enumerate((sim.x, sim.y, sim.heading, sim.s, sim.speed)):
                tracks[row, result.acted, step] = values[:n][result.acted]
        tracks = tracks[:, :, : step + 1]
        for found in find_infractions(sim.priority, routes, signs, tracks[3]):
            offender, wronged = Pose(*tracks[:, found.offender]), Pose(*tracks[:, found.wronged])
            zone = sim.priority.zone_start[routes[found.offender], routes[found.wronged]]
            counts["infractions"] += 1
            if seen_in_time(offender, wronged, zone, found.offender_entry_step, extent, shift):
                counts["seen_in_time"] += 1
                # the driver's own criterion: the centre inside the square (shrink the grown square back)
                counts["seen_in_time_by_centre"] += seen_in_time(offender, wronged, zone, found.offender_entry_step,
                                                                 extent - VEHICLE_LENGTH, shift)
    print(json.dumps({"scenario": sim.spec.name, "episodes": args.episodes, "seed": args.seed, **counts}))


if __name__ == "__main__":
    main()
