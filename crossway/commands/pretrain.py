"""``crossway pretrain``: a warm start for ``crossway train`` from a privileged scripted teacher, or a
policy distilled from a trained one (``--teacher-checkpoint``)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from crossway.commands import HelpFormatter


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "pretrain", help="warm-start a policy by imitating the scripted driver, or distil a trained one "
                         "(not in the paper)",
        description="Teach the network to drive by imitating the scripted driver, which reads the right of way "
                    "from the simulator (information the network only gets through its views): every car's "
                    "observation is labelled with the driver's action, and the value heads learn the discounted "
                    "returns of the episodes driven. Episodes are driven by the teacher, then more and more by "
                    "the network itself (DAgger). With --teacher-checkpoint a trained policy (such as an "
                    "output ensemble) is the teacher instead: policy distillation. Writes OUT/pretrained.pt "
                    "(also on Ctrl-C), which "
                    "'crossway train --init-from' and every 'crossway evaluate' take, and OUT/progress.csv. "
                    "Not part of the paper's method, which learns from rewards alone "
                    "(docs/training.md#warm-start-from-a-scripted-teacher).",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--scenario", default="easy", help="built-in scenario (easy, medium, hard) or a TOML path")
    parser.add_argument("--minutes", type=float, default=10.0, help="wall-clock budget [min]")
    parser.add_argument("--rounds", type=int, default=0,
                        help="stop after this many rounds of collection and training (0: --minutes alone decides)")
    parser.add_argument("--out", type=Path, default=Path("runs/pretrain"), help="output directory")
    parser.add_argument("--save-every", type=float, default=5.0, metavar="MINUTES",
                        help="also write pretrained.pt every so often during the run, so that a run killed "
                             "outright loses at most that much (0: only at the end; Ctrl-C and SIGTERM always "
                             "write it)")
    parser.add_argument("--init-from", type=Path, default=None, metavar="CHECKPOINT",
                        help="start from these weights (a checkpoint or a models/*.pt policy); default: random")
    parser.add_argument("--steps-per-round", type=int, default=500,
                        help="simulator steps (0.1 s each) collected between training phases")
    parser.add_argument("--reuse", type=float, default=4.0,
                        help="how many times, on average, each collected sample is trained on")
    parser.add_argument("--batch-size", type=int, default=64, help="samples per Adam step")
    parser.add_argument("--learning-rate", type=float, default=3e-4, help="Adam step size")
    parser.add_argument("--value-coef", type=float, default=0.5, help="weight of the value losses")
    parser.add_argument("--gamma", type=float, default=0.99,
                        help="discount of the value targets per 0.1 s step; use the one 'crossway train' will use")
    parser.add_argument("--teacher-checkpoint", type=Path, default=None, metavar="CHECKPOINT",
                        help="distil this trained policy instead of imitating the scripted driver: its Gaussian "
                             "means, as 'crossway evaluate' drives it (an output ensemble's members side by side, "
                             "its caution applied), label every car. It must have learnt from the scenario's view "
                             "square; the --teacher-* options of the scripted driver do not apply. Default: the "
                             "scripted driver")
    parser.add_argument("--driver-checkpoint", type=Path, default=None, metavar="CHECKPOINT",
                        help="drive the episodes the teacher does not drive with this fixed trained policy instead "
                             "of the student (DAgger on the states that policy meets): with the output ensemble a "
                             "member will rejoin, the member learns the teacher's actions where the ensemble goes "
                             "wrong (docs/imitation.md, session 32). The rolling 'student' reach is then the "
                             "driver's. Default: the student drives")
    parser.add_argument("--teacher-sight", choices=("full", "view"), default="full",
                        help="full: the teacher yields to every car with priority, wherever it is; view: only to "
                             "those that may show (any part of them) in the square its views show (50 x 50 m "
                             "around it unless the scenario's [views] say otherwise), so that its labels follow "
                             "from the network's input")
    parser.add_argument("--teacher-approach-speed", type=float, default=None, metavar="M_PER_S",
                        help="the teacher slows to this speed [m/s] before every conflict zone shared with a route "
                             "that would have priority, whether or not a car is there: a driver that expects cars "
                             "it cannot see yet (docs/imitation.md measures 1 m/s with --teacher-sight view). "
                             "Default: no such slowing")
    parser.add_argument("--teacher-approach-signs", choices=("all", "own"), default="all",
                        help="with --teacher-approach-speed: which signs decide the routes that would have priority: "
                             "all the signs now on every arm (a learner's views show only its own lane's sign "
                             "line); own the car's own sign alone, every other arm taken as unsigned, so that the "
                             "slowing follows from what the views show")
    parser.add_argument("--teacher-brake-for-blockers", action="store_true",
                        help="the teacher also stops before a conflict zone that a car in sight stands or drives "
                             "in, even with the right of way (after 8 s standing it goes anyway): on easy it "
                             "halves the crashes of --teacher-sight view (docs/imitation.md)")
    parser.add_argument("--teacher-wait-outside-zones", action="store_true",
                        help="the teacher never stops with its body inside another route's conflict zone; it "
                             "stops before the first of overlapping zones instead (hard's zones overlap)")
    parser.add_argument("--teacher-break-wait-cycles", action="store_true",
                        help="the teacher goes ahead of a car with priority that waits, through a chain of cars, "
                             "for it: with --teacher-brake-for-blockers the cars on hard otherwise lock each other")
    parser.add_argument("--teacher-patience", type=float, default=4.0, metavar="SECONDS",
                        help="after standing this long the teacher stops yielding to cars with priority and goes; "
                             "'inf': it never does. A clock the student's four frames (0.3 s) cannot show: on "
                             "medium and hard 'inf' also drives better (docs/imitation.md)")
    parser.add_argument("--teacher-blocker-patience", type=float, default=8.0, metavar="SECONDS",
                        help="with --teacher-brake-for-blockers: after standing this long the teacher stops "
                             "braking for cars in its way; 'inf': it never does")
    parser.add_argument("--teacher-half-life", type=float, default=20_000.0, metavar="SAMPLES",
                        help="a new episode is driven by the teacher with probability 0.5**(samples collected / "
                             "SAMPLES), by the network otherwise (DAgger); 'inf': always the teacher")
    parser.add_argument("--brake-weight", type=float, default=1.0, metavar="W",
                        help="count each sample the teacher brakes hard in (-1.5 m/s2 or more) W times in the "
                             "acceleration loss: such samples are few (about 7%% on hard) and decide the crashes")
    parser.add_argument("--blocker-weight", type=float, default=1.0, metavar="W",
                        help="with --teacher-brake-for-blockers: multiply by W the weight of each sample whose "
                             "label is the teacher braking for a car standing in its way (on top of --brake-weight): "
                             "in the hard student's crossing crashes the car with priority ran into a car already "
                             "in their zone (docs/imitation.md). Default 1")
    parser.add_argument("--patience-weight", type=float, default=1.0, metavar="W",
                        help="multiply by W the weight of each sample whose label is the teacher going, having "
                             "stood out --teacher-patience, although a car with priority is near: about 0.2%% of "
                             "the hard teacher's car-steps, the 'wait, then go' students have not learnt (pair it "
                             "with --standing-input, so the network sees how long it has stood). Default 1")
    parser.add_argument("--acceleration-loss", choices=("squared", "absolute"), default="squared",
                        help="the acceleration mean's error against the teacher's label: 'squared' fits the "
                             "labels' mean, 'absolute' their median. Where the views cannot tell a state the "
                             "teacher goes in from one it brakes in, the mean is a car that neither goes nor "
                             "stops, the median the commoner of the two. progress.csv's action_loss_acc is then "
                             "the mean absolute error. Default: squared")
    parser.add_argument("--priority-exponent", type=float, default=0.0, metavar="ALPHA",
                        help="draw training samples with probability proportional to (the student's acceleration "
                             "error + 0.15 m/s2) ** ALPHA, measured when it drove past them and each time they are "
                             "trained on (prioritized replay as hard-example mining; docs/imitation.md). Default 0: "
                             "uniformly")
    parser.add_argument("--average-half-life", type=float, default=None, metavar="UPDATES",
                        help="write as OUT/pretrained.pt a moving average of the weights over the Adam steps, "
                             "each step's weights counting 0.5**(steps since / UPDATES) (Polyak averaging: it "
                             "smooths the noise of the last steps); the last weights go to OUT/pretrained-last.pt. "
                             "Default: the last weights")
    parser.add_argument("--network", type=_network_sizes, default=None, metavar="C1,C2,HIDDEN",
                        help="the network's sizes per head: first and second convolution channels, hidden units "
                             "(the default network is 16,16,128). With --init-from the loaded network is widened "
                             "to these sizes computing the same function: its units keep their weights, new ones "
                             "start with zero outputs (docs/imitation.md). Default: the --init-from file's sizes")
    parser.add_argument("--standing-input", action="store_true",
                        help="give the network a third scalar beside speed and target speed: how long its car "
                             "has stood (under 0.5 m/s) [s], the clock the teacher's --teacher-patience reads and "
                             "four frames cannot show. Not the paper's input. With --init-from a network without "
                             "it gets it with zero weights, driving as before until training moves them")
    parser.add_argument("--buffer-samples", type=int, default=40_000,
                        help="replay capacity in samples (28 KB each: 40,000 take 1.1 GB)")
    parser.add_argument("--delay-max", type=float, default=None, metavar="SECONDS",
                        help="longest wait between a lane's episodes (default: the scenario's)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--threads", type=int, default=2, help="torch threads for training")
    parser.set_defaults(func=run)


# each PretrainConfig field's flag, for learner.pretrain.check_config's messages: "--" and the field's name
# with dashes, but for these
_RENAMED = {"teacher_approach_mps": "--teacher-approach-speed", "teacher_patience_s": "--teacher-patience",
            "teacher_blocker_patience_s": "--teacher-blocker-patience", "delay_max_s": "--delay-max",
            "torch_threads": "--threads"}


def flag(field: str) -> str:
    """The ``crossway pretrain`` flag that sets PretrainConfig's ``field``."""
    return _RENAMED.get(field, "--" + field.replace("_", "-"))


def _network_sizes(text: str) -> tuple[int, int, int]:
    try:
        sizes = tuple(int(part) for part in text.split(","))
    except ValueError:
        sizes = ()
    if len(sizes) != 3 or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"expected three positive integers C1,C2,HIDDEN such as 32,32,256, "
                                         f"got {text!r}")
    return sizes


def run(args) -> int:
    from learner.pretrain import PretrainConfig, check_config, run_pretrain
    from simcore.scenario import load_scenario

    load_scenario(args.scenario)  # a clear error for an unknown scenario before anything starts
    if not args.save_every >= 0:
        raise ValueError(f"--save-every must be >= 0 minutes, got {args.save_every}")
    config = PretrainConfig(
        scenario=args.scenario, minutes=args.minutes, rounds=args.rounds, steps_per_round=args.steps_per_round,
        reuse=args.reuse, batch_size=args.batch_size, learning_rate=args.learning_rate, value_coef=args.value_coef,
        gamma=args.gamma, teacher_sight=args.teacher_sight, teacher_approach_mps=args.teacher_approach_speed,
        teacher_approach_signs=args.teacher_approach_signs, teacher_brake_for_blockers=args.teacher_brake_for_blockers,
        teacher_wait_outside_zones=args.teacher_wait_outside_zones,
        teacher_break_wait_cycles=args.teacher_break_wait_cycles,
        teacher_patience_s=args.teacher_patience, teacher_blocker_patience_s=args.teacher_blocker_patience,
        teacher_half_life=args.teacher_half_life,
        brake_weight=args.brake_weight, blocker_weight=args.blocker_weight, patience_weight=args.patience_weight,
        acceleration_loss=args.acceleration_loss, priority_exponent=args.priority_exponent,
        buffer_samples=args.buffer_samples, delay_max_s=args.delay_max, seed=args.seed, init_from=args.init_from,
        torch_threads=args.threads, average_half_life=args.average_half_life, network=args.network,
        standing_input=args.standing_input, teacher_checkpoint=args.teacher_checkpoint,
        driver_checkpoint=args.driver_checkpoint)
    check_config(config, name=flag)  # every setting's check, told in flags
    if args.out.exists() and not args.out.is_dir():
        raise ValueError(f"--out {str(args.out)!r} is a file, not a directory")
    if (args.out / "pretrained.pt").exists():
        raise ValueError(f"{str(args.out / 'pretrained.pt')!r} exists: choose another --out, or move it away first "
                         "(nothing is overwritten)")
    for checkpoint in (args.teacher_checkpoint, args.driver_checkpoint):
        if checkpoint is not None:
            from algo.policy import load_policy

            load_policy(checkpoint)  # refuse a bad file before the simulator starts
    if args.init_from is not None:
        from algo.policy import load_policy

        loaded = load_policy(args.init_from)  # refuse a bad file before the simulator starts
        if args.network is not None:
            from algo.policy import PolicyConfig, widen

            try:  # refuses a smaller network
                widen(loaded, PolicyConfig(*args.network,
                                           standing_input=loaded.config.standing_input or args.standing_input))
            except ValueError as error:
                raise ValueError(f"--network {','.join(map(str, args.network))} and --init-from "
                                 f"{args.init_from}: {error}") from None
    command = "crossway " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    run_pretrain(config, args.out, command, log=lambda line: print(line, flush=True),
                 save_every_s=60.0 * args.save_every)
    return 0
