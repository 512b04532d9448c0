"""``crossway evaluate``: the paper's experiments on a trained checkpoint."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from crossway.commands import HelpFormatter
from simcore.scenario import SIGN_CHANGE_RESTARTS


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate", help="run the paper's experiments on a checkpoint",
        description="Evaluate a trained checkpoint with the paper's protocols. Each writes JSON, CSV and a "
                    "Markdown table (with the paper's numbers beside ours) into --out. Stopped (Ctrl-C, "
                    "SIGTERM), the same command run again goes on from the jobs that had finished, kept in "
                    "--out/.partial until the outputs are written.",
    )
    experiments = parser.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    fmt = HelpFormatter
    table1 = experiments.add_parser(
        "table1", help="Table I: reaches, crashes, off-roads, time-overs and speed per sign",
        description="The paper's Table I protocol: tests with delay_max = 10, 20, ... s up to the scenario's "
                    "training delay_max (3 tests for easy, 5 for medium, 10 for hard), each of --episodes "
                    "episodes, run in parallel worker processes; results per traffic sign averaged over "
                    "the tests.", formatter_class=fmt)
    _add_policy_options(table1, scripted=True, scenario=True)
    _add_scripted_options(table1)
    _add_run_options(table1, episodes=3000, episodes_help="episodes per test (the paper: 3000)")
    table1.add_argument("--sign-restart", choices=SIGN_CHANGE_RESTARTS, default=None,
                        help="on a junction whose signs are redrawn at an interval (hard): after a redraw "
                             "each car waits its random delay before its next episode ('delayed', the "
                             "scenario file's default) or every car starts at the next step ('together', "
                             "eight at once: crossway's reading until session 30; docs/evaluation.md)")
    table1.add_argument("--sweep-up-to", type=float, default=None, metavar="SECONDS",
                        help="run only the tests with delay_max up to SECONDS (the densest traffic, where "
                             "policies lose most): a screen, each test with the seeds it has in the whole "
                             "protocol, so with half the --episodes it is the first half of those tests' "
                             "episodes. Default: the whole sweep")
    table1.add_argument("--share", default=None, metavar="I/N",
                        help="run only the I-th of N shares of every test's jobs (of 500 episodes each, "
                             "with the seeds they have in the whole protocol), e.g. 1/3, 2/3 and 3/3 on three "
                             "machines; 'crossway evaluate merge' then joins the N output folders into the "
                             "whole protocol's table. Default: every job")
    table1.set_defaults(func=run_table1_command)

    merge = experiments.add_parser(
        "merge", help="join runs of one protocol over other jobs (--share) into one report",
        description="Join the output folders (or reports) of runs of one protocol that ran other jobs of it, e.g. "
                    "'table1 --share 1/2' and '--share 2/2' on two machines, into the report one run over all "
                    "their jobs would have written: the same JSON, CSV, Markdown and pictures. Works for Table I "
                    "(table1-*.json: 500-episode jobs of every test), the right-of-way test (right-of-way-*.json: "
                    "150-episode jobs) and the TTC comparison (ttc-comparison.json: (traffic level, delay) "
                    "cells). A run of fewer --episodes counts as the first jobs of the protocol (Table I and "
                    "right of way: its episodes are the first ones). Refuses runs of two protocols, of other "
                    "scenarios, seeds, sizes, sign restarts or checkpoints (by SHA-256 where both reports have "
                    "it), and runs that overlap or leave a gap, before writing anything.", formatter_class=fmt)
    merge.add_argument("runs", nargs="+", type=Path, metavar="RUN",
                       help="output folder of a run, or its report (table1-*.json, right-of-way-*.json, "
                            "ttc-comparison.json)")
    merge.add_argument("--out", type=Path, required=True, help="output directory for the joined report")
    merge.set_defaults(func=run_merge_command)

    compare = experiments.add_parser(
        "compare", help="Table I reports of several policies side by side, against the paper (PNG, Markdown, CSV)",
        description="Read the output folders (or table1-*.json reports) of 'crossway evaluate table1' or 'evaluate "
                    "merge', of any junction, and write into --out: compare.png (one panel per junction, each "
                    "policy's reach per sign as a dot with +-1 standard error, the paper's figure as a black "
                    "bar), compare.md (reach per sign with its standard error, the paper's, how many points under "
                    "it, and each policy against the first one given on its junction, in points and standard "
                    "errors of the difference) and compare.csv (every outcome per policy and sign). Each "
                    "report's table is recomputed from its per-test counts, so reports of older versions compare "
                    "too. Refuses "
                    "other protocols' reports, and two reports of one name on one junction, before writing "
                    "anything.", formatter_class=fmt)
    compare.add_argument("runs", nargs="+", metavar="[NAME=]RUN",
                         help="a table1 output folder or report; NAME= sets the policy's name (default: the "
                              "checkpoint's file name without .pt)")
    compare.add_argument("--out", type=Path, required=True, help="output directory")
    compare.add_argument("--title", default="Table I: reach per sign, ours against the paper", help="figure title")
    compare.set_defaults(func=run_compare_command)

    peek = experiments.add_parser(
        "peek", help="the finished jobs of a Table I run still going (or stopped), per test and sign",
        description="Read the jobs a Table I run into --out has finished so far (kept in --out/.partial until "
                    "it writes its outputs) and print their reaches and crashes per test and sign, and their "
                    "average over the tests begun: a look at a run of hours before it ends, e.g. to stop a "
                    "policy that is clearly short. Reads files only; the run goes on undisturbed.",
        formatter_class=fmt)
    peek.add_argument("out", type=Path, metavar="OUT", help="the --out folder of the running table1 command")
    peek.set_defaults(func=run_peek_command)

    rules = experiments.add_parser(
        "right-of-way", help="Table II: episodes without right-of-way infractions",
        description="The paper's right-of-way test: every lane starts at once with a random route and sign, all "
                    "cars at the same current and target speed; an episode ends when every car has ended. An "
                    "infraction is a car entering a conflict area before a car with priority over it that also "
                    "crosses it (docs/evaluation.md). Each infraction is also sorted by whether the car wronged "
                    "could show in the offender's view while the offender could still stop at 3 m/s^2: "
                    "'no_seen_infraction' excuses those it could not have seen. Episodes are split over worker "
                    "processes.",
        formatter_class=fmt)
    _add_policy_options(rules, scripted=True, scenario=True)
    _add_scripted_options(rules)
    _add_run_options(rules, episodes=9000, episodes_help="episodes (the paper: 9000)")
    rules.add_argument("--share", default=None, metavar="I/N",
                       help="run only the I-th of N shares of the test's jobs (of 150 episodes each, with the seeds "
                            "they have in the whole test), e.g. 1/2 and 2/2 on two machines; 'crossway evaluate "
                            "merge' then joins the output folders. Default: every job")
    rules.set_defaults(func=run_right_of_way_command)

    ttc = experiments.add_parser(
        "ttc", help="Fig. 5: the learned policy against the TTC rule in IDM traffic",
        description="The paper's TTC comparison on hard: the ego starts from the stop-sign arm, IDM traffic "
                    "comes from the two adjacent arms at three levels (at most 4, 8, 12 cars), delay_max rises "
                    "by 20 s per test. Runs the TTC agent (and the learned policy, with --checkpoint) on the "
                    "same seeds; writes a CSV, a JSON and the two figures (reaches, time-overs). With "
                    "--sweep it first picks the threshold: the best reach rate with zero crashes.",
        formatter_class=fmt)
    _add_policy_options(ttc, scripted=False, scenario=False)
    ttc.add_argument("--threshold", type=float, default=6.0, help="TTC threshold [s] (ignored with --sweep)")
    ttc.add_argument("--sweep", default="", metavar="T1,T2,...",
                     help="comma-separated thresholds [s] to sweep first; the best zero-crash one is used")
    ttc.add_argument("--delays", default="20,40,60,80,100", help="comma-separated traffic delay_max values [s]")
    _add_run_options(ttc, episodes=200, episodes_help="ego episodes per (level, delay) cell")
    ttc.add_argument("--share", default=None, metavar="I/N",
                     help="run both drivers on only the I-th of N shares of the (level, delay) cells, low traffic "
                          "first, each with the seed it has in the whole comparison; 'crossway evaluate merge' then "
                          "joins the output folders and draws the figures. Needs --threshold (not --sweep). "
                          "Default: every cell")
    ttc.set_defaults(func=run_ttc_command)

    reaction = experiments.add_parser(
        "reaction", help="probe: does the policy slow down for the cars it must give way to?",
        description="Drive the scenario with the policy and, whenever a car approaches a conflict zone that a car "
                    "with priority over it has not cleared (and sees that car), run the network again with the "
                    "priority cars erased from its obstacle view. Reports how much they lower the commanded "
                    "acceleration and the value (docs/evaluation.md#reaction). Not one of the paper's "
                    "experiments: a diagnosis of what Table I's crash rate cannot show.", formatter_class=fmt)
    reaction.add_argument("--checkpoint", type=Path, required=True, help="learner checkpoint or exported policy")
    reaction.add_argument("--scenario", default="easy", help="easy, medium, hard or a TOML path")
    reaction.add_argument("--delay-max", type=float, default=10.0, metavar="SECONDS",
                          help="longest wait between a car's episodes [s] (10: Table I's densest test)")
    _add_run_options(reaction, episodes=500, episodes_help="episodes")
    reaction.set_defaults(func=run_reaction_command)

    export = experiments.add_parser(
        "export", help="copy a checkpoint's policy alone into a small file (for models/)",
        description="Keep only the network sizes, the weights and their provenance (version, agent-steps, run "
                    "id) of a learner checkpoint: about a third of its size, and what every evaluate "
                    "command accepts as --checkpoint.", formatter_class=fmt)
    export.add_argument("--checkpoint", type=Path, required=True, help="learner checkpoint")
    export.add_argument("--out", type=Path, required=True, help="file to write, e.g. models/easy.pt")
    export.add_argument("--note", default="", help="free text stored with the weights (how they were trained)")
    braking = export.add_mutually_exclusive_group()
    braking.add_argument("--emergency-braking", action="store_true",
                         help="store a rule that brakes for a car on a car's path ahead, read from its views, "
                              "on top of the network (not in the paper; algo/braking.py, docs/evaluation.md); "
                              "every evaluate command applies it. Default: keep the checkpoint's own rule, if any")
    braking.add_argument("--no-emergency-braking", action="store_true",
                         help="leave out the checkpoint's emergency-braking rule")
    export.add_argument("--emergency-margin", type=float, default=None, metavar="M",
                        help="with --emergency-braking: gap kept to the car in the path [m] (default 1.5)")
    export.add_argument("--emergency-reaction", type=float, default=None, metavar="S",
                        help="with --emergency-braking: time the trigger allows before braking starts [s] "
                             "(default 0.5)")
    export.add_argument("--emergency-deceleration", type=float, default=None, metavar="A",
                        help="with --emergency-braking: the braking the trigger distance assumes [m/s^2] (default 2)")
    export.set_defaults(func=run_export_command)


def _add_policy_options(parser, scripted: bool, scenario: bool) -> None:
    if scripted:
        parser.add_argument("--checkpoint", type=Path, help="learner checkpoint or exported policy")
        parser.add_argument("--scripted", action="store_true",
                            help="drive with the scripted driver instead of a checkpoint (a reference; smoke runs)")
    else:
        parser.add_argument("--checkpoint", type=Path,
                            help="learner checkpoint or exported policy (without it only the TTC agent runs)")
    if scenario:
        parser.add_argument("--scenario", default="easy", help="easy, medium, hard or a TOML path")


def _add_scripted_options(parser) -> None:
    parser.add_argument("--scripted-sight", choices=("full", "view"), default=None,
                        help="with --scripted: full (default) yields to every car with priority; view only to those "
                             "that may show in the square a learner's views show (50 x 50 m around it unless the "
                             "scenario's [views] say otherwise; the teacher of 'crossway pretrain --teacher-sight "
                             "view')")
    parser.add_argument("--scripted-approach-speed", type=float, default=None, metavar="M_PER_S",
                        help="with --scripted: slow to this speed [m/s] before every conflict zone shared with a "
                             "route that would have priority, whether or not a car is there (a driver that expects "
                             "cars it cannot see yet); default: no such caution")
    parser.add_argument("--scripted-approach-signs", choices=("all", "own"), default=None,
                        help="with --scripted-approach-speed: which signs decide the routes that would have "
                             "priority: all (default) the signs now on every arm; own the car's own sign alone, "
                             "every other arm taken as unsigned (what a learner's views show)")
    parser.add_argument("--scripted-brake-for-blockers", action="store_true",
                        help="with --scripted: also stop before a conflict zone that a car in sight stands or "
                             "drives in, even with the right of way (after 8 s standing it goes anyway)")
    parser.add_argument("--scripted-wait-outside-zones", action="store_true",
                        help="with --scripted: never stop with the body inside another route's conflict zone; "
                             "stop before the first of overlapping zones instead (hard's zones overlap)")
    parser.add_argument("--scripted-break-wait-cycles", action="store_true",
                        help="with --scripted: go ahead of a car with priority that waits, through a chain of "
                             "cars, for this one (else the chain waits for ever)")
    parser.add_argument("--scripted-patience", type=float, default=None, metavar="SECONDS",
                        help="with --scripted: after standing this long, stop yielding to cars with priority and go "
                             "('inf': never; default 4)")
    parser.add_argument("--scripted-blocker-patience", type=float, default=None, metavar="SECONDS",
                        help="with --scripted-brake-for-blockers: after standing this long, stop braking for cars "
                             "in the way ('inf': never; default 8)")


def _scripted_options(args, checkpoint: str | None) -> dict:
    """The scripted driver's options for the evaluation; refuses them with a checkpoint."""
    from simcore.controller import DriverOptions

    if checkpoint is not None and (args.scripted_sight is not None or args.scripted_approach_speed is not None
                                   or args.scripted_approach_signs is not None or args.scripted_brake_for_blockers
                                   or args.scripted_wait_outside_zones or args.scripted_break_wait_cycles
                                   or args.scripted_patience is not None
                                   or args.scripted_blocker_patience is not None):
        raise ValueError("--scripted-sight, --scripted-approach-speed, --scripted-approach-signs, "
                         "--scripted-brake-for-blockers, --scripted-wait-outside-zones, "
                         "--scripted-break-wait-cycles, --scripted-patience and --scripted-blocker-patience go "
                         "with --scripted, not with --checkpoint")
    patience = {}
    for flag, key, value in (("--scripted-patience", "patience_s", args.scripted_patience),
                             ("--scripted-blocker-patience", "blocker_patience_s", args.scripted_blocker_patience)):
        if value is not None:
            if not value > 0:
                raise ValueError(f"{flag} must be > 0 s ('inf': never), got {value}")
            patience[key] = value
    if args.scripted_approach_signs is not None and args.scripted_approach_speed is None:
        raise ValueError("--scripted-approach-signs goes with --scripted-approach-speed")
    if args.scripted_approach_speed is not None and not args.scripted_approach_speed >= 0:
        raise ValueError(f"--scripted-approach-speed must be >= 0 m/s, got {args.scripted_approach_speed}")
    return {"scripted": DriverOptions(sight=args.scripted_sight or "full",
                                      approach_speed_mps=args.scripted_approach_speed,
                                      approach_signs=args.scripted_approach_signs or "all",
                                      brake_for_blockers=args.scripted_brake_for_blockers,
                                      wait_outside_zones=args.scripted_wait_outside_zones,
                                      break_wait_cycles=args.scripted_break_wait_cycles, **patience)}


def _add_run_options(parser, episodes: int, episodes_help: str) -> None:
    parser.add_argument("--episodes", type=int, default=episodes, help=episodes_help)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes")
    parser.add_argument("--seed", type=int, default=0, help="random seed (each worker derives its own)")
    parser.add_argument("--out", type=Path, default=Path("results"), help="output directory")
    parser.add_argument("--portable-kernels", action="store_true",
                        help="multiply on MKL's AVX2 code path (MKL_CBWR=AVX2) instead of the fastest one for this "
                             "CPU: a policy's numbers then repeat to the digit on every Intel CPU with AVX2, not "
                             "only on the same kind (MKL's documented guarantee); on an AVX-512 machine the network "
                             "then runs 1.1x (one policy) to 1.45x (a seven-member ensemble) slower; refused where "
                             "MKL_CBWR is already set to something else; "
                             "docs/evaluation.md")


def _checked(args) -> str | None:
    """The checkpoint to evaluate (None: scripted); refuses contradictory or empty budgets."""
    if getattr(args, "scripted", None) is not None and (args.checkpoint is None) == (not args.scripted):
        raise ValueError("give either --checkpoint CKPT or --scripted")
    if args.episodes < 1 or args.workers < 1:
        raise ValueError("--episodes and --workers must be >= 1")
    if args.portable_kernels:
        from evaluation.parallel import use_portable_kernels

        use_portable_kernels()  # before any worker starts; the JSON's platform records it
    return str(args.checkpoint) if args.checkpoint else None


def run_table1_command(args) -> int:
    from evaluation.shares import parse_share
    from evaluation.table1 import markdown, run_table1

    checkpoint = _checked(args)
    share = parse_share(args.share) if args.share is not None else None
    report = run_table1(args.scenario, checkpoint, args.episodes, args.workers, args.seed, args.out,
                        _command_line(), **_scripted_options(args, checkpoint), sign_restart=args.sign_restart,
                        sweep_up_to_s=args.sweep_up_to, share=share)
    print(markdown(report["meta"]["scenario"], report["table"]), end="")
    print("wrote " + ", ".join(str(p) for p in report["paths"]) + f" in {report['meta']['wall_s']} s")
    return 0


def run_merge_command(args) -> int:
    from evaluation.shares import merge_reports

    report = merge_reports(args.runs, args.out, _command_line())
    meta, kind = report["meta"], report["kind"]
    if kind == "table1":
        from evaluation.table1 import markdown

        print(markdown(meta["scenario"], report["table"]), end="")
        size = f"{meta['episodes_per_test']} episodes per test"
        joined, missing = meta["jobs"][1], meta["jobs_not_joined"]
        unit = "job(s) per test"
    elif kind == "right-of-way":
        print(report["summary"]["markdown"], end="")
        size, joined, missing = f"{meta['protocol_episodes']} episodes", meta["jobs"][1], meta["jobs_not_joined"]
        unit = "job(s)"
    else:
        for row in report["rows"]:
            print(f"{row['driver']:6s} {row['level']:6s} delay {row['delay_max_s']:5g} s: reach "
                  f"{row['goal_rate']:.3f} crash {row['crash_rate']:.3f} time-over {row['time_over_rate']:.3f}")
        size, joined, missing = f"{meta['cells'][1]} (level, delay) cells", meta["cells"][1], meta["cells_not_joined"]
        unit = "cell(s)"
    print(f"joined {len(meta['merged_from'])} runs, {size}; wrote " + ", ".join(str(p) for p in report["paths"]))
    if missing:
        print(f"note: the shares' protocol has {missing} more {unit} that no run given holds; the report is of "
              f"the first {joined}, {size}", file=sys.stderr)
    return 0


def run_compare_command(args) -> int:
    from evaluation.compare import load_entries, markdown, write_comparison

    entries = load_entries(args.runs)
    paths = write_comparison(entries, args.out, args.title)
    print(markdown(entries), end="")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def run_peek_command(args) -> int:
    from evaluation.table1 import peek

    print(peek(args.out), end="")
    return 0


def _command_line() -> str:
    return "crossway " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def run_right_of_way_command(args) -> int:
    from evaluation.right_of_way import run_right_of_way
    from evaluation.shares import parse_share

    checkpoint = _checked(args)
    share = parse_share(args.share) if args.share is not None else None
    summary = run_right_of_way(args.scenario, checkpoint, args.episodes, args.workers, args.seed, args.out,
                               _command_line(), **_scripted_options(args, checkpoint), share=share)
    print(summary["markdown"], end="")
    if share is not None:
        print(f"share {share[0]}/{share[1]}: {summary['episodes']} of the test's {args.episodes} episodes; "
              "'crossway evaluate merge' joins the shares")
    print("wrote " + ", ".join(summary["paths"]) + f" in {summary['wall_s']} s")
    return 0


def run_reaction_command(args) -> int:
    from evaluation.reaction import run_reaction

    checkpoint = _checked(args)
    report = run_reaction(args.scenario, checkpoint, args.episodes, args.delay_max, args.workers, args.seed,
                          args.out, _command_line())
    print(report["markdown"], end="")
    print("wrote " + ", ".join(report["paths"]) + f" in {report['meta']['wall_s']} s")
    return 0


def _floats(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{option} must be comma-separated numbers, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise ValueError(f"{option} needs positive numbers, got {text!r}")
    return values


def run_ttc_command(args) -> int:
    from evaluation.shares import parse_share
    from evaluation.ttc_test import run_comparison, sweep_thresholds

    checkpoint = _checked(args)
    delays = _floats(args.delays, "--delays")
    share = parse_share(args.share) if args.share is not None else None
    if share is not None and args.sweep:
        raise ValueError("--share goes with --threshold, not --sweep: the sweep picks the threshold from every cell; "
                         "sweep first (or choose the threshold), then share the comparison")
    threshold = args.threshold
    if threshold <= 0:
        raise ValueError(f"--threshold must be > 0, got {threshold}")
    rows = []
    if args.sweep:
        best, rows = sweep_thresholds(_floats(args.sweep, "--sweep"), args.episodes, delays, args.workers, args.seed,
                                      args.out)
        for row in rows:
            print(f"sweep: threshold {row['threshold_s']:g} s, {row['level']:6s} delay {row['delay_max_s']:g} s: "
                  f"reach {row['goal_rate']:.3f} crash {row['crash_rate']:.3f} time-over {row['time_over_rate']:.3f}")
        if best is None:
            raise ValueError("no swept threshold gave zero crashes; sweep higher thresholds")
        threshold = best
        print(f"sweep: chose {threshold:g} s")
    report = run_comparison(checkpoint, threshold, args.episodes, delays, args.workers, args.seed, args.out,
                            _command_line(), sweep_rows=rows, share=share)
    if report["meta"]["ttc_cells_from_sweep"]:
        print(f"comparison: the TTC agent's {report['meta']['ttc_cells_from_sweep']} cells at {threshold:g} s "
              "are the sweep's (same seeds, same episodes)")
    for row in report["rows"]:
        print(f"{row['driver']:6s} {row['level']:6s} delay {row['delay_max_s']:5g} s: reach {row['goal_rate']:.3f} "
              f"crash {row['crash_rate']:.3f} time-over {row['time_over_rate']:.3f}")
    if share is not None:
        print(f"share {share[0]}/{share[1]}: cells {report['meta']['cells'][0] + 1}-{report['meta']['cells'][1]} of "
              f"{report['meta']['protocol_cells']}; 'crossway evaluate merge' joins the shares and draws the figures")
    print("wrote " + ", ".join(str(p) for p in report["paths"]) + f" in {report['meta']['wall_s']} s")
    return 0


def run_export_command(args) -> int:
    from evaluation.policy import export_policy

    from algo.braking import EmergencyBraking
    from algo.policy import load_policy

    if not args.out.parent.is_dir():
        raise ValueError(f"--out: directory {str(args.out.parent)!r} does not exist")
    settings = {"margin_m": args.emergency_margin, "reaction_s": args.emergency_reaction,
                "deceleration_mps2": args.emergency_deceleration}
    given = {k: v for k, v in settings.items() if v is not None}
    if given and not args.emergency_braking:
        raise ValueError("--emergency-margin, --emergency-reaction and --emergency-deceleration go with "
                         "--emergency-braking")
    rule: EmergencyBraking | bool | None = True  # keep the checkpoint's own
    if args.emergency_braking:
        rule = EmergencyBraking(**given)
    elif args.no_emergency_braking:
        rule = None
    path = export_policy(args.checkpoint, args.out, args.note, emergency_braking=rule)
    kept = load_policy(path).emergency_braking
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)" + (f"; {kept.describe()}" if kept else ""))
    return 0
