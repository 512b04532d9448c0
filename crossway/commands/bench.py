"""``crossway bench``: speed benchmarks that print one JSON object.

``crossway bench sim`` measures the simulator alone: agent-steps per second, rendering every
agent's semantic views included, with every entry lane kept busy (no wait between episodes),
cars driven by the scripted driver (its time is measured apart and not counted), pinned to one
CPU core.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import time
from collections import Counter

import numpy as np


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench",
        help="speed benchmarks (print JSON)",
        description="Speed benchmarks. Each prints one JSON object on stdout; progress goes to stderr.",
    )
    benches = parser.add_subparsers(dest="bench", metavar="BENCH", required=True)
    sim = benches.add_parser(
        "sim",
        help="simulator agent-steps per second, views included",
        description=(
            "Step the simulator with every entry lane busy (an agent restarts one step after its "
            "episode ends) and the scripted driver at the wheel; count agent-steps per second of "
            "Simulator.step, which renders all four 84x84 views of every agent. The driver's time "
            "is reported apart. Runs pinned to one CPU core unless --no-pin."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    sim.add_argument("--scenario", default="hard", help="built-in scenario (easy, medium, hard) or a TOML path")
    sim.add_argument("--seconds", type=float, default=10.0, help="wall-clock time to measure [s]")
    sim.add_argument("--seed", type=int, default=0, help="random seed")
    sim.add_argument("--no-views", action="store_true", help="skip rendering (measures physics and rules only)")
    sim.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    sim.add_argument("--json", action="store_true",
                     help="print only the JSON object (default also prints it; the flag silences progress)")
    sim.set_defaults(func=run_sim)


def pin_to_one_core() -> int | None:
    """Pin this process to the first CPU it may use; returns that CPU or None if unsupported."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return cpu


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux reports KiB


def run_sim(args) -> int:
    from simcore.controller import ScriptedDriver
    from simcore.simulator import SimConfig, Simulator

    if not args.seconds > 0:
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")
    cpu = None if args.no_pin else pin_to_one_core()
    config = SimConfig(delay_min_s=0.0, delay_max_s=0.0, observe=not args.no_views)
    sim = Simulator(args.scenario, config, seed=args.seed)
    driver = ScriptedDriver(sim)
    sim.reset()
    for _ in range(20):  # warm-up
        sim.step(driver.act())
    step_seconds = driver_seconds = 0.0
    agent_steps = steps = 0
    reasons: Counter[str] = Counter()
    started = time.perf_counter()
    next_report = started + 2.0
    while True:
        t0 = time.perf_counter()
        actions = driver.act()
        t1 = time.perf_counter()
        result = sim.step(actions)
        t2 = time.perf_counter()
        driver_seconds += t1 - t0
        step_seconds += t2 - t1
        agent_steps += int(result.acted.sum())
        steps += 1
        reasons.update(e.end_reason for e in result.episodes)
        if t2 - started >= args.seconds:
            break
        if not args.json and t2 >= next_report:
            print(f"bench sim: {t2 - started:4.1f}s {agent_steps / step_seconds:8.0f} agent-steps/s",
                  file=sys.stderr)
            next_report = t2 + 2.0
    report = {
        "bench": "sim",
        "scenario": sim.spec.name,
        "agents": round(agent_steps / steps, 3),  # mean cars on the road per step
        "lanes": sim.num_slots,
        "agent_steps_per_s": round(agent_steps / step_seconds, 1),
        "steps_per_s": round(steps / step_seconds, 1),
        "views": not args.no_views,
        "measured_s": round(step_seconds, 3),
        "driver_s": round(driver_seconds, 3),
        "steps": steps,
        "agent_steps": agent_steps,
        "episodes": dict(sorted(reasons.items())),
        "cpu_pinned": cpu,
        "peak_rss_bytes": peak_rss_bytes(),
        "python": platform.python_version(),
        "numpy": np.__version__,
    }
    print(json.dumps(report))
    return 0
