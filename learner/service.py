"""The learner process: Zenoh in and out, checkpoints, metrics, around ``LearnerCore``.

Wiring (one comment per connection):

- gradients key -> bounded queue (Zenoh callback thread; full queue: drop and count)
- queue -> decode and validate -> staleness check -> ``LearnerCore.apply`` (main thread)
- main thread -> weights key: publication at most every ``publish_interval_s`` when changed, and
  every ``REPUBLISH_S`` regardless (congestion DROP: a dead actor link never stalls the learner)
- weights key queryable -> main thread replies with the newest weights (actors ask on start)
- actors' liveliness tokens -> live-actor gauge
- main thread -> status key, about once a second (``crossway train``'s progress line)
- main thread -> run_dir/checkpoints, every ``checkpoint_interval_s`` and on SIGTERM/SIGINT
- run_dir/learner.lock, locked (flock) for the service's life: a second learner on the same run
  directory is refused instead of overwriting the first one's checkpoints
- metrics registry -> HTTP /metrics on ``metrics_port``
"""

from __future__ import annotations

import fcntl
import os
import queue
import re
import signal
import socket
import sys
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import torch
import zenoh

from algo.policy import ViewMismatch, load_policy, save_atomically
from learner.core import LearnerConfig, LearnerCore, StaleGradient
from learner.metrics import LearnerMetrics
from protocol import keys
from protocol.messages import (
    MAX_MESSAGE_BYTES,
    DecodeError,
    GradientPush,
    LearnerStatus,
    Weights,
    check_shapes,
    decode,
    encode,
)
from protocol.transport import TransportConfig, open_session

CHECKPOINT_PATTERN = re.compile(r"^ckpt-(\d{9})\.pt$")
KEEP_CHECKPOINTS = 3
REPUBLISH_S = 5.0  # publish the weights at least this often, changed or not: rejoining actors catch up [s]


@dataclass(frozen=True)
class LearnerServiceConfig:
    run_dir: Path
    run_name: str = "default"  # key-expression namespace shared with the actors
    transport: TransportConfig = field(default_factory=lambda: TransportConfig(listen=("tcp/0.0.0.0:7447",)))
    metrics_port: int = 9100  # 0: no metrics server
    metrics_address: str = "0.0.0.0"
    checkpoint_interval_s: float = 60.0
    publish_interval_s: float = 0.5  # shortest interval between weight publications
    status_interval_s: float = 1.0
    queue_size: int = 64  # pushes waiting to be applied; more are dropped and counted
    max_message_bytes: int = MAX_MESSAGE_BYTES
    learner: LearnerConfig = LearnerConfig()
    max_updates: int = 0  # stop after this many updates (0: run until signalled)
    torch_threads: int = 1
    init_from: Path | None = None  # weights for a new run (checkpoint or exported policy); unused on resume


LOCK_NAME = "learner.lock"


class RunDirInUse(ValueError):
    """Another live process holds the run directory's lock."""


def _holder(handle) -> str | None:
    """Try the exclusive lock on an open lock file: None if this process has it now, else who holds it."""
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        return handle.read().strip() or "a process that has not written its name yet"
    return None


def _refusal(run_dir: Path, holder: str) -> RunDirInUse:
    return RunDirInUse(f"run directory {run_dir} is in use by another learner ({holder}); stop that one "
                       "first or give another run directory")


def lock_run_dir(run_dir: Path):
    """Lock ``run_dir`` for this process: an open file holding an exclusive ``flock``.

    The lock goes with the file's closing or the process's death (a killed learner leaves no
    stale lock). The file names its holder, for the refusal's message. Raises ``RunDirInUse``.
    flock is reliable on local file systems; on NFS it depends on the server.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    handle = open(run_dir / LOCK_NAME, "a+")
    if (holder := _holder(handle)) is not None:
        handle.close()
        raise _refusal(run_dir, holder)
    handle.truncate(0)
    handle.write(f"pid {os.getpid()} on {socket.gethostname()} since {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
    handle.flush()
    return handle


def check_run_dir_free(run_dir: Path) -> None:
    """Raise ``RunDirInUse`` if a learner holds ``run_dir`` now (a launcher's check before it starts
    one); leaves the lock file as it is."""
    if not (run_dir / LOCK_NAME).exists():
        return
    with open(run_dir / LOCK_NAME) as handle:
        holder = _holder(handle)
    if holder is not None:
        raise _refusal(run_dir, holder)


def newest_checkpoint(run_dir: Path) -> Path | None:
    directory = run_dir / "checkpoints"
    if not directory.is_dir():
        return None
    found = sorted((int(m.group(1)), p) for p in directory.iterdir() if (m := CHECKPOINT_PATTERN.match(p.name)))
    return found[-1][1] if found else None


def write_checkpoint(run_dir: Path, core: LearnerCore, run_id: str, progress: dict | None = None) -> Path:
    """Atomic: write to a temporary file, fsync, rename; keep the newest few.

    ``progress``: the run's episode count and rolling windows, so that a resumed run's
    progress.csv goes on where it stopped instead of restarting from an empty window.
    """
    directory = run_dir / "checkpoints"
    directory.mkdir(parents=True, exist_ok=True)
    final = directory / f"ckpt-{core.version:09d}.pt"
    state = core.state_dict()
    state["run_id"] = run_id
    if progress is not None:
        state["progress"] = progress
    save_atomically(state, final)
    old = sorted(p for p in directory.iterdir() if CHECKPOINT_PATTERN.match(p.name))
    for path in old[:-KEEP_CHECKPOINTS]:
        path.unlink(missing_ok=True)
    return final


class LearnerService:
    def __init__(self, config: LearnerServiceConfig, log=print):
        self.config = config
        self.log = log
        torch.set_num_threads(config.torch_threads)
        self.core = LearnerCore(config.learner)
        self.metrics = LearnerMetrics()
        self.run_id = uuid.uuid4().hex[:12]
        self._run_dir_lock = lock_run_dir(config.run_dir)  # before reading or writing any checkpoint
        checkpoint = newest_checkpoint(config.run_dir)
        resumed_episodes = 0
        if checkpoint is not None:
            state = torch.load(checkpoint, weights_only=False)
            self.core.load_state_dict(state)
            self.run_id = state.get("run_id", self.run_id)
            progress = state.get("progress", {})  # absent in checkpoints written before it existed
            self.metrics.restore_rolling(progress.get("rolling", {}))
            resumed_episodes = int(progress.get("episodes", 0))
            self.log(f"learner: resumed from {checkpoint} at version {self.core.version}")
        elif config.init_from is not None:
            self.core.init_weights(load_policy(config.init_from))
            self.log(f"learner: new run starting from the weights in {config.init_from}")
        self._queue: queue.Queue[bytes] = queue.Queue(maxsize=config.queue_size)
        self._stop = threading.Event()
        self._live_actors: set[str] = set()
        self._actor_events: deque[str] = deque(maxlen=1000)  # joins and leaves, logged by the main thread
        self._episodes = resumed_episodes
        self._rejected = 0
        self.pushes_by_actor: dict[str, int] = {}  # applied pushes per actor id (tests, logs)
        self.newest_base_version = -1  # newest weights version an applied push started from
        self._rate_window: deque[tuple[float, int]] = deque()
        self._published_version = -1
        self._last_publish = 0.0
        self._weights_cache: tuple[tuple, bytes] | None = None  # ((version, views), payload)
        self.session: zenoh.Session | None = None

    # -- Zenoh callbacks (Zenoh's threads: never block, never call Zenoh) --------------------------

    def _on_gradient(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        try:
            self._queue.put_nowait(payload)
        except queue.Full:
            self.metrics.dropped.inc()

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        actor = keys.actor_id_from_key(str(sample.key_expr))
        if sample.kind == zenoh.SampleKind.PUT:
            self._live_actors.add(actor)
            self._actor_events.append(f"actor {actor} joined")
        else:
            self._live_actors.discard(actor)
            self._actor_events.append(f"actor {actor} left")
        self.metrics.live_actors.set(len(self._live_actors))

    # -- main thread ------------------------------------------------------------------------------

    def stop(self, *_args) -> None:
        self._stop.set()

    def close(self) -> None:
        """Give up the run directory (``run`` does on its way out)."""
        if not self._run_dir_lock.closed:
            self._run_dir_lock.close()

    def weights_payload(self) -> bytes:
        """Encoded newest weights, encoded once per version."""
        key = (self.core.version, self.core.views)
        if self._weights_cache is None or self._weights_cache[0] != key:
            extent_m, shift_m = self.core.views or (0.0, 0.0)
            message = Weights(version=self.core.version, sigma=self.core.sigma,
                              tensors=self.core.weights(), run_id=self.run_id,
                              view_extent_m=extent_m, view_shift_m=shift_m)
            self._weights_cache = (key, encode(message))
        return self._weights_cache[1]

    def handle_push(self, payload: bytes) -> bool:
        """Validate and apply one push; every refusal is counted by reason. True if applied."""
        try:
            push = decode(payload, expect=GradientPush, max_bytes=self.config.max_message_bytes)
            check_shapes(push.tensors, self.core.shapes, "gradient")
            staleness = self.core.staleness(push.base_version)
            self.core.check_views(push.view_extent_m, push.view_shift_m)
            self.core.apply(push.tensors, push.base_version, push.agent_steps)
        except DecodeError as error:
            self._reject(error.reason, str(error))
            return False
        except ViewMismatch as error:
            self._reject("views", f"{push.actor_id}: {error}")
            return False
        except StaleGradient as error:
            self._reject("stale", str(error))
            return False
        self.metrics.staleness.observe(staleness)
        self.pushes_by_actor[push.actor_id] = self.pushes_by_actor.get(push.actor_id, 0) + 1
        self.newest_base_version = max(self.newest_base_version, push.base_version)
        self.metrics.updates.inc()
        self.metrics.agent_steps.inc(push.agent_steps)
        self.metrics.version.set(self.core.version)
        self.metrics.sigma.set(self.core.sigma)
        for head, value in zip(("policy_acc", "policy_sa", "value_acc", "value_sa"),
                               (push.loss_policy_acc, push.loss_policy_sa, push.loss_value_acc, push.loss_value_sa)):
            self.metrics.loss.labels(head).set(value)
        for episode in push.episodes:
            self._episodes += 1
            self.metrics.record_episode(episode.scenario, episode.sign, episode.end_reason, episode.mean_speed_mps)
        now = time.monotonic()
        self._rate_window.append((now, push.agent_steps))
        while self._rate_window and now - self._rate_window[0][0] > 10.0:
            self._rate_window.popleft()
        return True

    def _reject(self, reason: str, detail: str) -> None:
        self._rejected += 1
        self.metrics.rejected.labels(reason).inc()
        if self._rejected <= 10 or self._rejected % 1000 == 0:
            self.log(f"learner: rejected a message ({detail[:200]}); {self._rejected} so far")

    def agent_steps_per_s(self) -> float:
        if len(self._rate_window) < 2:
            return 0.0
        span = max(self._rate_window[-1][0] - self._rate_window[0][0], 1.0)
        return sum(steps for _, steps in self._rate_window) / span

    def status(self) -> LearnerStatus:
        return LearnerStatus(
            run_id=self.run_id, version=self.core.version, agent_steps=self.core.agent_steps,
            episodes=self._episodes, reach_rate=self.metrics.rolling_reach_rate,
            mean_speed_mps=self.metrics.rolling_mean_speed, agent_steps_per_s=self.agent_steps_per_s(),
            sigma=self.core.sigma, live_actors=len(self._live_actors), rejected=self._rejected,
            reach_by_scenario=self.metrics.rolling_reach_rate_by_scenario,
        )

    def checkpoint(self) -> Path:
        progress = {"episodes": self._episodes, "rolling": self.metrics.rolling_state()}
        path = write_checkpoint(self.config.run_dir, self.core, self.run_id, progress)
        self.metrics.checkpoints.inc()
        return path

    def run(self) -> int:
        cfg = self.config
        run = cfg.run_name
        if cfg.metrics_port:
            self.metrics.serve(cfg.metrics_port, cfg.metrics_address)
            self.log(f"learner: metrics on http://{cfg.metrics_address}:{cfg.metrics_port}/metrics")
        self.metrics.version.set(self.core.version)
        self.metrics.sigma.set(self.core.sigma)
        with open_session(cfg.transport) as session:
            self.session = session
            # DROP, not BLOCK: one actor's dead link must not stall the learner; a lost publication
            # is followed by the next (at most REPUBLISH_S later) and queries are answered reliably
            weights_publisher = session.declare_publisher(keys.weights(run),
                                                          congestion_control=zenoh.CongestionControl.DROP)
            status_publisher = session.declare_publisher(keys.status(run))
            queryable = session.declare_queryable(keys.weights(run), zenoh.handlers.FifoChannel(256))
            subscriber = session.declare_subscriber(keys.gradients(run), self._on_gradient)
            liveliness = session.liveliness().declare_subscriber(keys.actor_tokens(run), self._on_liveliness,
                                                                 history=True)
            self.log(f"learner: run {run!r} at version {self.core.version}, listening on "
                     f"{list(cfg.transport.listen) or list(cfg.transport.connect)}")
            last_checkpoint = last_status = time.monotonic()
            try:
                while not self._stop.is_set():
                    try:
                        payload = self._queue.get(timeout=0.05)
                    except queue.Empty:
                        payload = None
                    if payload is not None:
                        self.handle_push(payload)
                    self.metrics.queue_depth.set(self._queue.qsize())
                    while self._actor_events:
                        self.log(f"learner: {self._actor_events.popleft()} ({len(self._live_actors)} live)")
                    now = time.monotonic()
                    while (query := queryable.try_recv()) is not None:
                        query.reply(keys.weights(run), self.weights_payload())
                        query.drop()
                    changed = self.core.version != self._published_version
                    if (changed and now - self._last_publish >= cfg.publish_interval_s) or \
                            now - self._last_publish >= REPUBLISH_S:
                        weights_publisher.put(self.weights_payload())
                        self._published_version = self.core.version
                        self._last_publish = now
                    if now - last_status >= cfg.status_interval_s:
                        self.metrics.agent_steps_rate.set(self.agent_steps_per_s())
                        status_publisher.put(encode(self.status()))
                        last_status = now
                    if now - last_checkpoint >= cfg.checkpoint_interval_s:
                        self.checkpoint()
                        last_checkpoint = now
                    if cfg.max_updates and self.core.version >= cfg.max_updates:
                        break
            finally:
                path = self.checkpoint()
                self.log(f"learner: stopped at version {self.core.version}; checkpoint {path}")
                for entity in (subscriber, liveliness, queryable, weights_publisher, status_publisher):
                    entity.undeclare()
                self.close()
        return 0


def run_learner(config: LearnerServiceConfig, stop_requested=lambda: False) -> int:
    """Process entry point: SIGTERM and SIGINT stop the loop and leave a checkpoint.

    ``stop_requested()`` True: a stop signal came while the process was still starting (caught by
    the caller's early handler); the service then stops at once, with a checkpoint."""
    service = LearnerService(config, log=lambda text: print(text, file=sys.stderr, flush=True))
    signal.signal(signal.SIGTERM, service.stop)
    signal.signal(signal.SIGINT, service.stop)
    if stop_requested():
        service.stop()
    return service.run()


__all__ = ["LearnerService", "LearnerServiceConfig", "RunDirInUse", "check_run_dir_free", "lock_run_dir",
           "newest_checkpoint", "run_learner", "write_checkpoint"]
