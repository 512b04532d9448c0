"""Prometheus metrics of the learner: one registry, served by the learner process alone.

Names follow ``crossway_<thing>_<unit>``; counters end in ``_total``; label sets are bounded
(scenario, sign, end reason, rejection reason, loss head; never actor ids).
"""

from __future__ import annotations

from collections import deque

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, start_http_server

from protocol.messages import REJECT_REASONS

STALENESS_BUCKETS = (0, 1, 2, 4, 8, 16, 32, 64, 128, 256)  # [versions]
ROLLING_EPISODES = 200  # the rolling reach rate and mean speed cover this many episodes


class LearnerMetrics:
    def __init__(self, registry: CollectorRegistry | None = None):
        self.registry = registry or CollectorRegistry()
        r = self.registry
        self.episodes = Counter("crossway_episodes_total", "Finished episodes reported by actors",
                                ["scenario", "sign", "end_reason"], registry=r)
        self.reach_rate = Gauge("crossway_reach_rate_ratio",
                                f"Goal fraction of the last {ROLLING_EPISODES} episodes (0-1)", registry=r)
        self.mean_speed = Gauge("crossway_mean_speed_meters_per_second",
                                f"Mean speed over the last {ROLLING_EPISODES} episodes", registry=r)
        self.reach_rate_by_scenario = Gauge(
            "crossway_reach_rate_by_scenario_ratio",
            f"Goal fraction of the last {ROLLING_EPISODES} episodes of each scenario label (0-1)", ["scenario"],
            registry=r)
        self.updates = Counter("crossway_updates_total", "Gradient pushes applied to the global network",
                               registry=r)
        self.rejected = Counter("crossway_rejected_messages_total", "Messages refused, by reason",
                                ["reason"], registry=r)
        self.dropped = Counter("crossway_pushes_dropped_total",
                               "Gradient pushes dropped because the learner's queue was full", registry=r)
        self.staleness = Histogram("crossway_gradient_staleness_versions",
                                   "Versions between a push's base weights and the learner's",
                                   buckets=STALENESS_BUCKETS, registry=r)
        self.version = Gauge("crossway_weights_version", "Version of the global weights", registry=r)
        self.live_actors = Gauge("crossway_live_actors", "Actors holding a liveliness token", registry=r)
        self.agent_steps = Counter("crossway_agent_steps_total", "Agent-steps behind applied gradients",
                                   registry=r)
        self.agent_steps_rate = Gauge("crossway_agent_steps_per_second",
                                      "Agent-steps per second behind applied gradients (10 s window)",
                                      registry=r)
        self.sigma = Gauge("crossway_sigma", "Exploration standard deviation (normalised action units)",
                           registry=r)
        self.loss = Gauge("crossway_loss", "Mean loss per local update of the last applied push, by head",
                          ["head"], registry=r)
        self.queue_depth = Gauge("crossway_push_queue_depth", "Pushes waiting to be applied", registry=r)
        self.checkpoints = Counter("crossway_checkpoints_total", "Checkpoints written", registry=r)
        self._goals: deque[bool] = deque(maxlen=ROLLING_EPISODES)
        self._speeds: deque[float] = deque(maxlen=ROLLING_EPISODES)
        self._goals_by_scenario: dict[str, deque[bool]] = {}  # labels come from actors' configs: few
        for reason in REJECT_REASONS:
            self.rejected.labels(reason)  # export zeros so dashboards see every reason

    def serve(self, port: int, address: str = "0.0.0.0"):
        """Serve /metrics from a daemon thread; returns (server, thread)."""
        return start_http_server(port, addr=address, registry=self.registry)

    def record_episode(self, scenario: str, sign: str, end_reason: str, mean_speed_mps: float) -> None:
        self.episodes.labels(scenario, sign, end_reason).inc()
        if end_reason in ("sign_change", "horizon"):
            return  # cut short: neither a reach nor a failure
        self._goals.append(end_reason == "goal")
        self._speeds.append(mean_speed_mps)
        goals = self._goals_by_scenario.setdefault(scenario, deque(maxlen=ROLLING_EPISODES))
        goals.append(end_reason == "goal")
        self.reach_rate_by_scenario.labels(scenario).set(sum(goals) / len(goals))
        self.reach_rate.set(sum(self._goals) / len(self._goals))
        self.mean_speed.set(sum(self._speeds) / len(self._speeds))

    @property
    def rolling_reach_rate(self) -> float:
        return sum(self._goals) / len(self._goals) if self._goals else 0.0

    @property
    def rolling_mean_speed(self) -> float:
        return sum(self._speeds) / len(self._speeds) if self._speeds else 0.0

    @property
    def rolling_reach_rate_by_scenario(self) -> dict[str, float]:
        """Goal fraction of each scenario label's last episodes (the yield drill apart from hard)."""
        return {label: sum(goals) / len(goals) for label, goals in self._goals_by_scenario.items() if goals}

    def rolling_state(self) -> dict:
        """The rolling windows, for a checkpoint (a resumed run's reach rate goes on from them)."""
        return {"goals": list(self._goals), "speeds_mps": list(self._speeds),
                "goals_by_scenario": {label: list(goals) for label, goals in self._goals_by_scenario.items()}}

    def restore_rolling(self, state: dict) -> None:
        """Refill the rolling windows from ``rolling_state``'s output (a missing key: left empty)."""
        self._goals.extend(bool(goal) for goal in state.get("goals", ()))
        self._speeds.extend(float(speed) for speed in state.get("speeds_mps", ()))
        for label, goals in state.get("goals_by_scenario", {}).items():
            window = self._goals_by_scenario.setdefault(str(label), deque(maxlen=ROLLING_EPISODES))
            window.extend(bool(goal) for goal in goals)
            if window:
                self.reach_rate_by_scenario.labels(str(label)).set(sum(window) / len(window))
        if self._goals:
            self.reach_rate.set(self.rolling_reach_rate)
            self.mean_speed.set(self.rolling_mean_speed)
