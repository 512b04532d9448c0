"""D-A3C maths against hand-computed numbers, and the learner core."""

import math

import numpy as np
import pytest
import torch

from algo.d_a3c import ActorCore, DA3CConfig, gaussian_log_prob, n_step_returns, stream_loss
from algo.policy import Policy, preprocess, sigma_at
from learner.core import LearnerConfig, LearnerCore, StaleGradient
from simcore.simulator import SimConfig, Simulator


def test_n_step_returns_by_hand():
    rewards = torch.tensor([1.0, 0.0, 2.0])
    # R_2 = 2 + 0.5 * 4 = 4; R_1 = 0 + 0.5 * 4 = 2; R_0 = 1 + 0.5 * 2 = 2
    assert n_step_returns(rewards, 4.0, 0.5).tolist() == pytest.approx([2.0, 2.0, 4.0])
    # terminal: no bootstrap
    assert n_step_returns(rewards, 0.0, 0.5).tolist() == pytest.approx([1.5, 1.0, 2.0])


def test_advantages_for_both_streams_by_hand():
    """Acceleration and steering streams, each with its own rewards and values."""
    gamma, sigma = 0.9, 0.5
    actions = torch.tensor([0.2, -0.1])
    mu = torch.tensor([0.0, 0.1])
    rewards_acc, values_acc, boot_acc = torch.tensor([0.005, -1.0]), torch.tensor([0.3, 0.1]), 0.0
    rewards_sa, values_sa, boot_sa = torch.tensor([0.05, 0.04]), torch.tensor([0.5, 0.4]), 0.45
    acc = stream_loss(mu, values_acc, actions, rewards_acc, boot_acc, gamma, sigma)
    sa = stream_loss(mu, values_sa, actions, rewards_sa, boot_sa, gamma, sigma)
    # acc: R_1 = -1, R_0 = 0.005 + 0.9 * -1 = -0.895; A = R - V
    assert acc.advantages.tolist() == pytest.approx([-0.895 - 0.3, -1.0 - 0.1])
    # sa: R_1 = 0.04 + 0.9 * 0.45 = 0.445, R_0 = 0.05 + 0.9 * 0.445 = 0.4505
    assert sa.advantages.tolist() == pytest.approx([0.4505 - 0.5, 0.445 - 0.4])
    assert float(acc.value) == pytest.approx(0.5 * ((-1.195) ** 2 + (-1.1) ** 2))


def test_policy_gradient_matches_the_papers_closed_form():
    """d/dmu of -A log N(a | mu, sigma) is -A (a - mu) / sigma^2 (paper, eq. 4)."""
    sigma = 0.3
    mu = torch.tensor([0.1, -0.4, 0.7], requires_grad=True)
    actions = torch.tensor([0.5, -0.2, 0.6])
    advantages = torch.tensor([1.5, -0.7, 0.2])
    loss = -(advantages * gaussian_log_prob(actions, mu, sigma)).sum()
    loss.backward()
    expected = -advantages * (actions - mu.detach()) / sigma ** 2
    assert mu.grad.tolist() == pytest.approx(expected.tolist(), rel=1e-6)
    # and the log-density itself
    assert float(gaussian_log_prob(torch.tensor(0.5), torch.tensor(0.1), sigma)) == pytest.approx(
        -0.4 ** 2 / (2 * sigma ** 2) - math.log(sigma * math.sqrt(2 * math.pi)))


def test_sigma_falls_linearly():
    assert sigma_at(0, 100) == pytest.approx(0.65)
    assert sigma_at(50, 100) == pytest.approx(0.35)
    assert sigma_at(100, 100) == pytest.approx(0.05)
    assert sigma_at(1000, 100) == pytest.approx(0.05)


def test_policy_outputs_four_vectors_in_range():
    policy = Policy()
    views, scalars = preprocess(np.random.randint(0, 256, (5, 16, 84, 84), dtype=np.uint8),
                                np.full((5, 2), 8.0, np.float32))
    mu_acc, v_acc, mu_sa, v_sa = policy(views, scalars)
    for out in (mu_acc, v_acc, mu_sa, v_sa):
        assert out.shape == (5,)
    assert mu_acc.abs().max() <= 1.0 and mu_sa.abs().max() <= 1.0


def test_learner_applies_and_refuses_stale_gradients():
    core = LearnerCore(LearnerConfig(max_staleness=2, sigma_decay_agent_steps=1000))
    before = core.weights()
    gradients = {name: np.ones_like(w) for name, w in before.items()}
    assert core.apply(gradients, base_version=0, agent_steps=100) == 1
    after = core.weights()
    assert all(not np.array_equal(before[n], after[n]) for n in before)
    assert core.sigma == pytest.approx(0.65 - 0.6 * 0.1)
    for _ in range(3):
        core.apply(gradients, base_version=core.version, agent_steps=1)
    with pytest.raises(StaleGradient):
        core.apply(gradients, base_version=0, agent_steps=1)  # 4 versions old
    with pytest.raises(StaleGradient):
        core.apply(gradients, base_version=core.version + 1, agent_steps=1)  # from the future


def test_checkpoint_state_round_trips_and_refuses_another_network():
    from algo.policy import PolicyConfig

    core = LearnerCore()
    core.apply({n: np.ones_like(w) for n, w in core.weights().items()}, 0, 10)
    other = LearnerCore()
    other.load_state_dict(core.state_dict())
    assert other.version == 1 and other.agent_steps == 10
    assert all(np.array_equal(a, b) for a, b in zip(core.weights().values(), other.weights().values()))
    with pytest.raises(ValueError, match="does not match"):
        LearnerCore(policy_config=PolicyConfig(hidden=64)).load_state_dict(core.state_dict())


def test_actor_core_sums_local_gradients_per_episode():
    """Every car learns: local updates change the local copy, the episode pushes the sum."""
    sim = Simulator("easy", SimConfig(delay_max_s=0.0, time_limit_s=3.0), seed=0)
    core = ActorCore(sim, config=DA3CConfig(update_interval=5), seed=0)
    learner = LearnerCore()
    core.set_weights(0, 0.65, learner.weights())
    core.reset()
    finished = []
    for _ in range(40):
        finished += core.step()
    assert len({f.summary.lane for f in finished}) == 3  # all three lanes learned
    for episode in finished:
        assert episode.base_version == 0
        assert episode.agent_steps == episode.summary.steps
        norm = sum(float(np.square(g).sum()) for g in episode.gradients.values())
        assert norm > 0.0
        assert set(episode.gradients) == set(learner.shapes)
        learner.apply(episode.gradients, episode.base_version, episode.agent_steps)


def test_agents_hold_their_own_weights_and_batched_acting_matches_one_by_one():
    sim = Simulator("medium", SimConfig(delay_max_s=0.0), seed=3)
    core = ActorCore(sim, config=DA3CConfig(update_interval=3), seed=3)
    core.set_weights(0, 0.3, LearnerCore().weights())
    core.reset()
    for _ in range(7):
        core.step()
    # after local updates on different data the slots' weights differ
    first = core.stacked["acc.hidden.weight"]
    assert not torch.equal(first[0], first[1])
    active = [slot for slot, learner in enumerate(core._learners) if learner is not None]
    assert len(active) == 4
    batched = core.means(active)  # all four lanes busy: one vmap call
    one_by_one = np.zeros_like(batched)
    for slot, learner in enumerate(core._learners):
        views, scalars = preprocess(learner.views[learner.length][None], learner.scalars[learner.length][None])
        with torch.no_grad():
            mu_acc, _, mu_sa, _ = torch.func.functional_call(core.global_policy, learner.params, (views, scalars))
        one_by_one[slot] = (float(mu_acc[0]), float(mu_sa[0]))
    np.testing.assert_allclose(batched, one_by_one, atol=1e-5)
