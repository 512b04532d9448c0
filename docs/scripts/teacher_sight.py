"""How far the scripted driver must see to drive the hard junction well (docs/imitation.md).

    python docs/scripts/teacher_sight.py [--episodes 500] [--scenario hard]

Runs ``ScriptedDriver`` with sight windows of several sizes and placements: a square of
half-side ``sight_m`` centred ``sight_shift_m`` ahead of the car, inside which it yields to
cars with priority; ``VIEW_SIGHT_M`` (25 m, centred) is what a learner's views show, ``None``
sees everything. Every window drives the same four tests (delay_max 10, 30, 60 and 100 s, seeds
5-8, ``--episodes`` counted episodes each; episodes cut short by a sign change do not count).
Prints one JSON line per window: its reach, crash and time-over fractions.
"""

from __future__ import annotations

import argparse
import collections
import json
import time

from simcore.controller import VIEW_SIGHT_M, ScriptedDriver
from simcore.simulator import SimConfig, Simulator

# (half-side [m], shift ahead [m]); None: the privileged driver that sees everything
WINDOWS = [(VIEW_SIGHT_M, 0.0), (VIEW_SIGHT_M, 15.0), (35.0, 0.0), (35.0, 15.0), (50.0, 0.0), (None, 0.0)]
TESTS = [(5, 10.0), (6, 30.0), (7, 60.0), (8, 100.0)]  # (seed, delay_max [s])


def drive(scenario: str, sight_m: float | None, shift_m: float, episodes: int) -> collections.Counter:
    ends: collections.Counter = collections.Counter()
    for seed, delay_max in TESTS:
        sim = Simulator(scenario, SimConfig(delay_min_s=0.0, delay_max_s=delay_max, observe=False), seed=seed)
        sim.reset()
        driver = ScriptedDriver(sim, sight_m=sight_m, sight_shift_m=shift_m)
        counted = 0
        while counted < episodes:
            for episode in sim.step(driver.act()).episodes:
                if episode.end_reason != "sign_change":
                    counted += 1
                    ends[episode.end_reason] += 1
    return ends


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=500, help="counted episodes per test (4 tests per window)")
    parser.add_argument("--scenario", default="hard")
    args = parser.parse_args()
    for sight_m, shift_m in WINDOWS:
        started = time.monotonic()
        ends = drive(args.scenario, sight_m, shift_m, args.episodes)
        total = sum(ends.values())
        print(json.dumps({"scenario": args.scenario, "sight_m": sight_m, "sight_shift_m": shift_m,
                          "episodes": total, "reach": round(ends["goal"] / total, 3),
                          "crash": round(ends["crash"] / total, 3), "time_over": round(ends["time_over"] / total, 3),
                          "wall_s": round(time.monotonic() - started, 1)}), flush=True)


if __name__ == "__main__":
    main()
