"""What the cars of hard's bursts stand for: seconds on the road by reason, per start and outcome.

    python docs/scripts/burst_waits.py [--delay-max 30] [--episodes 3000] [--seed 2] [--snapshots 1]
        [--checkpoint CKPT]

Drives the hard junction (delay_min 0) with the hard students' teacher (the scripted driver
limited to the views, slowing to 2 m/s by its own sign, braking for blockers, waiting outside
zones, breaking cycles) or the trained policy ``--checkpoint``. Every step it files each car's
step under one reason: "moving"; or, standing (under ``STANDING_MPS``), "blocker" (a car in sight
occupies a conflict zone ahead of it), "priority" (a car with priority in sight is within the
teacher's yield horizon of their zone ahead), "blocker+priority", or "other" (following a car on
its lane, nothing in sight). Episodes are sorted as ``crossway evaluate table1`` sorts them:
"burst" if they began within two steps of a sign redraw, "staggered" otherwise. Prints the first
``--snapshots`` roads where a burst car has stood 15 s or more at 37 s on the road, then one JSON
line: episodes per start, sign and outcome, and per start and outcome the mean seconds per reason.
"""

from __future__ import annotations

import argparse
import collections
import json
import math

import numpy as np

from script_driver import HARD_TEACHER, ScriptDriver, add_checkpoint_argument, needs_views
from evaluation.table1 import OUTCOMES, began_in_burst
from simcore.controller import STANDING_MPS, YIELD_HORIZON_S
from simcore.dynamics import DT, VEHICLE_LENGTH
from simcore.scenario import SIGN_CHANGE_RESTARTS
from simcore.simulator import SimConfig, Simulator
from simcore.views import may_show

SNAPSHOT_S = 37.0  # print the road when a burst car has been on it this long [s] ...
SNAPSHOT_STOOD_S = 15.0  # ... and has stood at least this long of it [s]


def standing_for(sim: Simulator, slot: int, idx: np.ndarray, higher: np.ndarray, sight: np.ndarray,
                 entry_lane: np.ndarray) -> list[tuple[str, int]]:
    """The cars the car in ``slot`` may stand for, each as ("blocker" or "priority", its slot) (see
    the module's docstring); ``higher``, ``sight``: [a, b] over the cars ``idx`` (priority, may show
    in a's view), as ``sight_and_priority`` gives them."""
    table, half = sim.priority, 0.5 * VEHICLE_LENGTH
    a, ra = int(np.searchsorted(idx, slot)), sim.route[slot]
    front = sim.s[slot] + half
    found = []
    for b, other in enumerate(idx.tolist()):
        rb = sim.route[other]
        if (other == slot or not sight[a, b] or not table.conflict[ra, rb] or not math.isnan(table.merge_at[ra, rb])
                or entry_lane[ra] == entry_lane[rb] or front > table.zone_start[ra, rb]):
            continue  # a shared lane is car following; a zone behind its front is no reason to stand
        if sim.s[other] + half >= table.zone_start[rb, ra] and sim.s[other] - half <= table.zone_end[rb, ra]:
            found.append(("blocker", other))
        elif higher[a, b] and (table.zone_start[rb, ra] - (sim.s[other] + half)
                               <= YIELD_HORIZON_S * max(sim.speed[other], sim.target_speed[other])):
            found.append(("priority", other))
    return found


def sight_and_priority(sim: Simulator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cars on the road (slots, ascending) and, over them, [a, b]: whether b has priority over a,
    and whether b may show in a's view square."""
    idx = np.flatnonzero(sim.present)
    ego, views = idx[:, None], sim.spec.views
    sight = may_show(sim.x[ego], sim.y[ego], sim.heading[ego], sim.x[idx][None, :], sim.y[idx][None, :],
                     views.extent_m, views.shift_m)
    return idx, sim.priorities(idx), sight


def standing_reasons(sim: Simulator, slots: list[int], entry_lane: np.ndarray) -> dict[int, str]:
    """For each car in ``slots``: "moving", or why it stands ("blocker", "priority", both joined by
    "+", or "other"), judged by what a learner's view square shows."""
    idx, higher, sight = sight_and_priority(sim)
    return {slot: "+".join(sorted({kind for kind, _ in standing_for(sim, slot, idx, higher, sight, entry_lane)}))
            or "other" if sim.speed[slot] < STANDING_MPS else "moving" for slot in slots}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--delay-max", type=float, default=30.0, help="[s]")
    parser.add_argument("--episodes", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--snapshots", type=int, default=1)
    parser.add_argument("--sign-restart", choices=SIGN_CHANGE_RESTARTS, default=None,
                        help="after a redraw: each car waits its random delay, or all start at once (the "
                             "reading of sessions 28-29); default: the scenario's")
    add_checkpoint_argument(parser)
    args = parser.parse_args()

    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=needs_views(args),
                                      sign_change_restart=args.sign_restart), seed=args.seed)
    result = sim.reset()
    options = HARD_TEACHER
    driver = ScriptDriver(sim, options, args.checkpoint)
    junction = sim.intersection
    entry_lane = np.array([r.entry_lane for r in junction.routes])
    started_s = {v: sim.time_s for v in np.flatnonzero(result.started).tolist()}
    seconds: dict[int, collections.Counter] = collections.defaultdict(collections.Counter)  # slot -> reason -> s
    redraws_s: list[float] = []
    totals: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)  # start/outcome -> reason
    episodes: collections.Counter = collections.Counter()
    snapshots = done = 0

    while done < args.episodes:
        learners = np.flatnonzero(sim.learners_present).tolist()
        if learners:
            for slot, reason in standing_reasons(sim, learners, entry_lane).items():
                seconds[slot][reason] += DT
            for slot in learners:
                stood = sum(s for r, s in seconds[slot].items() if r != "moving")
                if (snapshots < args.snapshots and abs(sim.steps[slot] * DT - SNAPSHOT_S) < 0.5 * DT
                        and stood >= SNAPSHOT_STOOD_S and began_in_burst(started_s.get(slot), redraws_s)):
                    snapshots += 1
                    print(f"--- car {slot} began in a burst and has stood {stood:.1f} of {SNAPSHOT_S:g} s:")
                    for v in learners:
                        route = junction.routes[sim.route[v]]
                        print(f"  car {v}: {junction.lanes[route.entry_lane].name} {route.turn}, sign "
                              f"{int(sim.sign[v])}, front {sim.s[v] + 0.5 * VEHICLE_LENGTH - route.junction_entry_s:+.1f}"
                              f" m past its line, {sim.speed[v]:.1f} m/s, on the road {sim.steps[v] * DT:.1f} s, "
                              f"seconds by reason {dict((r, round(s, 1)) for r, s in seconds[v].most_common())}")
        next_redraw_s = sim.next_sign_change_s
        result = sim.step(driver.act(result))
        if sim.next_sign_change_s != next_redraw_s:
            redraws_s.append(next_redraw_s)
        for episode in result.episodes:
            kind = "burst" if began_in_burst(started_s.get(episode.slot), redraws_s) else "staggered"
            started_s.pop(episode.slot, None)
            reasons = seconds.pop(episode.slot, collections.Counter())
            if episode.end_reason not in OUTCOMES:
                continue  # cut short by a sign change
            totals[f"{kind}/{episode.end_reason}"].update(reasons)
            episodes[f"{kind}/{episode.end_reason}"] += 1
            episodes[f"{kind}/{episode.sign}/{episode.end_reason}"] += 1
            done += 1
        for slot in np.flatnonzero(result.started).tolist():
            started_s[slot] = sim.time_s
    mean_s = {group: {r: round(s / episodes[group], 2) for r, s in reasons.most_common()}
              for group, reasons in sorted(totals.items())}
    print(json.dumps({"scenario": "hard", "episodes": args.episodes, "seed": args.seed, "delay_max_s": args.delay_max,
                      "driver": driver.record(), "counts": dict(sorted(episodes.items())),
                      "mean_seconds_by_reason": mean_s}))


if __name__ == "__main__":
    main()
