"""How hard's Table I outcomes split between episodes started together at a sign redraw and the rest.

    python docs/scripts/burst_starts.py [--scenario hard] [--delays 10 20 ... 100] [--episodes 300]
        [--seed 0] [--workers 2] [--sign-change-interval 120] [--checkpoint CKPT]
        [--approach-speed 2 --approach-signs own --brake-for-blockers --wait-outside-zones --break-wait-cycles]
        [--patience 4] [--blocker-patience 8]

The hard junction redraws its signs every ``episodes.sign_change_interval_s`` (120 s) and every
lane starts a new episode at the next step (paper, "Environment"; docs/simulator.md), so part of
each Table I test is synchronised starts, as in the right-of-way test. This drives the Table I
set-up (delay_min 0, the same seeds as ``crossway evaluate table1 --episodes N --seed S`` for a
test of at most 500 episodes) with the view-limited scripted driver (the hard students' teacher by
default) or a trained policy, and counts the outcomes per sign of the episodes that began within
two steps of a redraw ("burst") and of the others ("staggered"). ``--sign-change-interval``
overrides the scenario's interval (a what-if: 0 never redraws). Prints one JSON object on one line.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from collections import Counter, defaultdict

from script_driver import ScriptDriver, add_checkpoint_argument, needs_views
from simcore.controller import BLOCKER_PATIENCE_S, PATIENCE_S, DriverOptions
from simcore.dynamics import DT
from simcore.simulator import SimConfig, Simulator

OUTCOMES = ("goal", "crash", "off_path", "time_over")
BURST_WINDOW_S = 2 * DT  # an episode that starts this soon after a redraw belongs to its burst [s]


def run_test(job: tuple) -> dict:
    import torch

    torch.set_num_threads(1)
    args, delay_max, seed = job
    config = SimConfig(delay_min_s=0.0, delay_max_s=delay_max, observe=needs_views(args),
                       sign_change_interval_s=args.sign_change_interval)
    sim = Simulator(args.scenario, config, seed=seed)
    result = sim.reset()
    driver = ScriptDriver(sim, driver_options(args), args.checkpoint)
    started_s = {v: sim.time_s for v in result.started.nonzero()[0].tolist()}  # slot -> when its episode began [s]
    redraws_s: list[float] = []  # when the signs were redrawn [s]
    next_change = sim.next_sign_change_s
    counts: dict[str, dict[str, Counter]] = {"burst": defaultdict(Counter), "staggered": defaultdict(Counter)}
    done = 0
    while done < args.episodes:
        result = sim.step(driver.act(result))
        if sim.next_sign_change_s != next_change:  # redrawn during this step
            redraws_s.append(next_change)  # the time it was due, also when the road stood empty
            next_change = sim.next_sign_change_s
        for episode in result.episodes:
            start = started_s.pop(episode.slot, None)
            if episode.end_reason not in OUTCOMES or done >= args.episodes:
                continue  # cut short by a sign change: not an outcome (as crossway evaluate table1)
            burst = start is not None and any(0.0 < start - r <= BURST_WINDOW_S + 1e-9 for r in redraws_s[-2:])
            counts["burst" if burst else "staggered"][episode.sign][episode.end_reason] += 1
            done += 1
        for v in result.started.nonzero()[0].tolist():
            started_s[v] = sim.time_s
    return {"delay_max_s": delay_max, "counts": {k: {s: dict(c) for s, c in v.items()} for k, v in counts.items()}}


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
    parser.add_argument("--approach-speed", type=float, default=2.0, help="[m/s]; 0 or less: no approach rule")
    parser.add_argument("--approach-signs", choices=("all", "own"), default="own")
    parser.add_argument("--brake-for-blockers", action="store_true")
    parser.add_argument("--wait-outside-zones", action="store_true")
    parser.add_argument("--break-wait-cycles", action="store_true")
    parser.add_argument("--patience", type=float, default=PATIENCE_S, help="[s]; inf: never stop yielding")
    parser.add_argument("--blocker-patience", type=float, default=BLOCKER_PATIENCE_S,
                        help="[s]; inf: never stop braking for cars in the way")
    add_checkpoint_argument(parser)
    args = parser.parse_args()
    if args.episodes > 500:
        parser.error("--episodes: at most 500 (Table I's chunk), so the seeds match crossway evaluate table1")
    interval = args.sign_change_interval
    if interval is None:
        from simcore.scenario import load_scenario

        interval = load_scenario(args.scenario).episodes.sign_change_interval_s
    jobs = [(args, d, args.seed + i) for i, d in enumerate(args.delays)]
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        tests = pool.map(run_test, jobs)
    total: dict[str, dict[str, Counter]] = {"burst": defaultdict(Counter), "staggered": defaultdict(Counter)}
    for test in tests:
        for kind, by_sign in test["counts"].items():
            for sign, c in by_sign.items():
                total[kind][sign].update(c)
    summary = {}
    for kind, by_sign in total.items():
        for sign in ("none", "yield", "stop"):
            c = by_sign.get(sign, Counter())
            n = sum(c.values())
            summary[f"{kind}/{sign}"] = {"episodes": n, **{o: round(c[o] / n, 4) if n else None for o in OUTCOMES}}
        n = sum(sum(c.values()) for c in by_sign.values())
        summary[f"{kind}/all"] = {"episodes": n, "goal": round(sum(c["goal"] for c in by_sign.values()) / n, 4)
                                  if n else None}
    per_test = []
    for test in tests:
        row = {"delay_max_s": test["delay_max_s"]}
        for kind, by_sign in test["counts"].items():
            n = sum(sum(c.values()) for c in by_sign.values())
            row[kind] = {"episodes": n, "goal": round(sum(c.get("goal", 0) for c in by_sign.values()) / n, 4)
                         if n else None}
        per_test.append(row)
    counts = {kind: {sign: dict(c) for sign, c in by_sign.items()} for kind, by_sign in total.items()}
    print(json.dumps({"driver": driver_record(args), "scenario": args.scenario, "sign_change_interval_s": interval,
                      "episodes_per_test": args.episodes, "seed": args.seed, "summary": summary,
                      "per_test": per_test, "counts": counts}))


if __name__ == "__main__":
    main()
