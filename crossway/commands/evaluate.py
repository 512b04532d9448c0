"""``crossway evaluate``: the paper's experiments on a trained checkpoint."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate", help="run the paper's experiments on a checkpoint",
        description="Evaluate a trained checkpoint with the paper's protocols. Each writes JSON, CSV and a "
                    "Markdown table (with the paper's numbers beside ours) into --out.",
    )
    experiments = parser.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    fmt = argparse.ArgumentDefaultsHelpFormatter
    table1 = experiments.add_parser(
        "table1", help="Table I: reaches, crashes, off-roads, time-overs and speed per sign",
        description="The paper's Table I protocol: tests with delay_max = 10, 20, ... s up to the scenario's "
                    "training delay_max (3 tests for easy, 5 for medium, 10 for hard), each of --episodes "
                    "episodes, run in parallel worker processes; results per traffic sign averaged over "
                    "the tests.", formatter_class=fmt)
    table1.add_argument("--checkpoint", type=Path, help="learner checkpoint (runs/NAME/checkpoints/ckpt-*.pt)")
    table1.add_argument("--scripted", action="store_true",
                        help="drive with the scripted driver instead of a checkpoint (a reference, and for smoke runs)")
    table1.add_argument("--scenario", default="easy", help="easy, medium, hard or a TOML path")
    table1.add_argument("--episodes", type=int, default=3000, help="episodes per test (the paper: 3000)")
    table1.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes")
    table1.add_argument("--seed", type=int, default=0, help="test i uses seed + i")
    table1.add_argument("--out", type=Path, default=Path("results"), help="output directory")
    table1.set_defaults(func=run_table1_command)

    rules = experiments.add_parser(
        "right-of-way", help="Table II: episodes without right-of-way infractions",
        description="The paper's right-of-way test: every lane starts at once with a random route and sign, all "
                    "cars at the same current and target speed; an episode ends when every car has ended. An "
                    "infraction is a car entering a conflict area before a car with priority over it that also "
                    "crosses it (docs/evaluation.md). Episodes are split over worker processes.",
        formatter_class=fmt)
    rules.add_argument("--checkpoint", type=Path, help="learner checkpoint")
    rules.add_argument("--scripted", action="store_true", help="drive with the scripted driver instead")
    rules.add_argument("--scenario", default="easy", help="easy, medium, hard or a TOML path")
    rules.add_argument("--episodes", type=int, default=9000, help="episodes (the paper: 9000)")
    rules.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes")
    rules.add_argument("--seed", type=int, default=0, help="random seed")
    rules.add_argument("--out", type=Path, default=Path("results"), help="output directory")
    rules.set_defaults(func=run_right_of_way_command)


def run_table1_command(args) -> int:
    from evaluation.table1 import markdown, run_table1

    if (args.checkpoint is None) == (not args.scripted):
        raise ValueError("give either --checkpoint CKPT or --scripted")
    if args.episodes < 1 or args.workers < 1:
        raise ValueError("--episodes and --workers must be >= 1")
    report = run_table1(args.scenario, str(args.checkpoint) if args.checkpoint else None, args.episodes,
                        args.workers, args.seed, args.out, _command_line())
    print(markdown(report["meta"]["scenario"], report["table"]), end="")
    print("wrote " + ", ".join(str(p) for p in report["paths"]) + f" in {report['meta']['wall_s']} s")
    return 0


def _command_line() -> str:
    return "crossway " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def run_right_of_way_command(args) -> int:
    from evaluation.right_of_way import run_right_of_way

    if (args.checkpoint is None) == (not args.scripted):
        raise ValueError("give either --checkpoint CKPT or --scripted")
    if args.episodes < 1 or args.workers < 1:
        raise ValueError("--episodes and --workers must be >= 1")
    summary = run_right_of_way(args.scenario, str(args.checkpoint) if args.checkpoint else None, args.episodes,
                               args.workers, args.seed, args.out, _command_line())
    print(summary["markdown"], end="")
    print("wrote " + ", ".join(summary["paths"]) + f" in {summary['wall_s']} s")
    return 0
