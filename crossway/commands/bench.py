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

from crossway.commands import HelpFormatter


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
        formatter_class=HelpFormatter,
    )
    sim.add_argument("--scenario", default="hard", help="built-in scenario (easy, medium, hard) or a TOML path")
    sim.add_argument("--seconds", type=float, default=10.0, help="wall-clock time to measure [s]")
    sim.add_argument("--seed", type=int, default=0, help="random seed")
    sim.add_argument("--no-views", action="store_true", help="skip rendering (measures physics and rules only)")
    sim.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    sim.add_argument("--json", action="store_true",
                     help="print only the JSON object (default also prints it; the flag silences progress)")
    sim.set_defaults(func=run_sim)

    actor = benches.add_parser(
        "actor",
        help="one actor's agent-steps per second with D-A3C, against the bare network rate",
        description=(
            "Run one actor's loop without transport (simulator, every agent acting with its own "
            "local weights, local D-A3C updates every --update-interval steps) with every lane busy, "
            "and compare its agent-steps per second with the same network's bare forward+backward "
            "rate on the same batch (one update segment), timed as torch modules and in the matrix "
            "form the actor uses; the faster of the two is the bar. Pinned to one core, one torch thread."
        ),
        formatter_class=HelpFormatter,
    )
    actor.add_argument("--scenario", default="hard", help="built-in scenario or a TOML path")
    actor.add_argument("--seconds", type=float, default=20.0, help="wall-clock time to measure [s]")
    actor.add_argument("--update-interval", type=int, default=20, help="steps between local updates")
    actor.add_argument("--seed", type=int, default=0, help="random seed")
    actor.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    actor.add_argument("--json", action="store_true", help="print only the JSON object")
    actor.set_defaults(func=run_actor_bench)

    policy = benches.add_parser(
        "policy",
        help="an evaluation driver's forward passes per second for a checkpoint",
        description=(
            "Time the network as every 'crossway evaluate' drives with it (evaluation.policy.PolicyDriver: "
            "the matrix form of algo.stacked over the distinct patches and windows of the views, --cars "
            "cars per call). The views are a simulator's (--scenario driven by the scripted driver, the "
            "cars on the road at each step; default) or noise (--views noise, where no two patches are "
            "equal: the slowest case). A network no wider than one of the paper's sizes is driven with "
            "every patch multiplied. Also timed for comparison: 'full_product', every patch multiplied "
            "(the driver before session 39, and still for one network), and for a checkpoint that "
            "splits into equal members (an output ensemble, docs/scripts/ensemble.py) 'joined', the "
            "one joined network with its zero blocks multiplied. Pinned to one core, one torch thread."
        ),
        formatter_class=HelpFormatter,
    )
    policy.add_argument("--checkpoint", required=True, help="a checkpoint or models/*.pt policy")
    policy.add_argument("--cars", type=int, default=8, help="cars per forward pass (hard has 8 lanes)")
    policy.add_argument("--views", choices=("simulator", "noise"), default="simulator",
                        help="simulator: views of --scenario's cars as they drive; noise: uniform random bytes")
    policy.add_argument("--scenario", default="hard", help="with --views simulator: built-in scenario or a TOML path")
    policy.add_argument("--seconds", type=float, default=5.0, help="wall-clock time to measure each form [s]")
    policy.add_argument("--seed", type=int, default=0, help="random seed of the simulator or the noise")
    policy.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    policy.add_argument("--json", action="store_true", help="print only the JSON object")
    policy.set_defaults(func=run_policy_bench)

    learner = benches.add_parser(
        "learner",
        help="gradient pushes applied per second from synthetic pushes over Zenoh",
        description=(
            "Start a learner (this process, one torch thread, pinned to one core) and a pusher process "
            "that sends pre-encoded synthetic gradient pushes over Zenoh on loopback as fast as it can; "
            "report pushes applied per second, pushes dropped by the bounded queue, and the learner "
            "process's resident memory at the start and the end."
        ),
        formatter_class=HelpFormatter,
    )
    learner.add_argument("--seconds", type=float, default=20.0, help="wall-clock time to measure [s]")
    learner.add_argument("--queue-size", type=int, default=64, help="learner's bounded push queue")
    learner.add_argument("--no-pin", action="store_true", help="do not pin the learner to one CPU core")
    learner.add_argument("--json", action="store_true", help="print only the JSON object")
    learner.set_defaults(func=run_learner_bench)


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


def recorded_views(scenario: str, cars: int, seed: int, batches: int = 40) -> list[tuple[np.ndarray, np.ndarray]]:
    """``batches`` batches of ``cars`` cars' views and scalars as a simulator shows them: the
    scripted driver drives ``scenario`` with every lane busy, and each batch is the views of the
    cars on the road at one step (steps with fewer cars are skipped; every 5th step kept)."""
    from simcore.controller import ScriptedDriver
    from simcore.simulator import SimConfig, Simulator

    sim = Simulator(scenario, SimConfig(delay_min_s=0.0, delay_max_s=0.0), seed=seed)
    if sim.num_slots < cars:
        raise ValueError(f"--cars {cars}: {scenario} has only {sim.num_slots} lanes")
    driver = ScriptedDriver(sim)
    sim.reset()
    found: list[tuple[np.ndarray, np.ndarray]] = []
    for step in range(100 * batches):
        result = sim.step(driver.act())
        active = np.flatnonzero(sim.learners_present)
        if step % 5 == 0 and len(active) >= cars:
            found.append((result.views[active[:cars]].copy(), result.scalars[active[:cars]].copy()))
            if len(found) == batches:
                return found
    raise ValueError(f"--cars {cars}: fewer than {batches} steps of {scenario} had that many cars on the road")


def run_policy_bench(args) -> int:
    import torch

    from algo.policy import load_policy
    from algo.stacked import forward_full, unique_patches
    from evaluation.parallel import numeric_platform
    from evaluation.policy import PolicyDriver

    if not args.seconds > 0 or args.cars < 1:
        raise ValueError("--seconds must be > 0 and --cars >= 1")
    policy = load_policy(args.checkpoint)  # a clear error for a file that is not a policy
    cpu = None if args.no_pin else pin_to_one_core()
    torch.set_num_threads(1)
    if args.views == "simulator":
        batches = recorded_views(args.scenario, args.cars, args.seed)
    else:
        rng = np.random.default_rng(args.seed)
        batches = [(rng.integers(0, 256, (args.cars, 16, 84, 84), dtype=np.uint8),
                    np.column_stack([rng.uniform(0, 10, args.cars), np.full(args.cars, 8.0),
                                     rng.uniform(0, 5, args.cars)]).astype(np.float32)) for _ in range(4)]
    driver = PolicyDriver(None, policy)
    k = driver.members

    def full_product(views, scalars):  # every patch through the first layer, F.conv2d after it
        with torch.no_grad():
            return forward_full(torch.from_numpy(views), torch.from_numpy(np.ascontiguousarray(scalars, np.float32)),
                                driver._params, driver._first_layer)

    forms = {"as_driven": driver.heads, "full_product": full_product}
    if k > 1:
        forms["joined"] = PolicyDriver(None, policy, members=1).heads
    distinct = [len(unique_patches(torch.from_numpy(views))[0]) / (len(views) * 441) for views, _ in batches]
    report = {"bench": "policy", "checkpoint": str(args.checkpoint), "members": k,
              "network": [policy.config.conv1_channels, policy.config.conv2_channels, policy.config.hidden],
              "cars_per_call": args.cars, "views": args.views,
              "scenario": args.scenario if args.views == "simulator" else None,
              "distinct_patch_fraction": round(float(np.mean(distinct)), 4)}
    for form in forms.values():
        for views, scalars in batches[:5]:  # warm-up
            form(views, scalars)
    # the forms take turns in rounds of about 0.5 s, so a slower spell of a shared machine falls on
    # each of them alike; each form's rate is the median of its rounds
    rounds = max(3, round(args.seconds / 0.5))
    rates: dict[str, list[float]] = {name: [] for name in forms}
    calls = dict.fromkeys(forms, 0)
    for _ in range(rounds):
        for name, form in forms.items():
            done = 0
            started = time.perf_counter()
            while (elapsed := time.perf_counter() - started) < args.seconds / rounds or done < 3:
                form(*batches[(calls[name] + done) % len(batches)])
                done += 1
            calls[name] += done
            rates[name].append(done / elapsed)
    for name in forms:
        rate = float(np.median(rates[name]))
        report[f"{name}_calls_per_s"] = round(rate, 2)
        report[f"{name}_ms_per_car"] = round(1000.0 / rate / args.cars, 4)
        if not args.json:
            print(f"bench policy: {name}: {rate:.1f} calls/s (median of {rounds} rounds)", file=sys.stderr)
    report["speedup_over_full_product"] = round(report["as_driven_calls_per_s"] / report["full_product_calls_per_s"], 3)
    report.update({"cpu_pinned": cpu, "torch": torch.__version__, "python": platform.python_version(),
                   "platform": numeric_platform()})  # the kernels these timings ran on (MKL's path)
    print(json.dumps(report))
    return 0


def current_rss_bytes() -> int:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run_actor_bench(args) -> int:
    import torch

    from algo.d_a3c import ActorCore, DA3CConfig
    from algo.policy import Policy, preprocess
    from algo.stacked import after_conv1, conv1, first_layer_matrix, patches
    from evaluation.parallel import numeric_platform
    from learner.core import LearnerCore
    from simcore.simulator import SimConfig, Simulator

    if not args.seconds > 0 or args.update_interval < 1:
        raise ValueError("--seconds must be > 0 and --update-interval >= 1")
    cpu = None if args.no_pin else pin_to_one_core()
    torch.set_num_threads(1)
    sim = Simulator(args.scenario, SimConfig(delay_min_s=0.0, delay_max_s=0.0), seed=args.seed)
    core = ActorCore(sim, config=DA3CConfig(update_interval=args.update_interval), seed=args.seed)
    core.set_weights(0, 0.65, LearnerCore().weights())
    core.reset()
    for _ in range(3 * args.update_interval):  # warm-up: every agent has updated once
        core.step()
    # time the simulator's share apart: the rest is acting, updating and bookkeeping
    simulator_step = sim.step
    simulator_seconds = 0.0

    def timed_step(actions):
        nonlocal simulator_seconds
        t0 = time.perf_counter()
        result = simulator_step(actions)
        simulator_seconds += time.perf_counter() - t0
        return result

    sim.step = timed_step
    steps_before = core.agent_steps
    started = time.perf_counter()
    while time.perf_counter() - started < args.seconds:
        core.step()
    elapsed = time.perf_counter() - started
    actor_steps = core.agent_steps - steps_before
    actor_rate = actor_steps / elapsed
    learning_rate = actor_steps / (elapsed - simulator_seconds)  # agent-steps per second outside the simulator

    # the bare rate: forward and backward of the same network on one update segment, timed both
    # as torch modules and in the matrix form the actor uses (algo.stacked); the faster is the bar
    policy = Policy()
    batch = args.update_interval + 1
    raw = np.random.randint(0, 256, (batch, 16, 84, 84), dtype=np.uint8)
    speeds = np.full((batch, 2), 8.0, np.float32)
    views, scalars = preprocess(raw, speeds)

    def modules_pass():
        policy.zero_grad()
        sum(out.sum() for out in policy(views, scalars)).backward()

    rows = patches(torch.from_numpy(raw))
    leaves = {name: p.detach().clone().requires_grad_(True) for name, p in policy.named_parameters()}
    stacked = {name: leaf.unsqueeze(0) for name, leaf in leaves.items()}
    speeds_t = torch.from_numpy(speeds)[None]

    def matrix_pass():
        pre1 = conv1(rows, *first_layer_matrix(leaves))
        mu, value = after_conv1(pre1[None], speeds_t, stacked)
        for leaf in leaves.values():
            leaf.grad = None
        (mu.sum() + value.sum()).backward()

    bare_rates = {}
    for name, one_pass in (("modules", modules_pass), ("matrix", matrix_pass)):
        one_pass()  # warm-up
        samples = 0
        started = time.perf_counter()
        while time.perf_counter() - started < min(args.seconds, 10.0) / 2:
            one_pass()
            samples += batch
        bare_rates[name] = samples / (time.perf_counter() - started)
    bare_rate = max(bare_rates.values())
    report = {
        "bench": "actor", "scenario": sim.spec.name, "lanes": sim.num_slots,
        "agent_steps_per_s": round(actor_rate, 1),
        "bare_forward_backward_samples_per_s": round(bare_rate, 1),
        "bare_modules_samples_per_s": round(bare_rates["modules"], 1),
        "bare_matrix_samples_per_s": round(bare_rates["matrix"], 1),
        "ratio_to_bare": round(actor_rate / bare_rate, 3),
        "simulator_share": round(simulator_seconds / elapsed, 3),
        "agent_steps_per_s_outside_simulator": round(learning_rate, 1),
        "ratio_to_bare_outside_simulator": round(learning_rate / bare_rate, 3),
        "update_interval": args.update_interval, "batch": batch,
        "parameters": sum(p.numel() for p in policy.parameters()),
        "cpu_pinned": cpu, "torch_threads": torch.get_num_threads(),
        "peak_rss_bytes": peak_rss_bytes(), "torch": torch.__version__, "platform": numeric_platform(),
    }
    print(json.dumps(report))
    return 0


def _pusher(endpoint: str, run_name: str, payload: bytes, stop_after_s: float) -> None:
    """Child process: put the same valid push as fast as Zenoh takes it."""
    import zenoh

    from protocol import keys
    from protocol.transport import TransportConfig, open_session

    with open_session(TransportConfig(connect=(endpoint,))) as session:
        publisher = session.declare_publisher(keys.gradients(run_name),
                                              congestion_control=zenoh.CongestionControl.DROP)
        time.sleep(1.0)
        deadline = time.monotonic() + stop_after_s
        while time.monotonic() < deadline:
            publisher.put(payload)


def run_learner_bench(args) -> int:
    import multiprocessing
    import tempfile
    import threading
    from pathlib import Path

    import torch

    from learner.core import LearnerConfig
    from learner.service import LearnerService, LearnerServiceConfig
    from protocol.messages import EpisodeStats, GradientPush, encode
    from protocol.transport import TransportConfig

    if not args.seconds > 0 or args.queue_size < 1:
        raise ValueError("--seconds must be > 0 and --queue-size >= 1")
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    run_dir = Path(tempfile.mkdtemp(prefix="crossway-bench-"))
    service = LearnerService(LearnerServiceConfig(
        run_dir=run_dir, transport=TransportConfig(listen=(endpoint,)), metrics_port=0,
        checkpoint_interval_s=1e9, queue_size=args.queue_size,
        learner=LearnerConfig(max_staleness=10**9)), log=lambda _: None)
    torch.set_num_threads(1)
    gradients = {name: (np.random.standard_normal(shape) * 1e-3).astype(np.float32)
                 for name, shape in service.core.shapes.items()}
    stats = EpisodeStats("easy", "south_0", "none", "goal", 100, 8.0, 1.0, 1.0, "left")
    payload = encode(GradientPush(actor_id="bench", base_version=0, agent_steps=100, tensors=gradients,
                                  episodes=(stats,)))
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    context = multiprocessing.get_context("spawn")
    pusher = context.Process(target=_pusher, args=(endpoint, "default", payload, args.seconds + 5.0))
    pusher.start()  # before pinning: the pusher keeps every core this process was allowed
    cpu = None if args.no_pin else pin_to_one_core()
    # wait for the first push, then measure
    deadline = time.monotonic() + 30.0
    while service.core.version == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    rss_start = current_rss_bytes()
    version_start, started = service.core.version, time.perf_counter()
    samples = []
    while time.perf_counter() - started < args.seconds:
        time.sleep(0.5)
        samples.append(current_rss_bytes())
    applied = service.core.version - version_start
    elapsed = time.perf_counter() - started
    service.stop()
    thread.join(timeout=30)
    pusher.terminate()
    pusher.join(timeout=10)
    report = {
        "bench": "learner", "pushes_applied_per_s": round(applied / elapsed, 1),
        "push_bytes": len(payload), "pushes_dropped": int(service.metrics.dropped._value.get()),
        "queue_size": args.queue_size, "rejected": service._rejected,
        "rss_start_bytes": rss_start, "rss_end_bytes": samples[-1] if samples else rss_start,
        "rss_max_bytes": max(samples) if samples else rss_start, "peak_rss_bytes": peak_rss_bytes(),
        "cpu_pinned": cpu, "torch_threads": torch.get_num_threads(), "measured_s": round(elapsed, 2),
    }
    print(json.dumps(report))
    return 0
