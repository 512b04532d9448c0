"""The PettingZoo environment: API conformance, spaces, seeding, agents coming and going."""

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import simcore
from simcore.simulator import CHANNELS, HISTORY


# Agents are named per episode ("south_0#3"), so possible_agents lists more names than one run
# uses and PettingZoo warns that not all of them finished: expected, not a failure.
@pytest.mark.filterwarnings("ignore:No agents present but not all possible_agents")
@pytest.mark.parametrize("scenario", ["easy", "medium", "hard"])
def test_parallel_api(scenario):
    env = simcore.make_env(scenario, max_cycles=200)
    parallel_api_test(env, num_cycles=200)


def test_spaces_have_explicit_dtypes_and_shapes():
    env = simcore.make_env("easy")
    obs_space = env.observation_space("east_0#1")
    assert obs_space["views"].dtype == np.uint8
    assert obs_space["views"].shape == (CHANNELS * HISTORY, 84, 84)
    assert obs_space["scalars"].dtype == np.float32
    act_space = env.action_space("east_0#1")
    assert act_space.dtype == np.float32
    np.testing.assert_allclose(act_space.low, [-3.0, -0.2])
    np.testing.assert_allclose(act_space.high, [3.0, 0.2])
    observations, _ = env.reset(seed=3)
    for agent, obs in observations.items():
        assert obs_space.contains(obs), agent


def _rollout(seed, steps=60):
    env = simcore.make_env("medium", max_cycles=steps, delay_max_s=3.0)
    observations, _ = env.reset(seed=seed)
    trace = []
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        observations, rewards, terminated, truncated, infos = env.step(actions)
        trace.append(sorted((a, round(r, 6)) for a, r in rewards.items()))
    return trace, {a: o["views"].sum() for a, o in observations.items()}


def test_seeding_makes_runs_reproducible():
    assert _rollout(7) == _rollout(7)
    assert _rollout(7)[0] != _rollout(8)[0]


def test_agents_appear_and_leave_with_their_episodes():
    env = simcore.make_env("easy", max_cycles=400, delay_min_s=0.5, delay_max_s=1.0)
    env.reset(seed=0)
    first = set(env.agents)
    assert first == {"east_0#1", "west_0#1", "south_0#1"}
    seen_end_reasons = set()
    appeared = set()
    for _ in range(400):
        if not env.agents:
            break
        # full brake, no steering: cars crawl to a stop and time out, or drive off a curve
        actions = {a: np.array([3.0, 0.0], dtype=np.float32) for a in env.agents}
        before = set(env.agents)
        observations, rewards, terminated, truncated, infos = env.step(actions)
        for agent in before:
            if terminated[agent] or truncated[agent]:
                assert agent not in env.agents
                seen_end_reasons.add(infos[agent]["end_reason"])
                assert "episode" in infos[agent] or infos[agent]["end_reason"] == "horizon"
            assert set(infos[agent]) >= {"reward_acc", "reward_sa"}
            assert rewards[agent] == pytest.approx(infos[agent]["reward_acc"] + infos[agent]["reward_sa"])
        appeared |= set(env.agents) - before
    assert any(name.endswith("#2") for name in appeared), "a lane must start a second episode"
    assert seen_end_reasons, "episodes must end within 400 steps"


def test_bad_actions_get_clear_errors():
    env = simcore.make_env("easy")
    env.reset(seed=0)
    agent = env.agents[0]
    good = {a: np.zeros(2, dtype=np.float32) for a in env.agents}
    with pytest.raises(ValueError, match="shape"):
        env.step({**good, agent: np.zeros(3)})
    with pytest.raises(ValueError, match="finite"):
        env.step({**good, agent: np.array([np.nan, 0.0])})
    with pytest.raises(ValueError, match="not on the road"):
        env.step({**good, "nobody#1": np.zeros(2)})
    with pytest.raises(ValueError, match="no action"):
        env.step({agent: np.zeros(2)})


def test_unknown_option_is_rejected():
    with pytest.raises(TypeError, match="delay_maximum"):
        simcore.make_env("easy", delay_maximum=3)


def test_rgb_render_mode_returns_an_image():
    env = simcore.make_env("easy", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
