"""The actor process: one simulator and its agents, weights in over Zenoh, gradients out.

Stateless: kill it at any time and start another. Wiring:

- weights key, queried at start and after a learner restart -> ``ActorCore.set_weights``
- weights key publications -> latest payload slot (Zenoh thread) -> decoded between steps
- ``ActorCore.step`` finished episodes -> ``GradientPush`` -> gradients key (congestion BLOCK)
- liveliness token on actors/<id> while alive; ``ActorHello`` heartbeat every few seconds
- no weights for ``learner_silence_s`` (the learner republishes every few seconds, changed or not):
  the learner is gone, so stop driving (nothing would receive the gradients) and wait for one again
"""

from __future__ import annotations

import os
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass, field

import torch
import zenoh

from algo.d_a3c import ActorCore, DA3CConfig, FinishedEpisode
from algo.policy import PolicyConfig, ViewMismatch, describe_views, parameter_shapes, same_views
from protocol import keys
from protocol.messages import ActorHello, DecodeError, EpisodeStats, GradientPush, Weights, check_shapes, decode, encode
from protocol.transport import TransportConfig, open_session
from simcore.simulator import SimConfig, Simulator

HEARTBEAT_S = 5.0
WEIGHTS_QUERY_TIMEOUT_S = 5.0
EXIT_VIEWS_MISMATCH = 3  # the learner's run learns from another view square than this actor's scenario


@dataclass(frozen=True)
class ActorServiceConfig:
    scenario: str = "easy"
    run_name: str = "default"
    transport: TransportConfig = field(default_factory=lambda: TransportConfig(connect=("tcp/127.0.0.1:7447",)))
    actor_id: str = ""  # default: <host>-<pid>
    seed: int | None = None
    sim: SimConfig = SimConfig()
    da3c: DA3CConfig = DA3CConfig()
    policy: PolicyConfig = PolicyConfig()
    torch_threads: int = 1
    max_episodes: int = 0  # stop after this many finished episodes (0: run until signalled)
    # the scenario label of this actor's episodes in the learner's metrics (default: the scenario's
    # name); the yield drill's say "hard-yield-drill", so its crash rate can be read on its own
    episode_label: str = ""
    # no weights publication for this long: the learner is gone; pause and wait for it [s]
    learner_silence_s: float = 60.0


class ActorService:
    def __init__(self, config: ActorServiceConfig, log=print):
        self.config = config
        self.log = log
        self.actor_id = config.actor_id or f"{socket.gethostname()}-{os.getpid()}"
        keys.hello(config.run_name, self.actor_id)  # validates the id early
        torch.set_num_threads(config.torch_threads)
        self.sim = Simulator(config.scenario, config.sim, seed=config.seed)
        self.core = ActorCore(self.sim, config.policy, config.da3c, seed=config.seed)
        self.shapes = parameter_shapes(self.core.global_policy)
        views = self.sim.spec.views
        self.views = (views.extent_m, views.shift_m)  # [m] reported with every push
        self._latest_weights: bytes | None = None
        self._last_weights_at = time.monotonic()  # when the newest publication arrived (Zenoh thread) [s]
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.episodes = 0
        self.pushes = 0

    def stop(self, *_args) -> None:
        self._stop.set()

    def _on_weights(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self._latest_weights = sample.payload.to_bytes()
            self._last_weights_at = time.monotonic()

    def _apply_weights(self, payload: bytes) -> bool:
        try:
            weights = decode(payload, expect=Weights)
            check_shapes(weights.tensors, self.shapes, "weights")
        except DecodeError as error:
            self.log(f"actor {self.actor_id}: ignored bad weights ({error})")
            return False
        if weights.view_extent_m > 0 and not same_views((weights.view_extent_m, weights.view_shift_m), self.views):
            raise ViewMismatch(
                f"the learner's run learns from {describe_views((weights.view_extent_m, weights.view_shift_m))}, "
                f"but scenario {self.sim.spec.name!r} shows {describe_views(self.views)}: start this actor on a "
                f"scenario with the run's [views], or a new run (another --run-name) for these views")
        if weights.version != self.core.version:
            if weights.version < self.core.version:
                self.log(f"actor {self.actor_id}: learner went back to version {weights.version} (restart)")
            self.core.set_weights(weights.version, weights.sigma, weights.tensors)
        return True

    def fetch_weights(self, session: zenoh.Session) -> bool:
        """Ask the learner for its newest weights; True once applied."""
        for reply in session.get(keys.weights(self.config.run_name), timeout=WEIGHTS_QUERY_TIMEOUT_S):
            if reply.ok is not None and self._apply_weights(reply.ok.payload.to_bytes()):
                return True
        return False

    def push(self, session: zenoh.Session, episode: FinishedEpisode) -> None:
        s = episode.summary
        stats = EpisodeStats(scenario=self.config.episode_label or self.sim.spec.name, lane=s.lane, sign=s.sign,
                             end_reason=s.end_reason,
                             steps=s.steps, mean_speed_mps=s.mean_speed_mps, return_acc=s.return_acc,
                             return_sa=s.return_sa, turn=s.turn)
        losses = episode.mean_losses
        message = GradientPush(actor_id=self.actor_id, base_version=episode.base_version,
                               agent_steps=episode.agent_steps, tensors=episode.gradients, episodes=(stats,),
                               loss_policy_acc=float(losses[0]), loss_policy_sa=float(losses[1]),
                               loss_value_acc=float(losses[2]), loss_value_sa=float(losses[3]),
                               view_extent_m=self.views[0], view_shift_m=self.views[1])
        session.put(keys.gradients(self.config.run_name), encode(message),
                    congestion_control=zenoh.CongestionControl.BLOCK)
        self.pushes += 1

    def hello(self) -> ActorHello:
        return ActorHello(actor_id=self.actor_id, scenario=self.sim.spec.name, host=socket.gethostname(),
                          pid=os.getpid(), agent_steps=self.core.agent_steps, episodes=self.episodes)

    def run(self) -> int:
        """Drive until stopped; 0, or ``EXIT_VIEWS_MISMATCH`` when the run's views are not this actor's."""
        try:
            return self._run()
        except ViewMismatch as error:
            self.log(f"actor {self.actor_id}: stopping: {error}")
            return EXIT_VIEWS_MISMATCH

    def _wait_for_learner(self, session: zenoh.Session) -> bool:
        """Ask for the learner's weights every second until it answers; False if stopped first."""
        while not self._stop.is_set() and not self.fetch_weights(session):
            self._stop.wait(1.0)  # no learner yet: ask again in a second
        with self._lock:
            self._last_weights_at = time.monotonic()
        return not self._stop.is_set()

    def _run(self) -> int:
        cfg = self.config
        run = cfg.run_name
        with open_session(cfg.transport) as session:
            token = session.liveliness().declare_token(keys.actor_token(run, self.actor_id))
            subscriber = session.declare_subscriber(keys.weights(run), self._on_weights)
            hello_key = keys.hello(run, self.actor_id)
            self.log(f"actor {self.actor_id}: {cfg.scenario}, waiting for the learner's weights "
                     f"({list(cfg.transport.connect) or list(cfg.transport.listen)})")
            try:
                if not self._wait_for_learner(session):
                    return 0
                self.log(f"actor {self.actor_id}: got weights version {self.core.version}, driving")
                self.core.reset()
                last_hello = 0.0
                while not self._stop.is_set():
                    for episode in self.core.step():
                        self.push(session, episode)
                        self.episodes += 1
                    with self._lock:
                        payload, self._latest_weights = self._latest_weights, None
                        silent_s = time.monotonic() - self._last_weights_at
                    if payload is not None:
                        self._apply_weights(payload)
                    now = time.monotonic()
                    if now - last_hello >= HEARTBEAT_S:
                        session.put(hello_key, encode(self.hello()))
                        last_hello = now
                    if cfg.max_episodes and self.episodes >= cfg.max_episodes:
                        break
                    if silent_s > cfg.learner_silence_s:
                        # the learner is gone (it republishes every few seconds): gradients would
                        # go nowhere, so stop driving until a learner answers again
                        self.log(f"actor {self.actor_id}: no weights from the learner for {silent_s:.0f} s; "
                                 "pausing until it answers")
                        if not self._wait_for_learner(session):
                            break
                        self.log(f"actor {self.actor_id}: the learner answered at version "
                                 f"{self.core.version}; driving again")
                        self.core.reset()  # episodes begun before the pause are dropped
            finally:
                subscriber.undeclare()
                token.undeclare()
        self.log(f"actor {self.actor_id}: stopped after {self.episodes} episodes")
        return 0


def run_actor(config: ActorServiceConfig) -> int:
    service = ActorService(config, log=lambda text: print(text, file=sys.stderr, flush=True))
    signal.signal(signal.SIGTERM, service.stop)
    signal.signal(signal.SIGINT, service.stop)
    return service.run()


__all__ = ["ActorService", "ActorServiceConfig", "run_actor"]
