"""Learner and actors over real Zenoh sessions on loopback (multicast scouting off, explicit
endpoints): weights out, gradients in, actors dying, the learner restarting, the CLI."""

import csv
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from learner.service import LearnerService, LearnerServiceConfig
from protocol import keys
from protocol.messages import LearnerStatus, decode
from protocol.transport import TransportConfig, open_session


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_actor(endpoint: str, actor_id: str, *extra, delay_max: str | None = "0.5") -> subprocess.Popen:
    waits = ("--delay-max", delay_max) if delay_max is not None else ()
    return subprocess.Popen(
        [sys.executable, "-m", "crossway", "actor", "--connect", endpoint, "--id", actor_id,
         "--scenario", "easy", *waits, "--update-interval", "10", "--seed", "1", *extra],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


@pytest.fixture
def learner(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path, transport=TransportConfig(listen=(endpoint,)), metrics_port=0,
        checkpoint_interval_s=3600, publish_interval_s=0.2), log=lambda _: None)
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    yield service, endpoint, thread
    service.stop()
    thread.join(timeout=30)


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()


def test_learner_and_two_actors_exchange_weights_and_gradients(learner):
    service, endpoint, _ = learner
    actors = [start_actor(endpoint, f"actor-{i}") for i in range(2)]
    try:
        wait_for(lambda: len(service._live_actors) == 2, 60, "two liveliness tokens")
        wait_for(lambda: len(service.pushes_by_actor) == 2 and service.core.version >= 12, 120,
                 "pushes from both actors")
        # actors picked up newer weights: later pushes started from versions above 0
        wait_for(lambda: service.newest_base_version > 0, 60, "a push computed on published weights")
        assert service._rejected == 0
        assert service.metrics.rolling_mean_speed > 0.0
    finally:
        for process in actors:
            stop(process)
    wait_for(lambda: len(service._live_actors) == 0, 30, "liveliness tokens to go")


def test_an_actor_killed_mid_episode_leaves_the_learner_running(learner):
    service, endpoint, thread = learner
    survivor, victim = start_actor(endpoint, "survivor"), start_actor(endpoint, "victim")
    try:
        wait_for(lambda: service.pushes_by_actor.get("victim", 0) >= 2, 120, "the victim's pushes")
        victim.send_signal(signal.SIGKILL)
        victim.wait(timeout=10)
        wait_for(lambda: "victim" not in service._live_actors, 30, "the victim's token to go")
        version = service.core.version
        wait_for(lambda: service.core.version >= version + 5, 120, "updates after the kill")
        assert thread.is_alive()
        assert service.pushes_by_actor.get("survivor", 0) > 0
    finally:
        stop(survivor)
        stop(victim)


def test_a_yield_drill_actor_drives_from_the_stop_arm_among_traffic(learner):
    """--yield-drill: learners only on hard's stop-sign arm; IDM traffic on the main road."""
    service, endpoint, _ = learner
    actor = start_actor(endpoint, "drill", "--scenario", "hard", "--yield-drill", delay_max=None)
    try:
        wait_for(lambda: service.pushes_by_actor.get("drill", 0) >= 6, 180, "the drill's pushes")
    finally:
        stop(actor)
    assert service._rejected == 0
    finished = {(s.labels["scenario"], s.labels["sign"]): s.value
                for metric in service.metrics.episodes.collect() for s in metric.samples
                if s.name.endswith("_total") and s.value > 0}
    # every learner started at the stop sign; the drill's episodes are counted apart from hard's
    assert finished and set(finished) == {("hard-yield-drill", "stop")}
    assert set(service.status().reach_by_scenario) == {"hard-yield-drill"}


@pytest.mark.parametrize("bad, message", [(("--scenario", "easy"), "the yield drill runs on the hard junction"),
                                          (("--scenario", "hard", "--delay-max", "5"), "leave out --delay-max"),
                                          (("--scenario", "hard", "--lanes", "south_0"), "leave out --lanes")])
def test_an_actor_refuses_a_yield_drill_it_cannot_run(bad, message):
    result = subprocess.run([sys.executable, "-m", "crossway", "actor", "--yield-drill", *bad,
                             "--connect", f"tcp/127.0.0.1:{free_port()}"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and message in result.stderr


def learner_process(run_dir: Path, endpoint: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "crossway", "learner", "--run-dir", str(run_dir), "--listen", endpoint,
         "--metrics-port", "0", "--checkpoint-interval", "3600"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )


def test_a_restarted_learner_resumes_its_version_and_actors_rejoin(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    statuses: list[LearnerStatus] = []
    with open_session(TransportConfig(connect=(endpoint,))) as session:
        session.declare_subscriber(keys.status("default"),
                                   lambda sample: statuses.append(decode(sample.payload.to_bytes())))
        first = learner_process(tmp_path, endpoint)
        actor = start_actor(endpoint, "steady")
        try:
            wait_for(lambda: statuses and statuses[-1].version >= 8, 120, "updates before the restart")
            first.send_signal(signal.SIGTERM)
            _, log = first.communicate(timeout=60)
            assert first.returncode == 0, log
            stopped_at = int(log.rsplit("stopped at version ", 1)[1].split(";")[0])
            assert stopped_at >= 8
            assert list((tmp_path / "checkpoints").glob("ckpt-*.pt"))
            statuses.clear()
            second = learner_process(tmp_path, endpoint)
            try:
                wait_for(lambda: statuses and statuses[-1].version >= stopped_at + 5, 120,
                         "the same actor's updates after the restart")
                assert min(s.version for s in statuses) >= stopped_at  # the count went on
                assert actor.poll() is None  # the actor rode out the restart
            finally:
                second.send_signal(signal.SIGTERM)
                _, log = second.communicate(timeout=60)
            assert "resumed from" in log and f"at version {stopped_at}" in log
        finally:
            stop(actor)
            stop(first)


def test_train_command_smoke(tmp_path):
    run_dir = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--actors", "1", "--minutes", "0.4",
         "--run-dir", str(run_dir), "--metrics-port", "0", "--delay-max", "0.5", "--noise-correlation", "0.9",
         "--acceleration-cost", "0.02", "--gamma", "0.998"],
        capture_output=True, text=True, timeout=180,
    )
    assert result.returncode == 0, result.stderr
    assert "time is up" in result.stderr
    rows = (run_dir / "progress.csv").read_text().splitlines()
    assert rows[0].startswith("wall_s,version,agent_steps")
    assert len(rows) >= 3
    by_scenario = list(csv.DictReader(open(run_dir / "progress-by-scenario.csv")))
    assert by_scenario and {row["scenario"] for row in by_scenario} == {"easy"}
    assert all(0.0 <= float(row["reach_rate"]) <= 1.0 for row in by_scenario)
    assert list((run_dir / "checkpoints").glob("ckpt-*.pt"))


def test_train_stopped_while_the_learner_is_still_starting_exits_cleanly(tmp_path):
    # 0.6 s: the launcher sends SIGTERM while the learner process is still importing torch
    run_dir = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--actors", "1", "--minutes", "0.01",
         "--run-dir", str(run_dir), "--metrics-port", "0"],
        capture_output=True, text=True, timeout=180,
    )
    assert result.returncode == 0, result.stderr
    assert "time is up" in result.stderr and "Traceback" not in result.stderr
    assert "learner: stopped at version 0" in result.stderr
    assert list((run_dir / "checkpoints").glob("ckpt-*.pt"))  # the initial weights, ready to resume from


@pytest.mark.parametrize("bad, message", [(("--actors", "0"), "--actors"),
                                          (("--noise-correlation", "1.0"), "--noise-correlation must be in [0, 1)"),
                                          (("--acceleration-cost", "-1"), "--acceleration-cost must be >= 0"),
                                          (("--value-coef", "0"), "--value-coef must be > 0"),
                                          (("--local-learning-rate", "-0.001"), "--local-learning-rate must be >= 0"),
                                          (("--gamma", "1.5"), "--gamma must be in (0, 1]"),
                                          (("--gamma", "0"), "--gamma must be in (0, 1]"),
                                          (("--gae-lambda", "-0.1"), "--gae-lambda must be in [0, 1]"),
                                          (("--curriculum", "yield", "--actors", "1", "--scenario", "hard"),
                                           "--curriculum yield needs --actors 2"),
                                          (("--curriculum", "yield", "--actors", "2", "--scenario", "easy"),
                                           "the yield drill runs on the hard junction")])
def test_train_rejects_bad_arguments(tmp_path, bad, message):
    result = subprocess.run([sys.executable, "-m", "crossway", "train", *bad, "--run-dir", str(tmp_path / "run"),
                             "--metrics-port", "0"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and message in result.stderr
    assert not (tmp_path / "run").exists()  # refused before anything started


def test_bad_pushes_are_counted_by_reason_and_metrics_are_served(tmp_path):
    import urllib.request

    import numpy as np

    from protocol.messages import EpisodeStats, GradientPush, encode

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    metrics_port = free_port()
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path, transport=TransportConfig(listen=(endpoint,)), metrics_port=metrics_port,
        metrics_address="127.0.0.1", checkpoint_interval_s=3600), log=lambda _: None)
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    good = {name: np.zeros(shape, np.float32) for name, shape in service.core.shapes.items()}
    wrong_shape = dict(good, **{next(iter(good)): np.zeros((1, 2), np.float32)})
    stats = (EpisodeStats("easy", "south_0", "stop", "goal", 10, 7.5, 1.0, 1.0, "left"),)
    try:
        with open_session(TransportConfig(connect=(endpoint,))) as session:
            time.sleep(1.0)
            key = keys.gradients("default")
            block = zenoh.CongestionControl.BLOCK
            session.put(key, b"\x93not a push", congestion_control=block)
            session.put(key, encode(GradientPush("x", 0, 10, wrong_shape, stats)), congestion_control=block)
            session.put(key, encode(GradientPush("x", 0, 10, good, stats, view_extent_m=50.0)),
                        congestion_control=block)
            wait_for(lambda: service.core.version == 1 and service._rejected == 2, 30, "one applied, two refused")
            assert service.core.views == (50.0, 0.0)  # the first push that says fixes the run's view square
            # an actor whose scenario shows a 70 m square: its gradient belongs to other inputs
            session.put(key, encode(GradientPush("wide", 1, 10, good, stats, view_extent_m=70.0, view_shift_m=15.0)),
                        congestion_control=block)
            wait_for(lambda: service._rejected == 3, 30, "the other view square refused")
            served = decode(next(iter(session.get(keys.weights("default"), timeout=10))).ok.payload.to_bytes())
            assert (served.version, served.view_extent_m, served.view_shift_m) == (1, 50.0, 0.0)
        assert thread.is_alive()
        text = urllib.request.urlopen(f"http://127.0.0.1:{metrics_port}/metrics", timeout=10).read().decode()
        assert 'crossway_rejected_messages_total{reason="malformed"} 1.0' in text
        assert 'crossway_rejected_messages_total{reason="shape"} 1.0' in text
        assert 'crossway_rejected_messages_total{reason="views"} 1.0' in text
        assert 'crossway_episodes_total{end_reason="goal",scenario="easy",sign="stop"} 1.0' in text
        assert "crossway_weights_version 1.0" in text
        for name in ("crossway_updates_total", "crossway_gradient_staleness_versions_bucket", "crossway_live_actors",
                     "crossway_agent_steps_total", "crossway_sigma", "crossway_reach_rate_ratio"):
            assert name in text
    finally:
        service.stop()
        thread.join(timeout=30)


def test_train_stops_cleanly_on_ctrl_c_and_leaves_a_checkpoint(tmp_path):
    run_dir = tmp_path / "run"
    process = subprocess.Popen(
        [sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--actors", "1", "--minutes", "5",
         "--run-dir", str(run_dir), "--metrics-port", "0", "--delay-max", "0.5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        progress = run_dir / "progress.csv"
        wait_for(lambda: progress.exists() and len(progress.read_text().splitlines()) >= 3, 120,
                 "progress rows")
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, err
    assert "interrupted" in err
    assert list((run_dir / "checkpoints").glob("ckpt-*.pt"))


def test_a_new_run_starts_from_given_weights_and_a_resumed_run_ignores_them(tmp_path):
    """--init-from: a curriculum across scenarios (easy weights to start medium)."""
    import numpy as np
    import torch

    from learner.core import LearnerCore

    source = LearnerCore(seed=7)
    source.apply({n: np.ones_like(w) for n, w in source.weights().items()}, 0, 10)
    init = tmp_path / "init.pt"
    torch.save(source.state_dict(), init)
    config = LearnerServiceConfig(run_dir=tmp_path / "run", metrics_port=0, init_from=init,
                                  transport=TransportConfig(listen=(f"tcp/127.0.0.1:{free_port()}",)))
    logs: list[str] = []
    service = LearnerService(config, log=logs.append)
    assert service.core.version == 0  # a new run: its own version count
    for name, weights in source.weights().items():
        np.testing.assert_array_equal(service.core.weights()[name], weights)
    assert any("starting from the weights in" in line for line in logs)
    service.close()  # it never ran: give up the run directory's lock by hand
    # a run directory with a checkpoint resumes from it, not from --init-from
    resumed = LearnerCore(seed=3)
    resumed.version = 42
    (config.run_dir / "checkpoints").mkdir(parents=True)
    torch.save(resumed.state_dict(), config.run_dir / "checkpoints" / "ckpt-000000042.pt")
    service = LearnerService(config, log=logs.append)
    assert service.core.version == 42
    np.testing.assert_array_equal(service.core.weights()["acc.hidden.weight"], resumed.weights()["acc.hidden.weight"])


def test_an_actor_refuses_a_run_that_learns_from_another_view_square(tmp_path):
    """A run resumed with its view square (a 70 m window placed 15 m ahead) meets an actor on
    plain easy (the paper's 50 m, centred): the actor stops with a message, pushing nothing."""
    import torch

    from actors.worker import EXIT_VIEWS_MISMATCH
    from learner.core import LearnerCore

    wide = LearnerCore(seed=1)
    wide.views = (70.0, 15.0)
    (tmp_path / "checkpoints").mkdir()
    torch.save(wide.state_dict(), tmp_path / "checkpoints" / "ckpt-000000000.pt")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    service = LearnerService(LearnerServiceConfig(
        run_dir=tmp_path, transport=TransportConfig(listen=(endpoint,)), metrics_port=0,
        checkpoint_interval_s=3600), log=lambda _: None)
    assert service.core.views == (70.0, 15.0)
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    actor = start_actor(endpoint, "narrow")
    try:
        _, err = actor.communicate(timeout=90)
        assert actor.returncode == EXIT_VIEWS_MISMATCH, err
        assert "learns from views 70 m wide, centred 15 m ahead" in err and "shows views 50 m wide" in err
        assert service.core.version == 0 and not service.pushes_by_actor
    finally:
        stop(actor)
        service.stop()
        thread.join(timeout=30)


def test_train_refuses_to_resume_a_run_on_another_view_square(tmp_path):
    import torch

    from learner.core import LearnerCore

    wide = LearnerCore(seed=1)
    wide.views = (70.0, 15.0)
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    torch.save(wide.state_dict(), tmp_path / "run" / "checkpoints" / "ckpt-000000000.pt")
    done = subprocess.run([sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--minutes", "1",
                           "--run-dir", str(tmp_path / "run"), "--metrics-port", "0"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert "learnt from views 70 m wide, centred 15 m ahead of the car" in done.stderr
    assert "another --run-dir" in done.stderr


def test_a_resumed_run_goes_on_with_its_episode_count_and_rolling_reach_rate(tmp_path):
    """progress.csv after a resume: no restart from an empty window (a dip to 0 in the curves)."""
    config = LearnerServiceConfig(run_dir=tmp_path / "run", metrics_port=0,
                                  transport=TransportConfig(listen=(f"tcp/127.0.0.1:{free_port()}",)))
    first = LearnerService(config, log=lambda line: None)
    for index in range(250):  # more than the window: the oldest fall out
        reason = "goal" if index % 4 else "crash"
        first.metrics.record_episode("easy", "none", reason, 5.0 + index % 3)
        first._episodes += 1
    before = first.status()
    assert before.episodes == 250 and 0.0 < before.reach_rate < 1.0
    first.checkpoint()
    first.close()
    second = LearnerService(config, log=lambda line: None)
    after = second.status()
    assert after.episodes == 250
    assert after.reach_rate == pytest.approx(before.reach_rate)
    assert after.mean_speed_mps == pytest.approx(before.mean_speed_mps)
    window = [index % 4 != 0 for index in range(50, 250)]  # the newest 200 before the checkpoint
    assert after.reach_rate == pytest.approx(sum(window) / 200)
    second.metrics.record_episode("easy", "none", "crash", 5.0)  # index 50 (a goal) drops out
    assert second.status().reach_rate == pytest.approx(sum(window[1:]) / 200)


def test_the_learner_keeps_a_reach_rate_per_scenario_label_across_a_resume(tmp_path):
    """The yield drill's episodes (scenario label hard-yield-drill) have their own rolling reach rate,
    in the status, in Prometheus, and in a checkpoint."""
    config = LearnerServiceConfig(run_dir=tmp_path / "run", metrics_port=0,
                                  transport=TransportConfig(listen=(f"tcp/127.0.0.1:{free_port()}",)))
    first = LearnerService(config, log=lambda line: None)
    for index in range(40):
        first.metrics.record_episode("hard", "none", "goal" if index % 4 else "crash", 8.0)  # 30 of 40
        first.metrics.record_episode("hard-yield-drill", "stop", "goal" if index % 2 else "crash", 6.0)  # 20 of 40
    assert first.status().reach_by_scenario == {"hard": 0.75, "hard-yield-drill": 0.5}
    assert first.status().reach_rate == pytest.approx(50 / 80)
    gauge = {s.labels["scenario"]: s.value for metric in first.metrics.reach_rate_by_scenario.collect()
             for s in metric.samples}
    assert gauge == {"hard": 0.75, "hard-yield-drill": 0.5}
    first.checkpoint()
    first.close()
    second = LearnerService(config, log=lambda line: None)
    assert second.status().reach_by_scenario == {"hard": 0.75, "hard-yield-drill": 0.5}


def test_train_refuses_initial_weights_that_are_not_a_checkpoint(tmp_path):
    bogus = tmp_path / "bogus.pt"
    bogus.write_text("not a checkpoint")
    result = subprocess.run([sys.executable, "-m", "crossway", "train", "--run-dir", str(tmp_path / "run"),
                             "--init-from", str(bogus), "--metrics-port", "0"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert "bogus.pt is not a crossway checkpoint" in result.stderr
    assert not (tmp_path / "run" / "checkpoints").exists()  # nothing started


def test_train_refuses_initial_weights_of_another_network(tmp_path):
    """A student with the standing-time input (or widened) cannot start D-A3C, which learns the
    paper's network: refused before any process starts, not after the actors are up."""
    from dataclasses import asdict

    import torch

    from algo.policy import Policy, PolicyConfig

    clocked = tmp_path / "clocked.pt"
    policy = Policy(PolicyConfig(standing_input=True))
    torch.save({"policy": policy.state_dict(), "policy_config": asdict(policy.config)}, clocked)
    result = subprocess.run([sys.executable, "-m", "crossway", "train", "--run-dir", str(tmp_path / "run"),
                             "--init-from", str(clocked), "--metrics-port", "0"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "'standing_input': True" in result.stderr and "goes on with crossway pretrain" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "run" / "checkpoints").exists()


def test_actor_options_reach_the_agents_config():
    """--gamma and the other agent-side options end up in the D-A3C config the actor runs with."""
    from crossway.cli import build_parser
    from crossway.commands.distributed import actor_config

    args = build_parser().parse_args(["actor", "--scenario", "hard", "--gamma", "0.998", "--noise-correlation", "0.9",
                                      "--acceleration-cost", "0.01", "--value-coef", "2", "--gae-lambda", "0.9",
                                      "--local-learning-rate", "0"])
    config = actor_config(args, ("tcp/127.0.0.1:7447",), None, 0, "a", None)
    assert (config.da3c.gamma, config.da3c.noise_correlation) == (0.998, 0.9)
    assert (config.da3c.acceleration_cost, config.da3c.value_coef, config.da3c.gae_lambda) == (0.01, 2.0, 0.9)
    assert config.da3c.local_learning_rate == 0.0
    default = actor_config(build_parser().parse_args(["actor"]), ("tcp/127.0.0.1:7447",), None, 0, "a", None)
    assert default.da3c.gamma == 0.99  # the paper gives no discount; ours stays the default
    assert default.da3c.gae_lambda == 1.0  # the paper's advantage
    assert default.da3c.local_learning_rate == 1e-3


def test_train_stopped_by_sigterm_stops_its_learner_and_actors(tmp_path):
    """kill/pkill on the launcher ends the whole run: no learner or actor is left driving."""
    run_dir, log_path = tmp_path / "run", tmp_path / "train.log"
    with open(log_path, "w") as log:
        launcher = subprocess.Popen(
            [sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--actors", "2", "--minutes", "5",
             "--run-dir", str(run_dir), "--metrics-port", "0"],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while "driving" not in log_path.read_text() and time.monotonic() < deadline:
            time.sleep(0.5)
        assert "driving" in log_path.read_text()
        launcher.send_signal(signal.SIGTERM)
        assert launcher.wait(timeout=180) == 0
        text = log_path.read_text()
        assert "train: interrupted" in text and "learner: stopped at version" in text
        left = subprocess.run(["ps", "-o", "pid,stat,args", "-g", str(launcher.pid)], capture_output=True, text=True)
        running = [line for line in left.stdout.splitlines()[1:] if line.split()[1][0] != "Z"]
        assert not running, left.stdout  # nothing of the run's session is left running (zombies await init)
        assert list((run_dir / "checkpoints").glob("ckpt-*.pt"))
    finally:
        try:
            os.killpg(launcher.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_a_second_learner_on_the_same_run_dir_is_refused_until_the_first_is_gone(tmp_path):
    """Two learners writing one run directory would overwrite each other's checkpoints."""
    from learner.service import RunDirInUse, check_run_dir_free

    first = learner_process(tmp_path, f"tcp/127.0.0.1:{free_port()}")
    try:
        wait_for(lambda: (tmp_path / "learner.lock").exists()
                 and f"pid {first.pid}" in (tmp_path / "learner.lock").read_text(), 60, "the first learner's lock")
        second = subprocess.run(
            [sys.executable, "-m", "crossway", "learner", "--run-dir", str(tmp_path), "--listen",
             f"tcp/127.0.0.1:{free_port()}", "--metrics-port", "0"], capture_output=True, text=True, timeout=60)
        assert second.returncode == 2
        assert f"is in use by another learner (pid {first.pid} on" in second.stderr
        train = subprocess.run(
            [sys.executable, "-m", "crossway", "train", "--scenario", "easy", "--actors", "1", "--minutes", "0.1",
             "--run-dir", str(tmp_path), "--metrics-port", "0"], capture_output=True, text=True, timeout=60)
        assert train.returncode == 2 and "is in use by another learner" in train.stderr
        assert not (tmp_path / "progress.csv").exists()  # refused before it wrote anything
        with pytest.raises(RunDirInUse):
            check_run_dir_free(tmp_path)
        first.send_signal(signal.SIGKILL)  # a learner that dies without cleaning up leaves no stale lock
        first.wait(timeout=30)
        check_run_dir_free(tmp_path)
    finally:
        stop(first)


def test_an_actor_pauses_while_no_learner_publishes_and_drives_again_for_a_new_one(tmp_path):
    """No weights for --learner-timeout: the actor stops pushing gradients into nothing and waits."""
    learner_endpoint, watch_endpoint = (f"tcp/127.0.0.1:{free_port()}" for _ in range(2))

    def start_learner(run_dir: Path):
        service = LearnerService(LearnerServiceConfig(
            run_dir=run_dir, transport=TransportConfig(listen=(learner_endpoint,)), metrics_port=0,
            checkpoint_interval_s=3600, publish_interval_s=0.2), log=lambda _: None)
        thread = threading.Thread(target=service.run, daemon=True)
        thread.start()
        return service, thread

    pushes: list[float] = []  # arrival times of the actor's gradient pushes, seen by a watcher
    with open_session(TransportConfig(listen=(watch_endpoint,))) as watcher:
        watcher.declare_subscriber(keys.gradients("default"), lambda _: pushes.append(time.monotonic()))
        first, first_thread = start_learner(tmp_path / "a")
        actor = start_actor(f"{learner_endpoint},{watch_endpoint}", "patient", "--learner-timeout", "2")
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(actor.stderr), daemon=True)
        reader.start()
        try:
            wait_for(lambda: first.pushes_by_actor.get("patient", 0) >= 2 and pushes, 120, "pushes to both")
            first.stop()
            first_thread.join(timeout=30)
            wait_for(lambda: any("pausing until it answers" in line for line in lines), 60, "the actor to pause")
            paused_at = time.monotonic()
            time.sleep(4.0)
            assert not [t for t in pushes if t > paused_at]  # nothing pushed while no learner is there
            assert actor.poll() is None
            second, second_thread = start_learner(tmp_path / "b")
            try:
                wait_for(lambda: second.pushes_by_actor.get("patient", 0) >= 1, 120, "pushes to the new learner")
                assert any("driving again" in line for line in lines)
            finally:
                second.stop()
                second_thread.join(timeout=30)
        finally:
            stop(actor)
            first.stop()


def test_an_actor_refuses_a_learner_timeout_that_is_not_positive():
    result = subprocess.run([sys.executable, "-m", "crossway", "actor", "--learner-timeout", "0",
                             "--connect", f"tcp/127.0.0.1:{free_port()}"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--learner-timeout must be > 0" in result.stderr
