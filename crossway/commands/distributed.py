"""``crossway learner``, ``crossway actor`` and ``crossway train``.

The learner owns the global network; actors host a simulator each and connect to it over Zenoh.
``train`` starts both on this machine (learner on a loopback endpoint, actors connected to it),
shows a live progress line and stops cleanly on Ctrl-C or when its time is up.
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing
import os
import signal
import socket
import sys
import time
from pathlib import Path

from crossway.commands import HelpFormatter

CURRICULA = ("none", "single", "yield")
YIELD_DRILL_TRAFFIC_LEVEL = "medium"  # the TTC test's level: at most 8 traffic cars
YIELD_DRILL_TRAFFIC_DELAY_MAX_S = 40.0  # longest wait before a traffic car starts again [s]
YIELD_DRILL_LABEL = "hard-yield-drill"  # scenario label of the drill's episodes in the learner's metrics
CURRICULUM_NOTES = {"none": "", "single": " (single-agent curriculum)",
                    "yield": " (yield curriculum: odd-numbered actors drive the yield drill)"}


def _add_common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--run-name", default="default",
                        help="namespace of this run's Zenoh keys; learner and actors must agree")
    parser.add_argument("--mode", choices=("peer", "client"), default="peer",
                        help="Zenoh session mode (client: through a router)")


def _add_tls(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("mutual TLS (tls/HOST:PORT endpoints; deploy/make-certs.sh makes a dev set)")
    group.add_argument("--tls-root-ca", default="", metavar="PEM", help="CA certificate that signs every party")
    group.add_argument("--tls-cert", default="", metavar="PEM", help="this process's certificate")
    group.add_argument("--tls-key", default="", metavar="PEM", help="this process's private key")


def _transport(args, listen: tuple[str, ...], connect: tuple[str, ...], mode: str | None = None):
    from protocol.transport import TransportConfig

    return TransportConfig(mode=mode or args.mode, listen=listen, connect=connect,
                           tls_root_ca=getattr(args, "tls_root_ca", ""), tls_certificate=getattr(args, "tls_cert", ""),
                           tls_private_key=getattr(args, "tls_key", ""))


def _add_learner_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--learning-rate", type=float, default=2.5e-4, help="Adam step size of the global network")
    parser.add_argument("--sigma-decay-steps", type=int, default=5_000_000,
                        help="agent-steps over which the exploration sigma falls from --sigma-start to 0.05")
    parser.add_argument("--sigma-start", type=float, default=0.65,
                        help="exploration sigma at agent-step 0 (the paper: 0.65; lower to fine-tune a policy)")
    parser.add_argument("--init-from", type=Path, default=None, metavar="CHECKPOINT",
                        help="start a new run from these weights (a learner checkpoint or an exported policy, "
                             "e.g. models/easy.pt, for a curriculum across scenarios); ignored when --run-dir "
                             "already holds a checkpoint to resume from")
    parser.add_argument("--max-staleness", type=int, default=50,
                        help="refuse gradients computed on weights more than this many versions old")
    parser.add_argument("--checkpoint-interval", type=float, default=60.0, metavar="SECONDS",
                        help="seconds between checkpoints (one is also written on exit)")
    parser.add_argument("--metrics-port", type=int, default=9100, help="Prometheus /metrics port (0: off)")


def _add_actor_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="easy", help="built-in scenario (easy, medium, hard) or a TOML path")
    parser.add_argument("--delay-max", type=float, default=None, metavar="SECONDS",
                        help="longest wait between an agent's episodes [s]; default: the scenario's")
    parser.add_argument("--update-interval", type=int, default=20,
                        help="steps between an agent's local D-A3C updates")
    parser.add_argument("--noise-correlation", type=float, default=0.0, metavar="RHO",
                        help="AR(1) coefficient of each car's acceleration noise per 0.1 s step, in [0, 1): "
                             "0 draws fresh noise every step (the paper); 0.95 holds a deviation for about "
                             "2 s, so cars explore braking long enough to give way (docs/training.md)")
    parser.add_argument("--gamma", type=float, default=0.99,
                        help="discount factor per 0.1 s step, in (0, 1] (not given in the paper). It sets how "
                             "much crash risk a car accepts to save waiting time: with 0.99, going first beats "
                             "waiting 2 s for a car with priority unless it crashes more than ~8%% of the time; "
                             "with 0.998, ~2%% (docs/training.md#the-discount-and-giving-way)")
    parser.add_argument("--gae-lambda", type=float, default=1.0, metavar="LAMBDA",
                        help="lambda of generalized advantage estimation for the policy gradient, in [0, 1]: 1 is "
                             "the paper's A = R - v; lower leans on the critic (less variance, more bias)")
    parser.add_argument("--value-coef", type=float, default=0.5, metavar="COEF",
                        help="weight of the value losses against the policy losses in each local update")
    parser.add_argument("--local-learning-rate", type=float, default=1e-3, metavar="LR",
                        help="SGD step of each agent's local copy at its updates during the episode (the "
                             "'delayed' part of D-A3C), >= 0. 0 drives the whole episode on the weights it "
                             "started from. Lower it to fine-tune a trained policy at a small --sigma-start: "
                             "the local gradient scales as 1/sigma^2, and at sigma 0.05 the default step (%(default)g) "
                             "alone cut a hard student's training reach from 93%% to 52%% (docs/imitation.md)")
    parser.add_argument("--acceleration-cost", type=float, default=0.0, metavar="COEF",
                        help="weight of a cost on the squared acceleration mean per step (not in the paper; 0: "
                             "off); keeps the mean near 'hold' at the speed cap instead of full throttle, so "
                             "exploration still brakes (docs/training.md)")


def add_parser(subparsers) -> None:
    fmt = HelpFormatter
    learner = subparsers.add_parser(
        "learner", help="run the central D-A3C learner", formatter_class=fmt,
        description="Own the global network and its optimizer, apply actors' whole-episode gradients as "
                    "they arrive, publish new weights, serve Prometheus metrics, write checkpoints (and "
                    "resume from the newest one in --run-dir).")
    learner.add_argument("--run-dir", required=True, type=Path, help="directory for checkpoints")
    learner.add_argument("--listen", default="tcp/0.0.0.0:7447",
                         help="comma-separated Zenoh endpoints to listen on")
    learner.add_argument("--connect", default="", help="comma-separated endpoints to connect to (e.g. a router)")
    _add_common(learner)
    _add_learner_options(learner)
    _add_tls(learner)
    learner.set_defaults(func=run_learner_command)

    actor = subparsers.add_parser(
        "actor", help="run one actor (a simulator and its agents)", formatter_class=fmt,
        description="Host one simulator with a learning agent on every entry lane; pull the newest "
                    "global weights over Zenoh and push each finished episode's gradient sum to the "
                    "learner. Stateless: stop it at any time, start more to go faster.")
    actor.add_argument("--connect", default="tcp/127.0.0.1:7447",
                       help="comma-separated Zenoh endpoints of the learner or a router")
    actor.add_argument("--id", default="", help="actor id (default: HOST-PID)")
    actor.add_argument("--seed", type=int, default=None, help="random seed (default: random)")
    actor.add_argument("--lanes", default="", help="comma-separated entry lanes that host agents (default: all)")
    actor.add_argument("--yield-drill", action="store_true",
                       help="drive the yield drill instead of the scenario (hard only): learners start from "
                            "the stop-sign arm and must give way to IDM traffic on the two adjacent arms, "
                            "as in the TTC test (docs/training.md)")
    actor.add_argument("--learner-timeout", type=float, default=60.0, metavar="SECONDS",
                       help="pause driving when no weights have come from the learner for this long (it "
                            "republishes them every 5 s, so it is gone) and wait for a learner to answer "
                            "again: gradients pushed with no learner to take them are lost work")
    _add_common(actor)
    _add_actor_options(actor)
    _add_tls(actor)
    actor.set_defaults(func=run_actor_command)

    router = subparsers.add_parser(
        "router", help="run a Zenoh router (learner and actors connect to it as clients)", formatter_class=fmt,
        description="A Zenoh router from the Python package (zenohd itself is not on the package registries): "
                    "start it where every machine can reach it, then run the learner and the actors with "
                    "--mode client --connect tcp/ROUTER:7447. Stops on Ctrl-C or SIGTERM.")
    router.add_argument("--listen", default="tcp/0.0.0.0:7447", help="comma-separated endpoints to listen on")
    _add_tls(router)
    router.set_defaults(func=run_router_command)

    train = subparsers.add_parser(
        "train", help="train on this machine: a learner and N actors", formatter_class=fmt,
        description="Start a learner and N actor processes on this machine, connected over Zenoh on "
                    "loopback; show a live progress line; stop after --minutes or on Ctrl-C or SIGTERM, leaving a "
                    "checkpoint in --run-dir. Running it again with the same --run-dir resumes.")
    train.add_argument("--actors", type=int, default=max(1, (os.cpu_count() or 2) - 1),
                       help="actor processes (each uses one core)")
    train.add_argument("--minutes", type=float, default=30.0, help="wall-clock budget [min]")
    train.add_argument("--run-dir", type=Path, default=Path("runs/default"), help="checkpoints and progress.csv")
    train.add_argument("--curriculum", choices=CURRICULA, default="none",
                       help="single: one agent per simulator and no traffic (path following only); "
                            "actor i drives from entry lane i. yield (hard only): odd-numbered actors drive "
                            "the yield drill (learners on the stop-sign arm give way to IDM traffic), even "
                            "ones the scenario as usual")
    train.add_argument("--seed", type=int, default=0, help="actor i uses seed + i")
    train.add_argument("--port", type=int, default=0, help="loopback TCP port of the learner (0: a free one)")
    _add_common(train)
    _add_learner_options(train)
    _add_actor_options(train)
    train.set_defaults(func=run_train_command)


# -- configs from arguments ------------------------------------------------------------------------


def learner_config(args, listen: tuple[str, ...], connect: tuple[str, ...]):
    from learner.core import LearnerConfig
    from learner.service import LearnerServiceConfig

    if args.learning_rate <= 0 or args.sigma_decay_steps < 0 or args.max_staleness < 0:
        raise ValueError("--learning-rate must be > 0, --sigma-decay-steps and --max-staleness >= 0")
    if not 0.05 <= args.sigma_start <= 2.0:
        raise ValueError(f"--sigma-start must be between 0.05 (the final sigma) and 2, got {args.sigma_start}")
    if args.init_from is not None:
        from dataclasses import asdict

        from algo.policy import PolicyConfig, load_policy

        loaded = load_policy(args.init_from)  # fail here, before any process starts, with the file's problem
        if loaded.config != PolicyConfig():
            raise ValueError(f"--init-from {args.init_from}: its network {asdict(loaded.config)} is not the one D-A3C "
                             f"trains, {asdict(PolicyConfig())} (the paper's inputs); a network widened or given "
                             "the standing-time input by crossway pretrain goes on with crossway pretrain")
    if args.metrics_port < 0 or args.metrics_port > 65535:
        raise ValueError(f"--metrics-port must be 0-65535, got {args.metrics_port}")
    return LearnerServiceConfig(
        run_dir=args.run_dir, run_name=args.run_name, transport=_transport(args, listen, connect),
        metrics_port=args.metrics_port, checkpoint_interval_s=args.checkpoint_interval,
        learner=LearnerConfig(learning_rate=args.learning_rate, sigma_decay_agent_steps=args.sigma_decay_steps,
                              sigma_start=args.sigma_start, max_staleness=args.max_staleness),
        init_from=args.init_from,
    )


def yield_drill_sim_config():
    """The yield drill: the TTC test's setting (evaluation.ttc_test) as a training simulator.

    Learners start from both lanes of hard's stop-sign arm (south); IDM traffic, which never
    yields, comes from both lanes of the main road (east, west, no sign). Every car the learner
    meets has priority over it, so each episode asks it to find a gap: the skill our policies
    lack (docs/training.md#giving-way-why-our-agents-have-not-learned-it-yet).
    """
    from evaluation.ttc_test import EGO_LANES, ttc_setting

    return ttc_setting(EGO_LANES, YIELD_DRILL_TRAFFIC_LEVEL, YIELD_DRILL_TRAFFIC_DELAY_MAX_S)


def actor_config(args, connect: tuple[str, ...], lanes: tuple[str, ...] | None, seed, actor_id: str,
                 delay_max: float | None, yield_drill: bool = False):
    from actors.worker import ActorServiceConfig
    from algo.d_a3c import DA3CConfig
    from simcore.scenario import load_scenario
    from simcore.simulator import SimConfig

    load_scenario(args.scenario)  # fail here, with the scenario's own message
    if args.update_interval < 1:
        raise ValueError(f"--update-interval must be >= 1, got {args.update_interval}")
    if not 0.0 <= args.noise_correlation < 1.0:
        raise ValueError(f"--noise-correlation must be in [0, 1), got {args.noise_correlation}")
    if not args.value_coef > 0.0:
        raise ValueError(f"--value-coef must be > 0, got {args.value_coef}")
    if not 0.0 < args.gamma <= 1.0:
        raise ValueError(f"--gamma must be in (0, 1], got {args.gamma}")
    if not 0.0 <= args.gae_lambda <= 1.0:
        raise ValueError(f"--gae-lambda must be in [0, 1], got {args.gae_lambda}")
    if not args.acceleration_cost >= 0.0:
        raise ValueError(f"--acceleration-cost must be >= 0, got {args.acceleration_cost}")
    if not args.local_learning_rate >= 0.0:
        raise ValueError(f"--local-learning-rate must be >= 0, got {args.local_learning_rate}")
    if yield_drill:
        if load_scenario(args.scenario).name != "hard":
            raise ValueError(f"the yield drill runs on the hard junction (the TTC test's arms), not {args.scenario!r}")
        if lanes is not None:
            raise ValueError("the yield drill chooses its own lanes: leave out --lanes")
        sim = yield_drill_sim_config()
        episode_label = YIELD_DRILL_LABEL
    else:
        episode_label = ""
        sim = SimConfig(lanes=lanes, delay_max_s=delay_max, delay_min_s=0.0 if delay_max is not None else None)
    return ActorServiceConfig(
        scenario=args.scenario, run_name=args.run_name, transport=_transport(args, (), connect),
        actor_id=actor_id, seed=seed, sim=sim, episode_label=episode_label,
        da3c=DA3CConfig(update_interval=args.update_interval, noise_correlation=args.noise_correlation,
                        acceleration_cost=args.acceleration_cost, value_coef=args.value_coef,
                        gamma=args.gamma, gae_lambda=args.gae_lambda,
                        local_learning_rate=args.local_learning_rate),
    )


def run_learner_command(args) -> int:
    from learner.service import run_learner
    from protocol.transport import parse_endpoints

    return run_learner(learner_config(args, parse_endpoints(args.listen), parse_endpoints(args.connect)))


def run_actor_command(args) -> int:
    from actors.worker import run_actor
    from protocol.transport import parse_endpoints

    lanes = tuple(x for x in args.lanes.split(",") if x) or None
    if not args.learner_timeout > 0:
        raise ValueError(f"--learner-timeout must be > 0 seconds, got {args.learner_timeout}")
    if args.yield_drill and args.delay_max is not None:
        raise ValueError("the yield drill sets its own waits (0-2 s for learners, 0-40 s for traffic): "
                         "leave out --delay-max")
    from dataclasses import replace

    config = actor_config(args, parse_endpoints(args.connect), lanes, args.seed, args.id, args.delay_max,
                          yield_drill=args.yield_drill)
    return run_actor(replace(config, learner_silence_s=args.learner_timeout))


def run_router_command(args) -> int:
    import threading

    from protocol.transport import open_session, parse_endpoints

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    listen = parse_endpoints(args.listen)
    with open_session(_transport(args, listen, (), mode="router")) as session:
        print(f"router: {session.zid()} listening on {list(listen)}", file=sys.stderr, flush=True)
        stop.wait()
    print("router: stopped", file=sys.stderr)
    return 0


# -- local launcher ------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _child_learner(config, handlers_set) -> None:
    # the launcher may stop the learner (SIGTERM) before it has imported torch and set its own
    # handler, e.g. a short --minutes on a loaded machine: remember the signal, stop cleanly later.
    # The launcher waits for ``handlers_set`` before it sends the signal.
    import threading

    early_stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: early_stop.set())
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the launcher, which sends SIGTERM
    handlers_set.set()
    from learner.service import run_learner

    sys.exit(run_learner(config, stop_requested=early_stop.is_set))


def check_resumed_views(run_dir, spec) -> None:
    """Refuse to resume a run whose weights learnt from another view square than ``spec`` shows
    (every actor would refuse its weights); a fresh run takes the views of its first actors."""
    from algo.policy import require_views
    from learner.service import newest_checkpoint

    checkpoint = newest_checkpoint(run_dir)
    if checkpoint is not None:
        require_views(checkpoint, (spec.views.extent_m, spec.views.shift_m), spec.name,
                      "resume it on a scenario with its [views], or give another --run-dir")


def _child_actor(config) -> None:
    from actors.worker import run_actor

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher stops actors with SIGTERM
    sys.exit(run_actor(config))


def run_train_command(args) -> int:
    import zenoh

    from learner.service import check_run_dir_free
    from protocol import keys
    from protocol.messages import DecodeError, LearnerStatus, decode
    from protocol.transport import TransportConfig, open_session
    from simcore.scenario import build_intersection, load_scenario

    if args.actors < 1:
        raise ValueError(f"--actors must be >= 1, got {args.actors}")
    if not args.minutes > 0:
        raise ValueError(f"--minutes must be > 0, got {args.minutes}")
    if args.curriculum == "yield" and args.actors < 2:
        raise ValueError("--curriculum yield needs --actors 2 or more (odd-numbered actors drive the drill)")
    port = args.port or _free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    lane_names = [lane.name for lane in build_intersection(load_scenario(args.scenario)).lanes]
    delay_max = args.delay_max
    if args.curriculum == "single" and delay_max is None:
        delay_max = 0.0  # alone on the road: no reason to wait
    learner_cfg = learner_config(args, (endpoint,), ())
    check_run_dir_free(args.run_dir)  # a learner already on it: refuse before progress.csv is touched
    check_resumed_views(args.run_dir, load_scenario(args.scenario))
    actor_cfgs = []
    for i in range(args.actors):
        lanes = (lane_names[i % len(lane_names)],) if args.curriculum == "single" else None
        drill = args.curriculum == "yield" and i % 2 == 1
        actor_cfgs.append(actor_config(args, (endpoint,), lanes, args.seed + i, f"local-{i}", delay_max,
                                       yield_drill=drill))
    args.run_dir.mkdir(parents=True, exist_ok=True)  # only once every option has been checked

    context = multiprocessing.get_context("spawn")  # Zenoh sessions do not survive fork
    learner_handlers_set = context.Event()
    learner = context.Process(target=_child_learner, args=(learner_cfg, learner_handlers_set),
                              name="crossway-learner")
    learner.start()
    actors = [context.Process(target=_child_actor, args=(cfg,), name=f"crossway-actor-{i}")
              for i, cfg in enumerate(actor_cfgs)]
    for process in actors:
        process.start()
    print(f"train: learner on {endpoint}, {args.actors} actor(s) on {args.scenario}"
          f"{CURRICULUM_NOTES[args.curriculum]}, run dir {args.run_dir}",
          file=sys.stderr)
    if args.metrics_port:
        print(f"train: Prometheus metrics at http://127.0.0.1:{args.metrics_port}/metrics", file=sys.stderr)

    interrupted = False

    def on_sigint(*_):
        nonlocal interrupted
        interrupted = True

    # SIGTERM (kill, pkill, a scheduler) stops the run as Ctrl-C does: without it the launcher died
    # alone and left its learner and actors running
    previous = signal.signal(signal.SIGINT, on_sigint)
    previous_term = signal.signal(signal.SIGTERM, on_sigint)
    progress_path = args.run_dir / "progress.csv"
    new_file = not progress_path.exists()
    started = time.monotonic()
    deadline = started + args.minutes * 60.0
    latest: LearnerStatus | None = None
    interactive = sys.stderr.isatty()
    last_line = 0.0
    by_scenario_path = args.run_dir / "progress-by-scenario.csv"
    new_by_scenario = not by_scenario_path.exists()
    with open(progress_path, "a", newline="") as handle, open(by_scenario_path, "a", newline="") as by_handle, \
            open_session(TransportConfig(connect=(endpoint,))) as session:
        writer = csv.writer(handle)
        by_writer = csv.writer(by_handle)
        if new_file:
            writer.writerow(["wall_s", "version", "agent_steps", "episodes", "reach_rate", "mean_speed_mps",
                             "agent_steps_per_s", "sigma", "live_actors", "rejected"])
        if new_by_scenario:  # one row per scenario label and status: the yield drill apart from hard
            by_writer.writerow(["wall_s", "version", "agent_steps", "scenario", "reach_rate"])
        subscriber = session.declare_subscriber(keys.status(args.run_name), zenoh.handlers.RingChannel(16))
        while (not interrupted and time.monotonic() < deadline and learner.is_alive()
               and any(process.is_alive() for process in actors)):
            sample = subscriber.try_recv()  # the newest status; the ring keeps the last few
            if sample is None:
                time.sleep(0.2)
                continue
            try:
                status = decode(sample.payload.to_bytes(), expect=LearnerStatus)
            except DecodeError:
                continue
            latest = status
            elapsed = time.monotonic() - started
            writer.writerow([round(elapsed, 1), status.version, status.agent_steps, status.episodes,
                             round(status.reach_rate, 4), round(status.mean_speed_mps, 3),
                             round(status.agent_steps_per_s, 1), round(status.sigma, 4), status.live_actors,
                             status.rejected])
            for label, rate in sorted(status.reach_by_scenario.items()):
                by_writer.writerow([round(elapsed, 1), status.version, status.agent_steps, label, round(rate, 4)])
            handle.flush()
            by_handle.flush()
            by_label = ""
            if len(status.reach_by_scenario) > 1:
                by_label = " (" + ", ".join(f"{label} {rate:.1%}"
                                            for label, rate in sorted(status.reach_by_scenario.items())) + ")"
            line = (f"train {int(elapsed // 60):02d}:{int(elapsed % 60):02d}  v{status.version}  "
                    f"{status.agent_steps:,} agent-steps ({status.agent_steps_per_s:,.0f}/s)  "
                    f"{status.episodes:,} episodes  reach {status.reach_rate:6.1%}{by_label}  "
                    f"speed {status.mean_speed_mps:4.1f} m/s  sigma {status.sigma:.3f}  "
                    f"actors {status.live_actors}/{args.actors}")
            if interactive:
                print("\r" + line, end="", file=sys.stderr, flush=True)
            elif time.monotonic() - last_line >= 10.0:
                print(line, file=sys.stderr, flush=True)
                last_line = time.monotonic()
        subscriber.undeclare()
    if interactive:
        print(file=sys.stderr)
    signal.signal(signal.SIGINT, previous)
    signal.signal(signal.SIGTERM, previous_term)
    actors_failed = not interrupted and learner.is_alive() and not any(process.is_alive() for process in actors)
    reason = ("interrupted" if interrupted else "learner exited" if not learner.is_alive()
              else "every actor exited (their messages are above)" if actors_failed else "time is up")
    print(f"train: {reason}; stopping actors, then the learner (it writes a checkpoint)", file=sys.stderr)
    for process in actors:
        if process.is_alive():
            process.terminate()
    for process in actors:
        process.join(timeout=30)
    if learner.is_alive():
        # a learner still starting would die of SIGTERM without its checkpoint: wait for its handler
        learner_handlers_set.wait(timeout=120)
        learner.terminate()
    learner.join(timeout=120)
    if latest is not None:
        print(f"train: version {latest.version}, {latest.agent_steps:,} agent-steps, {latest.episodes:,} "
              f"episodes, reach rate {latest.reach_rate:.1%} over the last episodes; progress in {progress_path}")
    return 0 if learner.exitcode == 0 and not actors_failed else 1
