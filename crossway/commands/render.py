"""``crossway render``: watch a scenario without a trained model.

Cars are driven by the scripted driver (pure pursuit along the route, speed keeping, and a
simple rule that stops before a conflict while a car with priority has not cleared it).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render a scenario driven by scripted drivers to a GIF or MP4",
        description=(
            "Simulate a scenario with every car driven by the scripted path-following driver and "
            "write an animation: the junction in the paper's colours (grey roads, red stop lines, "
            "yellow yield lines, green learning cars) with the 50 x 50 m square one agent sees, "
            "and that agent's four 84x84 semantic views (navigable, path, obstacles, sign) beside it."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--scenario", default="hard",
                        help="built-in scenario (easy, medium, hard) or the path of a scenario TOML file")
    parser.add_argument("--steps", type=int, default=300, help="simulation steps to render (100 ms each)")
    parser.add_argument("--out", default="run.gif", help="output file: .gif, or .mp4 (needs ffmpeg)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (routes, signs, speeds, delays)")
    parser.add_argument("--focus", default=None, metavar="LANE",
                        help="entry lane whose agent's views are shown (e.g. south_0); default: the "
                             "first car on the road, switching when it leaves")
    parser.add_argument("--fps", type=int, default=10, help="frames per second of the animation (10 = real time)")
    parser.add_argument("--delay-max", type=float, default=None, metavar="SECONDS",
                        help="longest wait between an agent's episodes [s]; default: the scenario's")
    parser.add_argument("--pixels-per-m", type=float, default=5.0, help="scale of the global view [px/m]")
    parser.set_defaults(func=run)


def run(args) -> int:
    from simcore.controller import ScriptedDriver
    from simcore.render import choose_focus, render_frame, write_animation
    from simcore.simulator import SimConfig, Simulator

    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if not 1 <= args.fps <= 60:
        raise ValueError(f"--fps must be between 1 and 60, got {args.fps}")
    if not args.pixels_per_m > 0:
        raise ValueError(f"--pixels-per-m must be > 0, got {args.pixels_per_m}")
    out = Path(args.out)
    if out.suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"--out must end in .gif or .mp4, got {out.name!r}")
    if not out.parent.is_dir():
        raise ValueError(f"--out: directory {str(out.parent)!r} does not exist")
    config = SimConfig(delay_min_s=0.0 if args.delay_max is not None else None, delay_max_s=args.delay_max)
    sim = Simulator(args.scenario, config, seed=args.seed)
    driver = ScriptedDriver(sim)
    result = sim.reset()
    focus = choose_focus(sim, None, args.focus)
    frames = [render_frame(sim, result, focus, args.pixels_per_m)]
    reasons: Counter[str] = Counter()
    started = time.perf_counter()
    for step in range(1, args.steps):
        result = sim.step(driver.act())
        reasons.update(e.end_reason for e in result.episodes)
        focus = choose_focus(sim, focus, args.focus)
        frames.append(render_frame(sim, result, focus, args.pixels_per_m))
        if step % 25 == 0 or step == args.steps - 1:
            print(f"\rrender: step {step + 1}/{args.steps}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    write_animation(frames, out, fps=args.fps)
    elapsed = time.perf_counter() - started
    summary = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "none ended"
    print(f"wrote {out} ({len(frames)} frames, {len(frames) / args.fps:.1f} s of simulation) in {elapsed:.1f} s")
    print(f"episodes by end reason: {summary}")
    return 0
