"""``crossway render``: watch a scenario without a trained model.

Every car is driven by ``simcore.controller.ScriptedDriver`` (pure pursuit along its route,
speed keeping, and a simple rule that stops before a conflict while a car with priority has not
cleared it). The animation shows the global view in the paper's colours and one agent's four
semantic views (``simcore.render``).
"""

from __future__ import annotations

import argparse
import math
import sys
import textwrap
import time
from collections import Counter

EXAMPLES = """\
examples:
  crossway render --scenario hard --steps 300 --out run.gif
  crossway render --scenario medium --steps 600 --delay-max 10 --focus south_0 --out south.mp4
  crossway render --scenario my_junction.toml --steps 200 --pixels-per-m 4 --out small.gif
  crossway render --scenario easy --checkpoint runs/easy/checkpoints/ckpt-000009000.pt --out trained.gif
"""


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="animate a scenario driven by scripted drivers (GIF or MP4)",
        description=textwrap.fill(
            "Simulate a scenario with every car driven by the scripted path-following driver "
            "(no trained model needed) or, with --checkpoint, by a trained policy, and write an "
            "animation. Left: the whole junction in the "
            "paper's colours: grey roads, red stop lines, yellow yield lines, green learning cars, "
            "the focus agent's route (faint green) and the 50 x 50 m square it perceives (green "
            "outline). Right: that agent's four 84x84 semantic views (navigable, path, obstacles, "
            "sign; newest frame) as the network receives them, the simulated time and the "
            "episodes ended so far by end reason. One frame per simulation step of 100 ms.",
            width=78,
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--scenario", default="hard", metavar="NAME_OR_TOML",
        help="built-in scenario (easy, medium, hard) or the path of a scenario TOML file "
             "(default: hard)")
    parser.add_argument(
        "--steps", type=int, default=300, metavar="N",
        help="simulation steps to render, one frame each; a step is 100 ms of simulated time, so "
             "300 steps are 30 s (default: 300)")
    parser.add_argument(
        "--out", default="run.gif", metavar="FILE",
        help="output file: .gif (Pillow), or .mp4 (needs ffmpeg on PATH); its directory must "
             "exist (default: run.gif)")
    parser.add_argument(
        "--seed", type=int, default=0,
        help="random seed for routes, signs, speeds and start delays; the same seed gives the "
             "same animation (default: 0)")
    parser.add_argument(
        "--focus", default=None, metavar="LANE",
        help="entry lane whose agent is followed (view square, route, views), e.g. south_0; "
             "lanes are named <arm>_<k>, k = 0 next to the centre line (default: the "
             "lowest-numbered car on the road, switching to another when it leaves)")
    parser.add_argument(
        "--fps", type=int, default=10,
        help="frames per second of the animation, 1 to 60; 10 plays in real time "
             "(default: 10)")
    parser.add_argument(
        "--delay-max", type=float, default=None, metavar="SECONDS",
        help="longest random wait of a lane between two of its episodes [s]; the shortest "
             "becomes 0. Lower means denser traffic, e.g. 10 (default: the scenario's: easy "
             "30, medium 50, hard 100)")
    parser.add_argument(
        "--pixels-per-m", type=float, default=6.0, metavar="PX",
        help="scale of the junction view [pixels per metre], 0.5 to 20; the hard junction is "
             "136 m across, so 6 gives an 816 px square (plus the views panel). A GIF holds "
             "about one byte per pixel per frame in memory until it is written (default: 6)")
    parser.add_argument(
        "--checkpoint", default=None, metavar="CKPT",
        help="drive every car with this trained policy (a learner checkpoint or an exported "
             "policy) instead of the scripted driver; cars take the Gaussian mean (default: "
             "scripted driver)")
    parser.set_defaults(func=run)


def _progress(step: int, steps: int) -> None:
    end = "" if sys.stderr.isatty() else "\n"
    start = "\r" if sys.stderr.isatty() else ""
    print(f"{start}render: step {step}/{steps}", end=end, file=sys.stderr, flush=True)


def run(args) -> int:
    from simcore.controller import ScriptedDriver
    from simcore.dynamics import DT
    from simcore.render import check_animation_path, choose_focus, render_frame, write_animation
    from simcore.simulator import SimConfig, Simulator

    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if not 1 <= args.fps <= 60:
        raise ValueError(f"--fps must be between 1 and 60, got {args.fps}")
    if not (math.isfinite(args.pixels_per_m) and 0.5 <= args.pixels_per_m <= 20.0):
        raise ValueError(f"--pixels-per-m must be between 0.5 and 20, got {args.pixels_per_m}")
    if args.delay_max is not None and not (math.isfinite(args.delay_max) and args.delay_max >= 0.0):
        raise ValueError(f"--delay-max must be a number of seconds >= 0, got {args.delay_max}")
    try:
        out = check_animation_path(args.out)
    except ValueError as error:
        raise ValueError(f"--out: {error}") from None

    started = time.perf_counter()
    config = SimConfig(delay_min_s=None if args.delay_max is None else 0.0, delay_max_s=args.delay_max)
    sim = Simulator(args.scenario, config, seed=args.seed)
    focus = choose_focus(sim, None, args.focus)  # refuses a bad --focus before simulating
    if args.checkpoint is not None:
        from evaluation.policy import PolicyDriver, check_checkpoint, load_policy

        check_checkpoint(args.checkpoint, sim.spec)  # refuses a bad checkpoint now
        policy = PolicyDriver(sim, load_policy(args.checkpoint))
    else:
        scripted = ScriptedDriver(sim)
    reasons: Counter[str] = Counter()

    def frames():
        nonlocal focus
        result = sim.reset()
        for step in range(1, args.steps + 1):
            result = sim.step(policy.act(result) if args.checkpoint is not None else scripted.act())
            reasons.update(e.end_reason for e in result.episodes)
            focus = choose_focus(sim, focus, args.focus)
            yield render_frame(sim, result, focus, args.pixels_per_m, episodes=reasons)
            if step % 25 == 0 or step == args.steps:
                _progress(step, args.steps)

    count = write_animation(frames(), out, fps=args.fps)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    elapsed = time.perf_counter() - started
    summary = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "none ended"
    print(f"wrote {out}: {count} frames, {count * DT:.1f} s simulated at {args.fps} fps, "
          f"in {elapsed:.1f} s")
    print(f"episodes by end reason: {summary}")
    return 0
