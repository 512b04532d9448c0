"""Where the view-limited scripted driver's at-fault crashes come from (docs/imitation.md).

    python docs/scripts/teacher_crashes.py [--episodes 1500] [--delay-max 30] [--seed 5]

Drives the hard junction with ``ScriptedDriver(sight_m=VIEW_SIGHT_M)`` and, for every car that
runs into a car with priority over it, finds that car (the nearest one at the last step) and
looks back through the last 8 s for the first step it was inside the ego's 50 x 50 m view.
Prints one JSON object: counts, the median impact speed as a fraction of the target speed,
where the priority car first came into view (front edge, side edges) and how long before the
impact.
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from simcore.controller import VIEW_SIGHT_M, ScriptedDriver
from simcore.simulator import SimConfig, Simulator

HISTORY_STEPS = 80  # 8 s of 0.1 s steps
EDGE_BAND_M = 3.0  # "came in at an edge": within this of the view's side [m]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=1500)
    parser.add_argument("--delay-max", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args()
    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max, observe=False), seed=args.seed)
    sim.reset()
    driver = ScriptedDriver(sim, sight_m=VIEW_SIGHT_M)
    history: collections.deque = collections.deque(maxlen=HISTORY_STEPS)
    ends: collections.Counter = collections.Counter()
    impact_fractions, first_seen_s, entered_at = [], [], collections.Counter()
    finished = 0
    while finished < args.episodes:
        state = {k: getattr(sim, k).copy() for k in ("x", "y", "heading", "present")}
        history.append(state)
        result = sim.step(driver.act())
        for episode in result.episodes:
            finished += 1
            ends[episode.end_reason] += 1
            if not (episode.end_reason == "crash" and episode.crashed_into_priority):
                continue
            ego = episode.slot
            impact_fractions.append(episode.final_speed_mps / episode.target_speed_mps)
            distance = np.hypot(state["x"] - state["x"][ego], state["y"] - state["y"][ego])
            distance[ego] = np.inf
            distance[~state["present"]] = np.inf
            other = int(np.argmin(distance))
            for age, past in enumerate(history):
                if not (past["present"][ego] and past["present"][other]):
                    continue
                dx, dy = past["x"][other] - past["x"][ego], past["y"][other] - past["y"][ego]
                c, s = np.cos(past["heading"][ego]), np.sin(past["heading"][ego])
                ahead, left = dx * c + dy * s, dy * c - dx * s
                if abs(ahead) <= VIEW_SIGHT_M and abs(left) <= VIEW_SIGHT_M:
                    first_seen_s.append(0.1 * (len(history) - age))
                    if ahead >= VIEW_SIGHT_M - EDGE_BAND_M:
                        entered_at["front edge"] += 1
                    elif abs(left) >= VIEW_SIGHT_M - EDGE_BAND_M:
                        entered_at["side edge"] += 1
                    else:
                        entered_at["inside (seen 8 s or more before)" if age == 0 else "inside"] += 1
                    break
            else:
                entered_at["never seen"] += 1
    print(json.dumps({
        "episodes": finished, "end_reasons": dict(ends),
        "crashed_into_priority": len(impact_fractions),
        "median_impact_speed_fraction_of_target": round(float(np.median(impact_fractions)), 3),
        "priority_car_first_seen_at": dict(entered_at),
        "first_seen_before_impact_s_quartiles": [round(float(q), 1) for q in np.percentile(first_seen_s, [25, 50, 75])],
    }))


if __name__ == "__main__":
    main()
