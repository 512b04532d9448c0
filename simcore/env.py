"""PettingZoo ``ParallelEnv`` over the simulator.

An *agent* here is one episode of one entry lane: ``"south_0#3"`` is the third episode driven
from lane ``south_0``. Agents appear in ``env.agents`` when their episode starts (after the
random wait of paper, "Training settings") and leave when it ends, and a name never comes back,
as PettingZoo requires. The learner behind a lane is the same network throughout; only the
PettingZoo identity is per episode.

- observation: ``Dict(views=Box(0, 255, (16, 84, 84), uint8), scalars=Box(0, inf, (3,), float32))``;
  ``views[c*4 + k]`` is channel ``c`` (navigable, path, obstacles, sign) at frame ``k`` (3 newest);
  ``scalars`` is [speed, target speed] in m/s (the paper's) and the time the car has stood in s
  (``simcore.simulator.SCALARS``; networks read the third only when built with it).
- action: ``Box([-3, -0.2], [3, 0.2], float32)``: acceleration [m/s^2], steering [rad]; values
  outside are clipped; NaN or a wrong shape raises ``ValueError``.
- reward: ``R_acc + R_sa`` (paper, "Reward Shaping"); ``infos[agent]`` carries the two streams
  (``reward_acc``, ``reward_sa``) and, when the episode ends, ``end_reason`` and its statistics.
- ``terminated``: goal, crash, off path, time over; ``truncated``: signs redrawn ("hard") or the
  ``max_cycles`` step budget ran out.

With no car on the road, ``step`` jumps to the next start, so ``env.agents`` is only empty once
``max_cycles`` steps have passed.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from simcore.dynamics import MAX_ACCELERATION, MAX_STEERING, MAX_SPEED
from simcore.rewards import END_REASON_NAMES, EndReason
from simcore.scenario import ScenarioSpec
from simcore.simulator import CHANNELS, HISTORY, SCALARS, SimConfig, Simulator
from simcore.views import VIEW_SIZE_PX


class IntersectionParallelEnv(ParallelEnv):
    metadata = {"name": "crossway_intersection_v0", "render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, scenario: str | ScenarioSpec = "easy", max_cycles: int = 1000,
                 render_mode: str | None = None, **sim_options):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if max_cycles < 1:
            raise ValueError(f"max_cycles must be >= 1, got {max_cycles}")
        config = replace(SimConfig(skip_idle=True), **sim_options)
        self.sim = Simulator(scenario, config)
        self.max_cycles = max_cycles
        self.render_mode = render_mode
        self.agents: list[str] = []
        self._slot_agent: list[str | None] = [None] * self.sim.num_slots
        self._agent_slot: dict[str, int] = {}
        self._cycles = 0
        self._last_result = None
        self._observation_space = gymnasium.spaces.Dict({
            "views": gymnasium.spaces.Box(0, 255, (CHANNELS * HISTORY, VIEW_SIZE_PX, VIEW_SIZE_PX), np.uint8),
            "scalars": gymnasium.spaces.Box(np.zeros(SCALARS, np.float32),
                                            np.array([MAX_SPEED, MAX_SPEED, np.inf], np.float32), (SCALARS,), np.float32),
        })
        self._action_space = gymnasium.spaces.Box(
            np.array([-MAX_ACCELERATION, -MAX_STEERING], dtype=np.float32),
            np.array([MAX_ACCELERATION, MAX_STEERING], dtype=np.float32),
            dtype=np.float32,
        )

    @property
    def possible_agents(self) -> list[str]:
        # an episode lasts at least one step and a lane waits at least one step between episodes
        episodes_per_lane = self.max_cycles // 2 + 2
        return [f"{lane}#{k}" for lane in self.sim.slot_names for k in range(1, episodes_per_lane + 1)]

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str) -> gymnasium.spaces.Dict:
        return self._observation_space

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str) -> gymnasium.spaces.Box:
        return self._action_space

    # -- episode bookkeeping ----------------------------------------------------------------------

    def _observation(self, result, slot: int) -> dict[str, np.ndarray]:
        return {"views": result.views[slot].copy(), "scalars": result.scalars[slot].copy()}

    def _name(self, slot: int) -> str:
        return f"{self.sim.slot_names[slot]}#{int(self.sim.episode_count[slot])}"

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._action_space.seed(seed)
        result = self.sim.reset(seed=seed)
        self._cycles = 0
        self._slot_agent = [None] * self.sim.num_slots
        self._agent_slot = {}
        self.agents = []
        observations, infos = {}, {}
        self._admit_started(result, observations, infos)
        self._last_result = result
        return observations, infos

    def _admit_started(self, result, observations: dict, infos: dict) -> list[str]:
        """Add the agents whose episode began in ``result``; returns their names."""
        names = []
        for slot in np.flatnonzero(result.started).tolist():
            agent = self._name(slot)
            self._slot_agent[slot] = agent
            self._agent_slot[agent] = slot
            self.agents.append(agent)
            observations[agent] = self._observation(result, slot)
            infos[agent] = {"lane": self.sim.slot_names[slot]}
            names.append(agent)
        return names

    def step(self, actions: dict[str, np.ndarray]):
        unknown = [agent for agent in actions if agent not in self._agent_slot]
        if unknown:
            raise ValueError(f"actions for agents that are not on the road: {unknown}; live agents: {self.agents}")
        batch = np.zeros((self.sim.num_slots, 2))
        for agent, action in actions.items():
            action = np.asarray(action, dtype=np.float64)
            if action.shape != (2,):
                raise ValueError(f"action for {agent} must have shape (2,) [acceleration m/s^2, "
                                 f"steering rad], got shape {action.shape}")
            batch[self._agent_slot[agent]] = action
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            raise ValueError(f"no action for live agents {missing}")
        result = self.sim.step(batch)
        self._cycles += 1
        out_of_time = self._cycles >= self.max_cycles
        observations, rewards, terminated, truncated, infos = {}, {}, {}, {}, {}
        for slot in np.flatnonzero(result.acted).tolist():
            agent = self._slot_agent[slot]
            observations[agent] = self._observation(result, slot)
            rewards[agent] = float(result.reward_acc[slot] + result.reward_sa[slot])
            terminated[agent] = bool(result.terminated[slot])
            truncated[agent] = bool(result.truncated[slot]) or (out_of_time and not result.terminated[slot])
            info = {"reward_acc": float(result.reward_acc[slot]), "reward_sa": float(result.reward_sa[slot])}
            reason = EndReason(int(result.end_reason[slot]))
            if out_of_time and reason == EndReason.RUNNING:
                reason = EndReason.HORIZON
            if reason != EndReason.RUNNING:
                info["end_reason"] = END_REASON_NAMES[reason]
            infos[agent] = info
        for summary in result.episodes:
            agent = self._slot_agent[summary.slot]
            infos[agent]["episode"] = summary
        for agent in [a for a in self.agents if terminated.get(a) or truncated.get(a)]:
            self.agents.remove(agent)
            self._slot_agent[self._agent_slot.pop(agent)] = None
        if not out_of_time:
            for agent in self._admit_started(result, observations, infos):
                rewards[agent] = 0.0
                terminated[agent] = False
                truncated[agent] = False
        self._last_result = result
        return observations, rewards, terminated, truncated, infos

    def render(self):
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without render_mode='rgb_array'")
            return None
        from simcore.render import render_frame

        present = np.flatnonzero(self.sim.learners_present)
        focus = int(present[0]) if len(present) else None
        return render_frame(self.sim, self._last_result, focus)

    def close(self):
        pass
