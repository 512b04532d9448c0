"""The intersection simulator: every entry lane hosts at most one learning agent at a time.

``Simulator`` is the fast batch path the actors use: state is a structure of arrays indexed by
*slot* (one slot per entry lane), actions come in as one ``[slots, 2]`` array and observations
go out as one ``[slots, 16, 84, 84]`` array. ``simcore.env`` wraps it as a PettingZoo
``ParallelEnv``.

One step (100 ms, paper "Training settings"):

1. validate and clip the actions of cars on the road; move them (kinematic bicycle);
2. project every car onto its route; rank who has priority over whom (``rightofway``);
3. detect ends: crash, off path, goal, time over (in that precedence) and compute both reward
   streams (``rewards``);
4. in "hard", redraw the signs at a fixed interval, cutting every episode short together (each
   lane then waits its random delay, or with ``sign_change_restart = "together"`` starts at once);
5. start new episodes on free lanes whose random wait is over (paper: U[delay_min, delay_max]);
6. render the semantic views of every car on the road, ended ones included, and shift them into
   each agent's 4-frame history.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from simcore.dynamics import (
    DT,
    INITIAL_SPEED_RANGE,
    MAX_ACCELERATION,
    MAX_STEERING,
    STANDING_MPS,
    TARGET_SPEED_RANGE,
    VEHICLE_LENGTH,
    VEHICLE_WIDTH,
    bicycle_step,
    box_corners,
    boxes_overlap,
)
from simcore.geometry import wrap_to_pi
from simcore.idm import IDMParameters, idm_acceleration
from simcore.rewards import (
    END_REASON_NAMES,
    EndReason,
    localization_reward,
    speed_reward,
    terminal_rewards,
)
from simcore.rightofway import SIGN_NAMES, Sign, build_priority_table, draw_signs, redraw_one_sign
from simcore.scenario import SIGN_CHANGE_RESTARTS, Intersection, ScenarioSpec, build_intersection, load_scenario
from simcore.views import EGO_OR_LOWER, HIGHER_PRIORITY, VIEW_SIZE_PX, ViewRenderer

HISTORY = 4  # frames per channel (paper, Fig. 3)
CHANNELS = 4
ACTION_LOW = np.array([-MAX_ACCELERATION, -MAX_STEERING])  # [m/s^2, rad]
ACTION_HIGH = np.array([MAX_ACCELERATION, MAX_STEERING])


@dataclass(frozen=True)
class SimConfig:
    """Options of a simulator; ``None`` keeps the scenario file's value."""

    delay_min_s: float | None = None  # shortest random wait between an agent's episodes [s]
    delay_max_s: float | None = None  # longest random wait between an agent's episodes [s]
    time_limit_s: float | None = None  # episode time limit [s]
    sign_change_interval_s: float | None = None  # > 0: redraw all signs together at this interval [s]
    sign_change_restart: str | None = None  # after a redraw: "delayed" (random waits) or "together"
    lanes: tuple[str, ...] | None = None  # entry lanes that host agents (e.g. ("south_0",)); None: all
    start_all_at_reset: bool = True  # reset starts an episode on every lane at once
    observe: bool = True  # render views; False skips them (scripted policies, fast evaluation)
    skip_idle: bool = False  # with no car on the road, jump straight to the next start
    # fixed signs per arm, e.g. (("south", "stop"), ("east", "none"), ...): never redrawn;
    # None: random signs (paper, "Environment")
    signs: tuple[tuple[str, str], ...] | None = None
    traffic: "TrafficConfig | None" = None  # scripted IDM traffic besides the learners
    # every learner gets the same initial and target speed, drawn once per reset (the paper's
    # right-of-way test: cars reach the junction almost together)
    equal_speeds: bool = False


TRAFFIC_SIDE_MARGIN_M = 0.5  # lateral margin of an IDM car's corridor beyond one car width [m]


@dataclass(frozen=True)
class TrafficConfig:
    """Scripted traffic cars (paper, "Comparison with TTC method"): they follow the centre of their
    route and control their speed with the IDM (``simcore.idm``); they are not learners."""

    lanes: tuple[str, ...]  # entry lanes traffic cars start from
    max_cars: int = 4  # at most this many traffic cars on the road at once
    delay_min_s: float = 0.0  # shortest wait before a traffic car starts again [s]
    delay_max_s: float = 20.0  # longest wait before a traffic car starts again [s]
    turns: tuple[str, ...] = ("straight",)  # routes traffic may take
    spawn_clearance_m: float = 15.0  # a lane's start must be this clear of cars before a start [m]
    idm: IDMParameters = IDMParameters()


@dataclass
class EpisodeSummary:
    """Statistics of one finished episode."""

    slot: int
    lane: str
    turn: str
    sign: str
    end_reason: str
    steps: int
    mean_speed_mps: float
    return_acc: float
    return_sa: float
    # a crash into a car with priority over this one (paper, "Reward Shaping": r_terminal -1, the
    # car that should have given way); False for every other end, and for the car run into
    crashed_into_priority: bool = False
    final_speed_mps: float = 0.0  # speed at the last step [m/s] (at impact, for a crash)
    target_speed_mps: float = 0.0  # the episode's target speed [m/s]


SCALARS = 3  # columns of StepResult.scalars: speed, target speed [m/s], standing time [s]


@dataclass
class StepResult:
    """Everything one step produced, indexed by slot. Arrays are views into the simulator's
    buffers: valid until the next step; copy what you keep."""

    views: np.ndarray  # [slots, 16, 84, 84] uint8, channel c frame k at index c*4+k (k=3 newest)
    # [slots, 3] float32: speed, target speed [m/s] (the paper's two scalars) and how long the car has
    # stood (slower than STANDING_MPS) up to this step [s], an input only networks built with it read
    scalars: np.ndarray
    observed: np.ndarray  # [slots] bool: rows of views/scalars that are valid this step
    acted: np.ndarray  # [slots] bool: cars whose action was applied this step
    reward_acc: np.ndarray  # [slots] float32, valid where acted
    reward_sa: np.ndarray  # [slots] float32, valid where acted
    terminated: np.ndarray  # [slots] bool: episode ended with a terminal reason
    truncated: np.ndarray  # [slots] bool: episode cut short (sign change, horizon)
    end_reason: np.ndarray  # [slots] int8 EndReason, RUNNING where the episode goes on
    started: np.ndarray  # [slots] bool: a new episode began; its first observation is in views
    episodes: list[EpisodeSummary] = field(default_factory=list)


class Simulator:
    """Multi-agent intersection simulator (paper, "Environment" and "Training settings")."""

    def __init__(self, scenario: str | ScenarioSpec, config: SimConfig = SimConfig(), seed: int | None = None):
        self.spec = scenario if isinstance(scenario, ScenarioSpec) else load_scenario(scenario)
        self.config = config
        self.intersection: Intersection = build_intersection(self.spec)
        episodes = self.spec.episodes
        self.delay_min_s = episodes.delay_min_s if config.delay_min_s is None else config.delay_min_s
        self.delay_max_s = episodes.delay_max_s if config.delay_max_s is None else config.delay_max_s
        self.time_limit_s = episodes.time_limit_s if config.time_limit_s is None else config.time_limit_s
        self.sign_interval_s = (episodes.sign_change_interval_s if config.sign_change_interval_s is None
                                else config.sign_change_interval_s)
        self.sign_restart = (episodes.sign_change_restart if config.sign_change_restart is None
                             else config.sign_change_restart)
        problems = []
        if self.sign_restart not in SIGN_CHANGE_RESTARTS:
            problems.append(f"sign_change_restart must be one of {', '.join(SIGN_CHANGE_RESTARTS)}, "
                            f"got {self.sign_restart!r}")
        if not 0.0 <= self.delay_min_s <= self.delay_max_s:
            problems.append(f"delays must satisfy 0 <= delay_min_s <= delay_max_s, got "
                            f"{self.delay_min_s}, {self.delay_max_s}")
        if not self.time_limit_s > 0.0:
            problems.append(f"time_limit_s must be > 0, got {self.time_limit_s}")
        if self.sign_interval_s < 0.0:
            problems.append(f"sign_change_interval_s must be >= 0, got {self.sign_interval_s}")
        lane_names = [lane.name for lane in self.intersection.lanes]
        if config.lanes is not None:
            unknown = [n for n in config.lanes if n not in lane_names]
            if unknown or not config.lanes:
                problems.append(f"lanes: unknown or empty {unknown or list(config.lanes)}; "
                                f"scenario {self.spec.name!r} has {lane_names}")
        self._fixed_signs = self._check_signs(config.signs, problems)
        self._traffic_routes = self._check_traffic(config.traffic, lane_names, problems)
        if problems:
            raise ValueError("invalid simulator options: " + "; ".join(problems))
        self.slot_lanes = [i for i, n in enumerate(lane_names) if config.lanes is None or n in config.lanes]
        self.slot_names = [lane_names[i] for i in self.slot_lanes]
        self.num_slots = len(self.slot_lanes)  # learner slots: the first num_slots vehicles
        self.num_traffic = config.traffic.max_cars if config.traffic else 0  # traffic vehicles after them
        self.num_vehicles = self.num_slots + self.num_traffic
        self.priority = build_priority_table(self.intersection)
        views = self.spec.views
        self.renderer = (ViewRenderer(self.intersection, self.num_vehicles, view_extent_m=views.extent_m,
                                      view_shift_m=views.shift_m) if config.observe else None)
        self._route_paths = [r.path for r in self.intersection.routes]
        self._route_length = np.array([r.path.length for r in self.intersection.routes])
        self._half_width = 0.5 * self.spec.lane_width_m
        self._rng = np.random.default_rng(seed)
        self._allocate()

    def _check_signs(self, signs, problems: list[str]) -> np.ndarray | None:
        if signs is None:
            return None
        names = {b.name: i for i, b in enumerate(self.intersection.branches)}
        by_name = {v: k for k, v in SIGN_NAMES.items()}
        fixed = np.zeros(len(names), dtype=np.int8)
        given = dict(signs)
        if set(given) != set(names):
            problems.append(f"signs: give one sign for each arm {sorted(names)}, got {sorted(given)}")
            return None
        for arm, sign in given.items():
            if sign not in by_name:
                problems.append(f"signs: {arm!r} has unknown sign {sign!r} (use {sorted(by_name)})")
                return None
            fixed[names[arm]] = int(by_name[sign])
        return fixed

    def _check_traffic(self, traffic, lane_names: list[str], problems: list[str]) -> dict[int, list[int]]:
        """Routes traffic may take from each of its lanes."""
        if traffic is None:
            return {}
        routes: dict[int, list[int]] = {}
        if not 1 <= traffic.max_cars <= 200:
            problems.append(f"traffic.max_cars must be 1-200, got {traffic.max_cars}")
        if not 0.0 <= traffic.delay_min_s <= traffic.delay_max_s:
            problems.append(f"traffic delays must satisfy 0 <= min <= max, got {traffic.delay_min_s}, "
                            f"{traffic.delay_max_s}")
        for name in traffic.lanes:
            if name not in lane_names:
                problems.append(f"traffic.lanes: unknown lane {name!r}; scenario has {lane_names}")
                continue
            lane = self.intersection.lanes[lane_names.index(name)]
            allowed = [r for r in lane.routes if self.intersection.routes[r].turn in traffic.turns]
            if not allowed:
                problems.append(f"traffic: lane {name!r} has no route turning {list(traffic.turns)}")
            routes[lane.index] = allowed
        if not traffic.lanes:
            problems.append("traffic.lanes: give at least one lane")
        return routes

    # -- state ------------------------------------------------------------------------------------

    def _allocate(self) -> None:
        k = self.num_vehicles
        self.present = np.zeros(k, dtype=bool)
        self.x = np.zeros(k)
        self.y = np.zeros(k)
        self.heading = np.zeros(k)
        self.speed = np.zeros(k)
        self.target_speed = np.ones(k)
        self.route = np.zeros(k, dtype=np.intp)
        self.sign = np.zeros(k, dtype=np.int8)
        self.steps = np.zeros(k, dtype=np.int64)
        self.s = np.zeros(k)
        self.r = np.zeros(k)
        self.heading_error = np.zeros(k)
        self.wait_until = np.zeros(k)
        self.speed_sum = np.zeros(k)
        self.return_acc = np.zeros(k)
        self.return_sa = np.zeros(k)
        self.crashed_into_priority = np.zeros(k, dtype=bool)  # set by the step that ends an episode
        self.episode_count = np.zeros(k, dtype=np.int64)
        self.lane_of = np.zeros(k, dtype=np.intp)  # entry lane of each vehicle's current trip
        self.lane_of[: self.num_slots] = self.slot_lanes
        self.is_traffic = np.arange(k) >= self.num_slots
        self.branch_signs = np.zeros(len(self.intersection.branches), dtype=np.int8)
        self.time_s = 0.0
        self.next_sign_change_s = math.inf
        learners = self.num_slots
        self._history = np.zeros((learners, CHANNELS, HISTORY, VIEW_SIZE_PX * VIEW_SIZE_PX), dtype=np.uint8)
        self._scalars = np.zeros((learners, SCALARS), dtype=np.float32)
        self._standing_s = np.zeros(learners)  # time each learner has stood, this step included [s]

    @property
    def learners_present(self) -> np.ndarray:
        """[slots] bool: learning cars on the road (``present`` also covers traffic)."""
        return self.present[: self.num_slots]

    def traffic_poses(self) -> np.ndarray:
        """[N, 3] x [m], y [m], heading [rad] of the traffic cars on the road."""
        idx = self.num_slots + np.flatnonzero(self.present[self.num_slots:])
        return np.stack([self.x[idx], self.y[idx], self.heading[idx]], axis=1)

    def seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> StepResult:
        """Clear the road and start over; with ``start_all_at_reset`` every lane starts now."""
        if seed is not None:
            self.seed(seed)
        self._allocate()
        if self._fixed_signs is not None:
            self.branch_signs = self._fixed_signs.copy()
        else:
            self.branch_signs = draw_signs(self._rng, len(self.branch_signs))
            if self.sign_interval_s > 0.0:
                self.next_sign_change_s = self.sign_interval_s
        self._shared_speeds = (self._rng.uniform(*INITIAL_SPEED_RANGE), self._rng.uniform(*TARGET_SPEED_RANGE))
        k = self.num_slots
        if self.config.start_all_at_reset:
            self.wait_until[:k] = 0.0
        else:
            self.wait_until[:k] = self._rng.uniform(self.delay_min_s, self.delay_max_s, k)
        traffic = self.config.traffic
        if traffic is not None:
            self.wait_until[k:] = self._rng.uniform(traffic.delay_min_s, traffic.delay_max_s, self.num_traffic)
        result = self._blank_result()
        self._start_due(result, blocked=np.zeros(self.num_vehicles, dtype=bool))
        if self.config.skip_idle:
            self._skip_idle(result)
        self._observe(result, self.learners_present.copy())
        return result

    # -- stepping ---------------------------------------------------------------------------------

    def validate_actions(self, actions) -> np.ndarray:
        """Check shape and finiteness of the rows that drive; clip to the action box."""
        actions = np.asarray(actions, dtype=np.float64)
        if actions.shape != (self.num_slots, 2):
            raise ValueError(
                f"actions must have shape ({self.num_slots}, 2): one row per slot of "
                f"[acceleration m/s^2, steering rad]; got shape {actions.shape}"
            )
        bad = self.learners_present & ~np.isfinite(actions).all(axis=1)
        if bad.any():
            names = [self.slot_names[i] for i in np.flatnonzero(bad)]
            raise ValueError(f"actions must be finite numbers; NaN or infinite for agents on lanes {names}")
        return np.clip(actions, ACTION_LOW, ACTION_HIGH)

    def step(self, actions) -> StepResult:
        actions = self.validate_actions(actions)
        result = self._blank_result()
        k = self.num_slots
        acted = self.learners_present.copy()
        result.acted[:] = acted
        idx = np.flatnonzero(acted)
        if len(idx):
            self.x[idx], self.y[idx], self.heading[idx], self.speed[idx] = bicycle_step(
                self.x[idx], self.y[idx], self.heading[idx], self.speed[idx], actions[idx, 0], actions[idx, 1]
            )
            # the target speed is "the maximum velocity the vehicle should not exceed" (paper,
            # "Training settings"): the car's speed is capped there, so r_speed <= xi
            self.speed[idx] = np.minimum(self.speed[idx], self.target_speed[idx])
            self.steps[idx] += 1
            self.speed_sum[idx] += self.speed[idx]
        traffic_idx = k + np.flatnonzero(self.present[k:]) if self.num_traffic else idx[:0]
        self._drive_traffic(traffic_idx)
        self.time_s += DT
        self._localise(idx)
        moving = np.concatenate([idx, traffic_idx]) if len(traffic_idx) else idx
        reasons_all, crashed_into_higher_all = self._detect_ends(moving)
        reasons, crashed_into_higher = reasons_all[: len(idx)], crashed_into_higher_all[: len(idx)]
        self.crashed_into_priority[idx] = crashed_into_higher
        self._reward(idx, reasons, crashed_into_higher, result)
        ended = np.zeros(k, dtype=bool)
        ended[idx] = reasons != EndReason.RUNNING
        result.end_reason[idx] = reasons
        result.terminated[:] = ended
        self._schedule_waits(ended)
        traffic_done = traffic_idx[reasons_all[len(idx):] != EndReason.RUNNING]
        # "hard": signs are redrawn together and every episode restarts (paper, "Environment")
        if self.time_s >= self.next_sign_change_s - 1e-9:
            cut = self.learners_present & ~ended
            result.end_reason[cut] = EndReason.SIGN_CHANGE
            result.truncated[cut] = True
            ended |= cut
            self._redraw_all_signs()
        for slot in np.flatnonzero(ended):
            result.episodes.append(self._summary(slot, EndReason(result.end_reason[slot])))
        blocked = np.zeros(self.num_vehicles, dtype=bool)
        blocked[:k] = ended  # a lane that just ended waits at least one step
        blocked[traffic_done] = True
        seen = self.learners_present.copy()
        self.present[:k] &= ~ended
        self._end_traffic(traffic_done)
        self._start_due(result, blocked)
        if self.config.skip_idle and not self.learners_present.any() and self.config.traffic is None:
            self._skip_idle(result)
        self._observe(result, seen | self.learners_present)
        return result

    # -- scripted traffic (paper, "Comparison with TTC method") ----------------------------------

    def _drive_traffic(self, idx: np.ndarray) -> None:
        """Traffic cars follow their route's centre exactly, at the speed the IDM gives."""
        if len(idx) == 0:
            return
        params = self.config.traffic.idm
        others = np.flatnonzero(self.present)
        for v in idx.tolist():
            path = self._route_paths[self.route[v]]
            gap, closing = np.inf, 0.0
            for u in others.tolist():  # the nearest car ahead in this route's corridor leads
                if u == v:
                    continue
                s_u, r_u = path.local_coordinates((self.x[u], self.y[u]))
                ahead = s_u - self.s[v]
                # corridor: the two bodies would overlap side by side (centres closer than one car
                # width plus a margin); a car on the next lane, a lane width away, is not in it
                if 0.0 < ahead < gap + VEHICLE_LENGTH and abs(r_u) < VEHICLE_WIDTH + TRAFFIC_SIDE_MARGIN_M:
                    gap = ahead - VEHICLE_LENGTH
                    heading_gap = self.heading[u] - self.heading[v]
                    closing = self.speed[v] - self.speed[u] * math.cos(heading_gap)
            acceleration = float(idm_acceleration(self.speed[v], self.target_speed[v], gap, closing, params))
            self.speed[v] = min(max(self.speed[v] + acceleration * DT, 0.0), self.target_speed[v])
            self.s[v] = min(self.s[v] + self.speed[v] * DT, path.length)
            self.x[v], self.y[v] = path.position(self.s[v], 0.0)
            self.heading[v] = path.heading_at(self.s[v])
            self.steps[v] += 1

    def _end_traffic(self, done: np.ndarray) -> None:
        if len(done) == 0:
            return
        traffic = self.config.traffic
        self.present[done] = False
        self.wait_until[done] = self.time_s + self._rng.uniform(traffic.delay_min_s, traffic.delay_max_s, len(done))

    def _lane_start_clear(self, lane_index: int, clearance_m: float) -> bool:
        start = self.intersection.routes[self.intersection.lanes[lane_index].routes[0]].path.position(0.0, 0.0)
        others = np.flatnonzero(self.present)
        if len(others) == 0:
            return True
        distance = np.hypot(self.x[others] - start[0], self.y[others] - start[1])
        return bool(distance.min() >= clearance_m)

    def _blank_result(self) -> StepResult:
        k = self.num_slots
        return StepResult(
            views=self._history.reshape(k, CHANNELS * HISTORY, VIEW_SIZE_PX, VIEW_SIZE_PX),
            scalars=self._scalars,
            observed=np.zeros(k, dtype=bool),
            acted=np.zeros(k, dtype=bool),
            reward_acc=np.zeros(k, dtype=np.float32),
            reward_sa=np.zeros(k, dtype=np.float32),
            terminated=np.zeros(k, dtype=bool),
            truncated=np.zeros(k, dtype=bool),
            end_reason=np.zeros(k, dtype=np.int8),
            started=np.zeros(k, dtype=bool),
        )

    def _localise(self, idx: np.ndarray) -> None:
        paths = self._route_paths
        for i in idx.tolist():
            path = paths[self.route[i]]
            s, r = path.local_coordinates((self.x[i], self.y[i]))
            self.s[i] = s
            self.r[i] = r
            self.heading_error[i] = wrap_to_pi(self.heading[i] - path.heading_at(s))

    def priorities(self, idx: np.ndarray) -> np.ndarray:
        """``out[a, b]``: car ``idx[b]`` has priority over car ``idx[a]`` (``rightofway``)."""
        return self.priority.higher(self.route[idx], self.s[idx], self.sign[idx])

    def _detect_ends(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = len(idx)
        reasons = np.zeros(n, dtype=np.int8)
        crashed_into_higher = np.zeros(n, dtype=bool)
        if n == 0:
            return reasons, crashed_into_higher
        crashed = np.zeros(n, dtype=bool)
        if n > 1:
            a, b = np.triu_indices(n, k=1)
            dx = self.x[idx][a] - self.x[idx][b]
            dy = self.y[idx][a] - self.y[idx][b]
            near = dx * dx + dy * dy < VEHICLE_LENGTH ** 2 + VEHICLE_WIDTH ** 2  # bounding circles
            if near.any():
                a, b = a[near], b[near]
                corners = box_corners(self.x[idx], self.y[idx], self.heading[idx])
                hit = boxes_overlap(corners[a], corners[b])
                if hit.any():
                    a, b = a[hit], b[hit]
                    crashed[a] = True
                    crashed[b] = True
                    higher = self.priorities(idx)
                    crashed_into_higher[a] |= higher[a, b]
                    crashed_into_higher[b] |= higher[b, a]
        learner = ~self.is_traffic[idx]
        off_path = learner & ((np.abs(self.r[idx]) > self._half_width) |
                              (np.abs(self.heading_error[idx]) > 0.5 * math.pi))
        goal = self.s[idx] >= self._route_length[self.route[idx]] - 1e-9
        time_over = learner & (self.steps[idx] * DT >= self.time_limit_s - 1e-9)
        # precedence: crash, off path, goal, time over
        reasons[time_over] = EndReason.TIME_OVER
        reasons[goal] = EndReason.GOAL
        reasons[off_path] = EndReason.OFF_PATH
        reasons[crashed] = EndReason.CRASH
        return reasons, crashed_into_higher

    def _reward(self, idx, reasons, crashed_into_higher, result: StepResult) -> None:
        if len(idx) == 0:
            return
        terminal_acc, terminal_sa = terminal_rewards(reasons, crashed_into_higher)
        reward_acc = speed_reward(self.speed[idx], self.target_speed[idx]) + terminal_acc
        reward_sa = localization_reward(self.heading_error[idx], self.r[idx]) + terminal_sa
        result.reward_acc[idx] = reward_acc
        result.reward_sa[idx] = reward_sa
        self.return_acc[idx] += reward_acc
        self.return_sa[idx] += reward_sa

    def _summary(self, slot: int, reason: EndReason) -> EpisodeSummary:
        steps = int(self.steps[slot])
        return EpisodeSummary(
            slot=int(slot), lane=self.slot_names[slot], turn=self.intersection.routes[self.route[slot]].turn,
            sign=SIGN_NAMES[Sign(int(self.sign[slot]))], end_reason=END_REASON_NAMES[reason], steps=steps,
            mean_speed_mps=float(self.speed_sum[slot] / max(steps, 1)),
            return_acc=float(self.return_acc[slot]), return_sa=float(self.return_sa[slot]),
            crashed_into_priority=bool(reason == EndReason.CRASH and self.crashed_into_priority[slot]),
            final_speed_mps=float(self.speed[slot]), target_speed_mps=float(self.target_speed[slot]),
        )

    # -- episodes, signs and waits ---------------------------------------------------------------

    def _schedule_waits(self, ended: np.ndarray) -> None:
        """Learners whose episode ended (``ended`` [slots]) wait U[delay_min, delay_max]."""
        count = int(ended.sum())
        if count:
            delays = self._rng.uniform(self.delay_min_s, self.delay_max_s, count)
            self.wait_until[: self.num_slots][ended] = self.time_s + delays

    def _redraw_all_signs(self) -> None:
        """New signs on every arm; every learner's episode restarts (paper, "Environment")."""
        self.branch_signs = draw_signs(self._rng, len(self.branch_signs))
        self.next_sign_change_s += self.sign_interval_s
        if self.sign_restart == "together":  # all at the next step: eight cars at once on "hard"
            self.wait_until[: self.num_slots] = self.time_s + DT
        else:  # each waits U[delay_min, delay_max] from now, as after any episode ("Training settings")
            delays = self._rng.uniform(self.delay_min_s, self.delay_max_s, self.num_slots)
            self.wait_until[: self.num_slots] = self.time_s + np.maximum(delays, DT)

    def _start_due(self, result: StepResult, blocked: np.ndarray) -> None:
        due = ~self.present & ~blocked & (self.wait_until <= self.time_s + 1e-9)
        traffic = self.config.traffic
        for v in np.flatnonzero(due).tolist():
            if v < self.num_slots:
                # with traffic about, a learner waits until its lane's start is clear
                if traffic is not None and not self._lane_start_clear(self.slot_lanes[v], traffic.spawn_clearance_m):
                    continue
                self._start_episode(v)
                result.started[v] = True
            else:
                self._start_traffic(v)

    def _start_traffic(self, v: int) -> None:
        traffic = self.config.traffic
        clear = [lane for lane in self._traffic_routes
                 if self._lane_start_clear(lane, traffic.spawn_clearance_m)]
        if not clear:
            return  # try again next step
        rng = self._rng
        lane_index = clear[int(rng.integers(len(clear)))]
        routes = self._traffic_routes[lane_index]
        route_index = routes[int(rng.integers(len(routes)))]
        self._place(v, lane_index, route_index)

    def _start_episode(self, slot: int) -> None:
        rng = self._rng
        lane = self.intersection.lanes[self.slot_lanes[slot]]
        if self.sign_interval_s <= 0.0 and self._fixed_signs is None:
            # a new sign with every episode (paper, "Environment")
            self.branch_signs[lane.branch] = redraw_one_sign(rng, self.branch_signs, lane.branch)
        route_index = lane.routes[int(rng.integers(len(lane.routes)))]
        self._place(slot, lane.index, route_index)

    def _place(self, slot: int, lane_index: int, route_index: int) -> None:
        """Put a vehicle at the start of a route with the paper's speed ranges."""
        rng = self._rng
        lane = self.intersection.lanes[lane_index]
        path = self._route_paths[route_index]
        self.lane_of[slot] = lane_index
        self.route[slot] = route_index
        self.sign[slot] = self.branch_signs[lane.branch]
        self.x[slot], self.y[slot] = path.position(0.0, 0.0)
        self.heading[slot] = path.heading_at(0.0)
        if self.config.equal_speeds and slot < self.num_slots:
            self.speed[slot], self.target_speed[slot] = self._shared_speeds
        else:
            self.speed[slot] = rng.uniform(*INITIAL_SPEED_RANGE)
            self.target_speed[slot] = rng.uniform(*TARGET_SPEED_RANGE)
        self.s[slot] = 0.0
        self.r[slot] = 0.0
        self.heading_error[slot] = 0.0
        self.steps[slot] = 0
        self.speed_sum[slot] = 0.0
        self.return_acc[slot] = 0.0
        self.return_sa[slot] = 0.0
        self.episode_count[slot] += 1
        if slot < self.num_slots:
            self._standing_s[slot] = 0.0
        self.present[slot] = True

    def _skip_idle(self, result: StepResult) -> None:
        """Nothing on the road: jump to the next start (or sign change) instead of stepping through."""
        while not self.learners_present.any():
            next_start = float(self.wait_until[: self.num_slots].min())
            if next_start >= self.next_sign_change_s:
                self.time_s = self.next_sign_change_s
                self._redraw_all_signs()
                continue
            self.time_s = max(self.time_s, next_start)
            self._start_due(result, blocked=np.zeros(self.num_vehicles, dtype=bool))
            if self.config.traffic is not None and not self.learners_present.any():
                self.time_s += DT  # a learner's lane start is still blocked: let time pass

    # -- observations -----------------------------------------------------------------------------

    def _observe(self, result: StepResult, on_road: np.ndarray) -> None:
        """Render views for every car on the road (ended ones included) into the history."""
        idx = np.flatnonzero(on_road)
        result.observed[idx] = True
        self._scalars[idx, 0] = self.speed[idx]
        self._scalars[idx, 1] = self.target_speed[idx]
        self._standing_s[idx] = np.where(self.speed[idx] < STANDING_MPS, self._standing_s[idx] + DT, 0.0)
        self._scalars[idx, 2] = self._standing_s[idx]
        if self.renderer is None or len(idx) == 0:
            return
        # every car on the road is drawn, traffic included; the egos are the learners in ``idx``
        if self.num_traffic:
            cars = np.union1d(idx, self.num_slots + np.flatnonzero(self.present[self.num_slots:]))
            higher = self.priorities(cars)[np.searchsorted(cars, idx)]
        else:
            cars = idx
            higher = self.priorities(idx)
        shades = np.zeros((len(idx), self.num_vehicles + 1), dtype=np.uint8)
        labels = cars + 1
        shades[:, labels] = np.where(higher, HIGHER_PRIORITY, EGO_OR_LOWER)
        self.renderer.draw_vehicles(self.x[cars], self.y[cars], self.heading[cars], labels)
        frames = np.empty((len(idx), CHANNELS, VIEW_SIZE_PX * VIEW_SIZE_PX), dtype=np.uint8)
        lanes = np.asarray(self.slot_lanes)[idx]
        self.renderer.render(self.x[idx], self.y[idx], self.heading[idx], self.route[idx],
                             lanes * len(Sign) + self.sign[idx], shades, frames)
        history = self._history
        started = result.started[idx]
        going = idx[~started]
        if len(going):
            history[going, :, :-1] = history[going, :, 1:]
            history[going, :, -1] = frames[~started]
        fresh = idx[started]
        if len(fresh):
            history[fresh] = frames[started][:, :, None, :]
