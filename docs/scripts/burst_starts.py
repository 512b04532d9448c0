"""How hard's Table I outcomes split between episodes started together at a sign redraw and the rest.

    python docs/scripts/burst_starts.py [--scenario hard] [--delays 10 20 ... 100] [--episodes 300]
        [--seed 0] [--workers 2] [--sign-change-interval 120] [--sign-restart together] [--checkpoint CKPT]
        [--approach-speed 2 --approach-signs own --brake-for-blockers --wait-outside-zones --break-wait-cycles]
        [--patience 4] [--blocker-patience 8]

The hard junction redraws its signs every ``episodes.sign_change_interval_s`` (120 s). With
``--sign-restart together`` (crossway's reading until session 30) every lane then starts a new
episode at the next step, so part of each Table I test is synchronised starts, as in the
right-of-way test; by default each lane waits its random delay (docs/simulator.md). This drives the Table I
set-up (delay_min 0, the same seeds as ``crossway evaluate table1 --episodes N --seed S`` for a
test of at most 500 episodes) with the view-limited scripted driver (the hard students' teacher by
default) or a trained policy, and counts the outcomes per sign of the episodes that began within
two steps of a redraw ("burst"), of every lane's first, begun at the reset ("reset"), and of the
others ("staggered"), as ``crossway evaluate table1`` does (its "By how the episodes began" table)
with ``evaluation.table1.run_test``. ``--sign-change-interval``
overrides the scenario's interval (a what-if: 0 never redraws). Prints one JSON object on one line.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from dataclasses import replace

from evaluation.table1 import SIGNS, STARTS, TestSpec, add_counts, by_start, run_test
from simcore.controller import BLOCKER_PATIENCE_S, PATIENCE_S, DriverOptions
from simcore.scenario import SIGN_CHANGE_RESTARTS, load_scenario


def driver_options(args: argparse.Namespace) -> DriverOptions:
    return DriverOptions(sight="view", approach_speed_mps=args.approach_speed if args.approach_speed > 0 else None,
                         approach_signs=args.approach_signs, brake_for_blockers=args.brake_for_blockers,
                         wait_outside_zones=args.wait_outside_zones, break_wait_cycles=args.break_wait_cycles,
                         patience_s=args.patience, blocker_patience_s=args.blocker_patience)


def driver_record(args: argparse.Namespace) -> dict:
    """What drove: the checkpoint, or the scripted driver's options."""
    return {"checkpoint": args.checkpoint} if args.checkpoint is not None else driver_options(args).record()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--delays", type=float, nargs="+", default=[10.0 * (i + 1) for i in range(10)],
                        help="delay_max of each test [s]")
    parser.add_argument("--episodes", type=int, default=300, help="episodes per test (at most 500: one chunk)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--sign-change-interval", type=float, default=None,
                        help="[s]; default: the scenario's; 0: signs never change")
    parser.add_argument("--sign-restart", choices=SIGN_CHANGE_RESTARTS, default=None,
                        help="after a redraw: each car waits its random delay, or all start at once (the "
                             "reading of sessions 28-29); default: the scenario's")
    parser.add_argument("--approach-speed", type=float, default=2.0, help="[m/s]; 0 or less: no approach rule")
    parser.add_argument("--approach-signs", choices=("all", "own"), default="own")
    parser.add_argument("--brake-for-blockers", action="store_true")
    parser.add_argument("--wait-outside-zones", action="store_true")
    parser.add_argument("--break-wait-cycles", action="store_true")
    parser.add_argument("--patience", type=float, default=PATIENCE_S, help="[s]; inf: never stop yielding")
    parser.add_argument("--blocker-patience", type=float, default=BLOCKER_PATIENCE_S,
                        help="[s]; inf: never stop braking for cars in the way")
    parser.add_argument("--checkpoint", default=None,
                        help="drive with this trained policy instead of the scripted driver (whose options are "
                             "then ignored)")
    args = parser.parse_args()
    if args.episodes > 500:
        parser.error("--episodes: at most 500 (Table I's chunk), so the seeds match crossway evaluate table1")
    spec = load_scenario(args.scenario)
    if args.sign_change_interval is not None:
        spec = replace(spec, episodes=replace(spec.episodes, sign_change_interval_s=args.sign_change_interval))
    if args.sign_restart is not None:
        spec = replace(spec, episodes=replace(spec.episodes, sign_change_restart=args.sign_restart))
    jobs = [TestSpec(spec, d, args.episodes, args.seed + i, args.checkpoint, driver_options(args))
            for i, d in enumerate(args.delays)]
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        tests = pool.map(run_test, jobs)
    table = by_start(tests)
    summary = {f"{kind}/{sign}": {k: round(v, 4) for k, v in table.get(kind, {}).get(sign, {"episodes": 0}).items()}
               for kind in STARTS for sign in (*SIGNS, "all")}
    per_test = [{"delay_max_s": t["delay_max_s"], **{kind: by_start([t]).get(kind, {}).get("all", {"episodes": 0})
                                                     for kind in STARTS}} for t in tests]
    counts: dict[str, dict] = {kind: {} for kind in STARTS}
    for test in tests:
        for kind, by_sign in test["counts_by_start"].items():
            add_counts(counts[kind], by_sign)
    print(json.dumps({"driver": driver_record(args), "scenario": spec.name,
                      "sign_change_interval_s": spec.episodes.sign_change_interval_s,
                      "sign_change_restart": spec.episodes.sign_change_restart,
                      "episodes_per_test": args.episodes, "seed": args.seed, "summary": summary,
                      "per_test": per_test, "counts": counts}))


if __name__ == "__main__":
    main()
