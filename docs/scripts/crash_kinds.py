"""What the view-limited scripted driver's crashes look like (docs/imitation.md, session 14).

    python docs/scripts/crash_kinds.py [--scenario easy] [--delay-max 10] [--episodes 600] [--seed 11]
        [--approach-speed 1] [--approach-signs own] [--brake-for-blockers] [--wait-outside-zones]
        [--break-wait-cycles] [--patience 4] [--checkpoint CKPT]

Drives the scenario's Table I set-up (delay_min 0) with the scripted driver limited to the views,
or with the trained policy ``--checkpoint`` (Gaussian means, as ``crossway evaluate``), and, for
every pair of cars that crash into each other, records the kind of the pair (same entry lane,
merging, crossing), which one had priority, both speeds at the impact, and whether the car
without priority had entered their conflict zone (its front past the zone's start) while the car
with priority was still outside it: then the car with priority ran into a car already in its way.
For those, at the last step before that entry: the lower car's speed, the gap from its front to the
zone and the acceleration it was commanded, and the car with priority's speed and gap to its zone.
At each time-over it counts the cars standing (under 0.5 m/s) on the road at that step, those
that ran out of time included.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import collections
import json
import math

import numpy as np

from script_driver import ScriptDriver, add_checkpoint_argument, needs_views
from simcore.controller import DriverOptions
from simcore.dynamics import DT, VEHICLE_LENGTH
from simcore.rewards import EndReason
from simcore.simulator import SimConfig, Simulator

HISTORY_STEPS = 150  # 15 s of 0.1 s steps
OUTCOMES = ("goal", "crash", "off_path", "time_over")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="easy")
    parser.add_argument("--delay-max", type=float, default=10.0, help="delay_max of the Table I test [s]")
    parser.add_argument("--episodes", type=int, default=600)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--approach-speed", type=float, default=1.0, help="[m/s]; 0 or less: no approach rule")
    parser.add_argument("--approach-signs", choices=("all", "own"), default="own")
    parser.add_argument("--brake-for-blockers", action="store_true")
    parser.add_argument("--wait-outside-zones", action="store_true")
    parser.add_argument("--break-wait-cycles", action="store_true")
    parser.add_argument("--patience", type=float, default=4.0, help="[s]; inf: never stop yielding")
    add_checkpoint_argument(parser)
    args = parser.parse_args()

    sim = Simulator(args.scenario, SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=needs_views(args)),
                    seed=args.seed)
    result = sim.reset()
    options = DriverOptions(sight="view", approach_speed_mps=args.approach_speed if args.approach_speed > 0 else None,
                            approach_signs=args.approach_signs, brake_for_blockers=args.brake_for_blockers,
                            wait_outside_zones=args.wait_outside_zones, break_wait_cycles=args.break_wait_cycles,
                            patience_s=args.patience)
    driver = ScriptDriver(sim, options, args.checkpoint)
    entry_lane = np.array([r.entry_lane for r in sim.intersection.routes])
    outcomes: collections.Counter = collections.Counter()
    kinds: collections.Counter = collections.Counter()
    crossing_with_priority = 0
    speeds: list[tuple[float, float]] = []  # (car without, car with priority) at impact [m/s]
    lower_first: list[float] = []  # time from the lower car's entry into the zone to the impact [s]
    at_entry: list[dict] = []  # both cars at the last step before the lower car's entry
    # (arc lengths s, speeds, commanded accelerations) of the last steps
    history: collections.deque = collections.deque(maxlen=HISTORY_STEPS)
    half = 0.5 * VEHICLE_LENGTH
    standing_at_time_over: list[int] = []
    done = 0
    while done < args.episodes:
        routes, s, signs = sim.route.copy(), sim.s.copy(), sim.sign.copy()  # before the step
        actions = driver.act(result)
        history.append((s, sim.speed.copy(), actions[:, 0].copy()))
        result = sim.step(actions)
        for episode in result.episodes:
            if episode.end_reason in OUTCOMES:
                outcomes[episode.end_reason] += 1
                done += 1
        # at a time-over: the cars standing (under 0.5 m/s) on the road, those that ran out of time
        # in this step included (they have left the road already)
        stood_out = [e for e in result.episodes if e.end_reason == "time_over"]
        if stood_out:
            standing = int((sim.present & (sim.speed < 0.5)).sum()) + sum(e.final_speed_mps < 0.5 for e in stood_out)
            standing_at_time_over += [standing] * len(stood_out)
        crashed = np.flatnonzero(result.end_reason == EndReason.CRASH)
        for i, a in enumerate(crashed.tolist()):
            for b in crashed[i + 1:].tolist():
                if math.hypot(sim.x[a] - sim.x[b], sim.y[a] - sim.y[b]) > 6.0:
                    continue  # two crashes elsewhere in the same step
                ra, rb = routes[a], routes[b]
                if entry_lane[ra] == entry_lane[rb]:
                    kinds["same entry lane"] += 1
                    continue
                if not math.isnan(sim.priority.merge_at[ra, rb]):
                    kinds["merging"] += 1
                    continue
                kinds["crossing"] += 1
                pair = np.array([a, b])
                higher = sim.priority.higher(routes[pair], s[pair], signs[pair])
                if higher[0, 1] or higher[1, 0]:
                    crossing_with_priority += 1
                    lower, upper = (a, b) if higher[0, 1] else (b, a)
                    speeds.append((float(sim.speed[lower]), float(sim.speed[upper])))
                    # where was the car with priority when the other one's front entered their zone?
                    zone_lower = sim.priority.zone_start[routes[lower], routes[upper]]
                    zone_upper = sim.priority.zone_start[routes[upper], routes[lower]]
                    for back, (past, speed, acceleration) in enumerate(reversed(history)):
                        if past[lower] + half < zone_lower:  # the step before it entered
                            if back > 0 and past[upper] + half < zone_upper:
                                lower_first.append(back * DT)
                                at_entry.append({
                                    "lower_speed_mps": round(float(speed[lower]), 1),
                                    "lower_gap_m": round(float(zone_lower - past[lower] - half), 2),
                                    "lower_acceleration_mps2": round(float(acceleration[lower]), 2),
                                    "upper_speed_mps": round(float(speed[upper]), 1),
                                    "upper_gap_m": round(float(zone_upper - past[upper] - half), 1)})
                            break
    print(json.dumps({"scenario": args.scenario, "delay_max_s": args.delay_max, "episodes": done,
                      "seed": args.seed, "driver": driver.record(), "outcomes": dict(outcomes),
                      "crash_pairs": dict(kinds), "crossing_pairs_with_a_priority": crossing_with_priority,
                      "lower_car_entered_the_zone_first": len(lower_first),
                      "seconds_from_that_entry_to_impact": sorted(round(x, 1) for x in lower_first),
                      "at_that_entry": at_entry,
                      "impact_speeds_mps_lower_upper": [(round(a, 1), round(b, 1)) for a, b in speeds],
                      "cars_standing_at_each_time_over": sorted(standing_at_time_over)}))


if __name__ == "__main__":
    main()
