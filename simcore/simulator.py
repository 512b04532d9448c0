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
4. in "hard", redraw the signs at a fixed interval, cutting every episode short together;
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
    TARGET_SPEED_RANGE,
    VEHICLE_LENGTH,
    VEHICLE_WIDTH,
    bicycle_step,
    box_corners,
    boxes_overlap,
)
from simcore.geometry import wrap_to_pi
from simcore.rewards import (
    END_REASON_NAMES,
    EndReason,
    localization_reward,
    speed_reward,
    terminal_rewards,
)
from simcore.rightofway import SIGN_NAMES, Sign, build_priority_table, draw_signs, redraw_one_sign
from simcore.scenario import Intersection, ScenarioSpec, build_intersection, load_scenario
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
    lanes: tuple[str, ...] | None = None  # entry lanes that host agents (e.g. ("south_0",)); None: all
    start_all_at_reset: bool = True  # reset starts an episode on every lane at once
    observe: bool = True  # render views; False skips them (scripted policies, fast evaluation)
    skip_idle: bool = False  # with no car on the road, jump straight to the next start


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


@dataclass
class StepResult:
    """Everything one step produced, indexed by slot. Arrays are views into the simulator's
    buffers: valid until the next step; copy what you keep."""

    views: np.ndarray  # [slots, 16, 84, 84] uint8, channel c frame k at index c*4+k (k=3 newest)
    scalars: np.ndarray  # [slots, 2] float32: speed, target speed [m/s]
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
        problems = []
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
        if problems:
            raise ValueError("invalid simulator options: " + "; ".join(problems))
        self.slot_lanes = [i for i, n in enumerate(lane_names) if config.lanes is None or n in config.lanes]
        self.slot_names = [lane_names[i] for i in self.slot_lanes]
        self.num_slots = len(self.slot_lanes)
        self.priority = build_priority_table(self.intersection)
        self.renderer = ViewRenderer(self.intersection, self.num_slots) if config.observe else None
        self._route_paths = [r.path for r in self.intersection.routes]
        self._route_length = np.array([r.path.length for r in self.intersection.routes])
        self._half_width = 0.5 * self.spec.lane_width_m
        self._rng = np.random.default_rng(seed)
        self._allocate()

    # -- state ------------------------------------------------------------------------------------

    def _allocate(self) -> None:
        k = self.num_slots
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
        self.episode_count = np.zeros(k, dtype=np.int64)
        self.branch_signs = np.zeros(len(self.intersection.branches), dtype=np.int8)
        self.time_s = 0.0
        self.next_sign_change_s = math.inf
        self._history = np.zeros((k, CHANNELS, HISTORY, VIEW_SIZE_PX * VIEW_SIZE_PX), dtype=np.uint8)
        self._scalars = np.zeros((k, 2), dtype=np.float32)

    def seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> StepResult:
        """Clear the road and start over; with ``start_all_at_reset`` every lane starts now."""
        if seed is not None:
            self.seed(seed)
        self._allocate()
        self.branch_signs = draw_signs(self._rng, len(self.branch_signs))
        if self.sign_interval_s > 0.0:
            self.next_sign_change_s = self.sign_interval_s
        if self.config.start_all_at_reset:
            self.wait_until[:] = 0.0
        else:
            self.wait_until[:] = self._rng.uniform(self.delay_min_s, self.delay_max_s, self.num_slots)
        result = self._blank_result()
        self._start_due(result, blocked=np.zeros(self.num_slots, dtype=bool))
        if self.config.skip_idle:
            self._skip_idle(result)
        self._observe(result, self.present.copy())
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
        bad = self.present & ~np.isfinite(actions).all(axis=1)
        if bad.any():
            names = [self.slot_names[i] for i in np.flatnonzero(bad)]
            raise ValueError(f"actions must be finite numbers; NaN or infinite for agents on lanes {names}")
        return np.clip(actions, ACTION_LOW, ACTION_HIGH)

    def step(self, actions) -> StepResult:
        actions = self.validate_actions(actions)
        result = self._blank_result()
        acted = self.present.copy()
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
        self.time_s += DT
        self._localise(idx)
        reasons, crashed_into_higher = self._detect_ends(idx)
        self._reward(idx, reasons, crashed_into_higher, result)
        ended = np.zeros(self.num_slots, dtype=bool)
        ended[idx] = reasons != EndReason.RUNNING
        result.end_reason[idx] = reasons
        result.terminated[:] = ended
        self._schedule_waits(ended)
        # "hard": signs are redrawn together and every episode restarts (paper, "Environment")
        if self.time_s >= self.next_sign_change_s - 1e-9:
            cut = self.present & ~ended
            result.end_reason[cut] = EndReason.SIGN_CHANGE
            result.truncated[cut] = True
            ended |= cut
            self._redraw_all_signs()
        for slot in np.flatnonzero(ended):
            result.episodes.append(self._summary(slot, EndReason(result.end_reason[slot])))
        blocked = ended.copy()  # a lane that just ended waits at least one step
        seen = self.present.copy()
        self.present &= ~ended
        self._start_due(result, blocked)
        if self.config.skip_idle and not self.present.any():
            self._skip_idle(result)
        self._observe(result, seen | self.present)
        return result

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
        off_path = (np.abs(self.r[idx]) > self._half_width) | (np.abs(self.heading_error[idx]) > 0.5 * math.pi)
        goal = self.s[idx] >= self._route_length[self.route[idx]]
        time_over = self.steps[idx] * DT >= self.time_limit_s - 1e-9
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
        )

    # -- episodes, signs and waits ---------------------------------------------------------------

    def _schedule_waits(self, ended: np.ndarray) -> None:
        count = int(ended.sum())
        if count:
            delays = self._rng.uniform(self.delay_min_s, self.delay_max_s, count)
            self.wait_until[ended] = self.time_s + delays

    def _redraw_all_signs(self) -> None:
        self.branch_signs = draw_signs(self._rng, len(self.branch_signs))
        self.next_sign_change_s += self.sign_interval_s
        # everyone restarts together at the next step (paper, "Environment")
        self.wait_until[:] = self.time_s + DT

    def _start_due(self, result: StepResult, blocked: np.ndarray) -> None:
        due = ~self.present & ~blocked & (self.wait_until <= self.time_s + 1e-9)
        for slot in np.flatnonzero(due).tolist():
            self._start_episode(slot)
            result.started[slot] = True

    def _start_episode(self, slot: int) -> None:
        rng = self._rng
        lane = self.intersection.lanes[self.slot_lanes[slot]]
        if self.sign_interval_s <= 0.0:  # a new sign with every episode (paper, "Environment")
            self.branch_signs[lane.branch] = redraw_one_sign(rng, self.branch_signs, lane.branch)
        route_index = lane.routes[int(rng.integers(len(lane.routes)))]
        path = self._route_paths[route_index]
        self.route[slot] = route_index
        self.sign[slot] = self.branch_signs[lane.branch]
        self.x[slot], self.y[slot] = path.position(0.0, 0.0)
        self.heading[slot] = path.heading_at(0.0)
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
        self.present[slot] = True

    def _skip_idle(self, result: StepResult) -> None:
        """Nothing on the road: jump to the next start (or sign change) instead of stepping through."""
        while not self.present.any():
            next_start = float(self.wait_until.min())
            if next_start >= self.next_sign_change_s:
                self.time_s = self.next_sign_change_s
                self._redraw_all_signs()
                continue
            self.time_s = max(self.time_s, next_start)
            self._start_due(result, blocked=np.zeros(self.num_slots, dtype=bool))

    # -- observations -----------------------------------------------------------------------------

    def _observe(self, result: StepResult, on_road: np.ndarray) -> None:
        """Render views for every car on the road (ended ones included) into the history."""
        idx = np.flatnonzero(on_road)
        result.observed[idx] = True
        self._scalars[idx, 0] = self.speed[idx]
        self._scalars[idx, 1] = self.target_speed[idx]
        if self.renderer is None or len(idx) == 0:
            return
        higher = self.priorities(idx)
        shades = np.zeros((len(idx), self.num_slots + 1), dtype=np.uint8)
        labels = idx + 1
        shades[:, labels] = np.where(higher, HIGHER_PRIORITY, EGO_OR_LOWER)
        self.renderer.draw_vehicles(self.x[idx], self.y[idx], self.heading[idx], labels)
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
