"""Who waits for whom on the road when a car has driven 35 s (docs/imitation.md, session 15).

    python docs/scripts/waiting_cars.py [--scenario hard] [--episodes 60] [--seed 5] [--delay-max 30]
        [--wait-outside-zones] [--break-wait-cycles] [--snapshots 3] [--checkpoint CKPT]

Drives the scenario (delay_min 0) with the scripted driver limited to the views, slowing to 2 m/s
before zones judged by its own sign and braking for blockers, plus the options given; or with the
trained policy ``--checkpoint`` (Gaussian means, as ``crossway evaluate``). The first
``--snapshots`` times a car reaches 35 s on the road (of the 40 s limit), it prints every car:
entry lane, turn, sign (0 none, 1 yield, 2 stop), how far its front is past the sign line, its
speed, how long it has stood, the cars in sight that occupy a conflict zone ahead of it
("blocked by"), and the cars whose zone with it its body is in now ("inside the zone of").
Ends with one JSON line of the episodes' outcomes.
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
from simcore.simulator import SimConfig, Simulator

SNAPSHOT_S = 35.0  # print the road when a car has been on it this long [s]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--delay-max", type=float, default=30.0, help="[s]")
    parser.add_argument("--wait-outside-zones", action="store_true")
    parser.add_argument("--break-wait-cycles", action="store_true")
    parser.add_argument("--snapshots", type=int, default=3)
    add_checkpoint_argument(parser)
    args = parser.parse_args()

    sim = Simulator(args.scenario, SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=needs_views(args)),
                    seed=args.seed)
    result = sim.reset()
    options = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                            wait_outside_zones=args.wait_outside_zones, break_wait_cycles=args.break_wait_cycles)
    driver = ScriptDriver(sim, options, args.checkpoint)
    table, junction = sim.priority, sim.intersection
    entry_lane = np.array([r.entry_lane for r in junction.routes])
    half = 0.5 * VEHICLE_LENGTH
    outcomes: collections.Counter = collections.Counter()
    snapshots = 0
    snapshot_step = round(SNAPSHOT_S / DT)
    while sum(outcomes.values()) < args.episodes:
        result = sim.step(driver.act(result))
        for episode in result.episodes:
            if episode.end_reason in ("goal", "crash", "off_path", "time_over"):
                outcomes[episode.end_reason] += 1
        learners = sim.learners_present
        if snapshots >= args.snapshots or not np.any(learners & (sim.steps[: sim.num_slots] == snapshot_step)):
            continue
        snapshots += 1
        print(f"--- a car has been on the road {SNAPSHOT_S:g} s:")
        cars = np.flatnonzero(sim.present).tolist()
        for a in cars:
            ra = sim.route[a]
            route = junction.routes[ra]
            blocked_by, inside_zone_of = [], []
            for b in cars:
                rb = sim.route[b]
                if (b == a or not table.conflict[ra, rb] or not math.isnan(table.merge_at[ra, rb])
                        or entry_lane[ra] == entry_lane[rb]):
                    continue
                b_occupies = sim.s[b] + half >= table.zone_start[rb, ra] and sim.s[b] - half <= table.zone_end[rb, ra]
                if b_occupies and sim.s[a] + half <= table.zone_start[ra, rb]:
                    blocked_by.append(b)
                if sim.s[a] + half >= table.zone_start[ra, rb] and sim.s[a] - half <= table.zone_end[ra, rb]:
                    inside_zone_of.append(b)
            standing = driver.standing_s(a)
            print(f"  car {a}: {junction.lanes[route.entry_lane].name} {route.turn}, sign {int(sim.sign[a])}, "
                  f"front {sim.s[a] + half - route.junction_entry_s:+.1f} m past its line, {sim.speed[a]:.1f} m/s, "
                  f"stood {standing:.1f} s, blocked by {blocked_by}, inside the zone of {inside_zone_of}")
    print(json.dumps({"scenario": args.scenario, "episodes": args.episodes, "seed": args.seed,
                      "delay_max_s": args.delay_max, "driver": driver.record(), "outcomes": dict(outcomes)}))


if __name__ == "__main__":
    main()
