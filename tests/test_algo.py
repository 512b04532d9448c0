"""D-A3C maths against hand-computed numbers, and the learner core."""

import math

import numpy as np
import pytest
import torch

from algo.d_a3c import (ActorCore, DA3CConfig, EpisodeLearner, ExplorationNoise, gae_advantages, gaussian_log_prob,
                        n_step_returns, stream_loss)
from algo.policy import Policy, preprocess, sigma_at
from algo.stacked import after_conv1, conv1, first_layer_matrix, patches, unique_patches
from learner.core import LearnerConfig, LearnerCore, StaleGradient
from simcore.simulator import SimConfig, Simulator


def test_n_step_returns_by_hand():
    rewards = torch.tensor([1.0, 0.0, 2.0])
    # R_2 = 2 + 0.5 * 4 = 4; R_1 = 0 + 0.5 * 4 = 2; R_0 = 1 + 0.5 * 2 = 2
    assert n_step_returns(rewards, 4.0, 0.5).tolist() == pytest.approx([2.0, 2.0, 4.0])
    # terminal: no bootstrap
    assert n_step_returns(rewards, 0.0, 0.5).tolist() == pytest.approx([1.5, 1.0, 2.0])


def test_gae_advantages_by_hand():
    rewards, values, gamma = torch.tensor([1.0, 0.0, 2.0]), torch.tensor([0.5, 1.0, 3.0]), 0.5
    # deltas: 1 + 0.5 * 1 - 0.5 = 1; 0 + 0.5 * 3 - 1 = 0.5; 2 + 0.5 * 4 - 3 = 1 (bootstrap 4)
    assert gae_advantages(rewards, values, 4.0, gamma, 0.0).tolist() == pytest.approx([1.0, 0.5, 1.0])
    # lambda 0.5: A_2 = 1; A_1 = 0.5 + 0.25 * 1 = 0.75; A_0 = 1 + 0.25 * 0.75 = 1.1875
    assert gae_advantages(rewards, values, 4.0, gamma, 0.5).tolist() == pytest.approx([1.1875, 0.75, 1.0])
    # lambda 1 is the n-step advantage R_t - v(s_t), bootstrapped or terminal
    for bootstrap in (4.0, 0.0):
        expected = n_step_returns(rewards, bootstrap, gamma) - values
        assert gae_advantages(rewards, values, bootstrap, gamma, 1.0).tolist() == pytest.approx(expected.tolist())


def test_gae_changes_the_policy_weights_but_not_the_value_target():
    mu, actions = torch.tensor([0.0, 0.1], requires_grad=True), torch.tensor([0.2, -0.1])
    rewards, bootstrap = torch.tensor([0.005, -1.0]), 0.0
    values = torch.tensor([0.3, 0.1], requires_grad=True)
    paper = stream_loss(mu, values, actions, rewards, bootstrap, 0.9, 0.5)
    td = stream_loss(mu, values, actions, rewards, bootstrap, 0.9, 0.5, gae_lambda=0.0)
    # one-step TD errors: 0.005 + 0.9 * 0.1 - 0.3 = -0.205; -1 + 0 - 0.1 = -1.1
    assert td.advantages.tolist() == pytest.approx([-0.205, -1.1])
    assert paper.advantages.tolist() == pytest.approx([-1.195, -1.1])
    assert float(td.value.detach()) == pytest.approx(float(paper.value.detach()))  # v still regresses on R_t
    (grad_td,) = torch.autograd.grad(td.policy, mu)
    # d/dmu of -A log N(a | mu, sigma) = -A (a - mu) / sigma^2
    assert grad_td.tolist() == pytest.approx([0.205 * 0.2 / 0.25, 1.1 * -0.2 / 0.25])


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


def test_the_learner_fixes_its_view_square_on_the_first_push_that_reports_one():
    from algo.policy import ViewMismatch

    core = LearnerCore()
    core.check_views(0.0, 0.0)  # a sender that does not say fixes nothing
    assert core.views is None
    core.check_views(70.0, 15.0)
    core.check_views(70.0, 15.0)  # the same square again
    with pytest.raises(ViewMismatch, match="see views 50 m wide, centred 0 m ahead.*learns from views 70 m"):
        core.check_views(50.0, 0.0)
    with pytest.raises(ViewMismatch):
        core.check_views(70.0, 0.0)  # the same size placed elsewhere: other pixels too
    restored = LearnerCore()
    restored.load_state_dict(core.state_dict())
    assert restored.views == (70.0, 15.0)
    state = core.state_dict()
    del state["views"]  # a checkpoint written before views were recorded
    restored.load_state_dict(state)
    assert restored.views is None


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


@pytest.mark.parametrize("rho", [0.0, 0.95])
def test_exploration_noise_keeps_sigma_and_holds_only_the_acceleration(rho):
    """Each step's noise has std sigma whatever rho; acceleration noise has lag-1 correlation rho,
    steering noise none; the fresh part is what is left after the known offset rho * eps_{t-1}."""
    slots, steps, sigma = 200, 400, 0.5
    noise = ExplorationNoise(slots, rho, np.random.default_rng(0))
    for slot in range(slots):
        noise.start(slot, sigma)
    history = np.zeros((steps, slots, 2))
    previous = noise.noise.copy()
    for t in range(steps):
        eps, fresh = noise.step(list(range(slots)), sigma)
        np.testing.assert_allclose(eps - fresh, rho * previous * np.array([1.0, 0.0]), atol=1e-6)
        previous = eps.copy()
        history[t] = eps
    np.testing.assert_allclose(history.std(axis=(0, 1)), [sigma, sigma], rtol=0.03)
    lag1 = [np.corrcoef(history[:-1, :, h].ravel(), history[1:, :, h].ravel())[0, 1] for h in range(2)]
    assert abs(lag1[0] - rho) < 0.02 and abs(lag1[1]) < 0.02
    acc_sigma, sa_sigma = noise.log_prob_sigmas(sigma)
    assert acc_sigma == pytest.approx(sigma * math.sqrt(1 - rho * rho)) and sa_sigma == pytest.approx(sigma)
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        ExplorationNoise(1, 1.0, np.random.default_rng(0))


def test_actor_with_correlated_noise_learns_from_the_fresh_part_of_each_action():
    """The env gets mu + eps_t (clipped); the policy gradient sees mu + fresh noise, with the
    conditional sigma; with rho = 0 both are the same sample, as in the paper."""
    for rho in (0.0, 0.9):
        sim = Simulator("easy", SimConfig(delay_max_s=0.0), seed=1)
        core = ActorCore(sim, config=DA3CConfig(update_interval=5, noise_correlation=rho), seed=1)
        core.set_weights(0, 0.4, LearnerCore().weights())
        core.reset()
        active = [slot for slot, learner in enumerate(core._learners) if learner is not None]
        previous = core.noise.noise[active].copy()
        centred, env_actions = core.act()
        means = core.means(active)[active]
        sent = np.clip(means + core.noise.noise[active], -1.0, 1.0) * np.array([3.0, 0.2])
        np.testing.assert_allclose(env_actions[active], sent, atol=1e-5)
        fresh = core.noise.noise[active] - rho * previous * np.array([1.0, 0.0])
        np.testing.assert_allclose(centred[active], means + fresh, atol=1e-5)
        if rho == 0.0:
            np.testing.assert_allclose(np.clip(centred[active], -1, 1) * np.array([3.0, 0.2]), env_actions[active],
                                       atol=1e-5)
        finished = []
        for _ in range(60):
            finished += core.step()
        assert finished and all(np.isfinite(f.mean_losses).all() for f in finished)


def test_agents_hold_their_own_weights_and_batched_acting_matches_one_by_one():
    sim = Simulator("medium", SimConfig(delay_max_s=0.0), seed=3)
    core = ActorCore(sim, config=DA3CConfig(update_interval=3), seed=3)
    core.set_weights(0, 0.3, LearnerCore().weights())
    core.reset()
    observations = {}
    for _ in range(7):
        core.step()
        observations.update({slot: (core._result.views[slot].copy(), core._result.scalars[slot].copy())
                             for slot in np.flatnonzero(core._result.observed)})
    # after local updates on different data the slots' weights differ
    first = core.stacked["acc.hidden.weight"]
    assert not torch.equal(first[0], first[1])
    active = [slot for slot, learner in enumerate(core._learners) if learner is not None]
    assert len(active) == 4
    batched = core.means(active)  # all four lanes busy: one batched call
    one_by_one = np.zeros_like(batched)
    for slot, learner in enumerate(core._learners):
        views, scalars = preprocess(observations[slot][0][None], observations[slot][1][None])
        with torch.no_grad():
            mu_acc, _, mu_sa, _ = torch.func.functional_call(core.global_policy, learner.params, (views, scalars))
        one_by_one[slot] = (float(mu_acc[0]), float(mu_sa[0]))
    np.testing.assert_allclose(batched, one_by_one, atol=1e-5)
    # and a run with a gap (slot 1 idle) gives the same means for the others
    gapped = core.means([0, 2, 3])
    np.testing.assert_allclose(gapped[[0, 2, 3]], one_by_one[[0, 2, 3]], atol=1e-5)
    assert not gapped[1].any()


def test_matrix_form_of_the_network_matches_the_modules():
    """Patches, the first layer as one product for both heads, and the rest for stacked weight
    sets give Policy's outputs."""
    torch.manual_seed(0)
    policies = [Policy(), Policy()]
    raw = np.random.default_rng(0).integers(0, 256, (2, 3, 16, 84, 84), dtype=np.uint8)
    speeds = np.random.default_rng(1).uniform(0, 10, (2, 3, 2)).astype(np.float32)
    rows = patches(torch.from_numpy(raw))
    assert rows.shape == (2, 3, 441, 256)
    # patch k of the grid holds the 4x4 window at (4 * (k // 21), 4 * (k % 21)) of every plane
    np.testing.assert_array_equal(rows[1, 2, 21 * 5 + 7].numpy().reshape(16, 4, 4), raw[1, 2, :, 20:24, 28:32])
    stacked = {name: torch.stack([dict(p.named_parameters())[name].detach() for p in policies])
               for name, _ in policies[0].named_parameters()}
    with torch.no_grad():
        pre1 = torch.stack([conv1(rows[b], *first_layer_matrix({n: w[b] for n, w in stacked.items()}))
                            for b in range(2)])
        mu, values = after_conv1(pre1, torch.from_numpy(speeds), stacked)
        for b, policy in enumerate(policies):
            views, scalars = preprocess(raw[b], speeds[b])
            mu_acc, v_acc, mu_sa, v_sa = policy(views, scalars)
            reference = policy.acc.conv1(views).permute(0, 2, 3, 1).reshape(3, 441, -1)
            torch.testing.assert_close(pre1[b, :, :, :16], reference, atol=1e-4, rtol=1e-4)
            torch.testing.assert_close(mu[b], torch.stack([mu_acc, mu_sa], 1), atol=1e-5, rtol=1e-4)
            torch.testing.assert_close(values[b], torch.stack([v_acc, v_sa], 1), atol=1e-5, rtol=1e-4)


def test_distinct_patches_group_equal_patches_exactly_even_when_hashes_collide(monkeypatch):
    """unique_patches gives each patch the row of an equal patch, whatever the hash does."""
    import algo.stacked as stacked

    raw = np.zeros((2, 16, 84, 84), dtype=np.uint8)
    raw[0, :, :4, :4] = 255  # patch 0 of view 0: every byte 255 (0xff.. words, -1 as int64)
    raw[1, 3, 40:44, 8:12] = 7  # a patch of view 1 in one plane,
    raw[1, 3, 43, 11] = 8  # ... one byte of it 8,
    raw[1, 3, 44, 8] = 7  # and the patch below it holding a single 7
    rows, inverse = unique_patches(torch.from_numpy(raw))
    assert rows.shape == (4, 256)  # zero, all 255, and the two nearly equal ones
    full = patches(torch.from_numpy(raw)).reshape(-1, 256)
    torch.testing.assert_close(rows[inverse], full, rtol=0, atol=0)
    # every hash equal: the exact grouping takes over and gives the same groups
    monkeypatch.setattr(stacked, "_row_hashes", lambda words: torch.zeros(len(words), dtype=torch.int64))
    rows_exact, inverse_exact = unique_patches(torch.from_numpy(raw))
    assert rows_exact.shape == (4, 256)
    torch.testing.assert_close(rows_exact[inverse_exact], full, rtol=0, atol=0)


def test_acting_on_distinct_patches_and_windows_gives_the_full_networks_outputs():
    """forward_distinct on a simulator's views (mostly flat) equals the full matrix form to float
    rounding, for one car and for several; noise views (few equal patches) go the full way after
    the first layer and give the same outputs too."""
    from algo.policy import ensemble, member_weights
    from algo.stacked import conv2_matrices, forward_distinct
    from evaluation.policy import PolicyDriver

    torch.manual_seed(7)
    members = [Policy() for _ in range(3)]
    with torch.no_grad():
        for member in members:
            for p in member.parameters():
                p.add_(0.05 * torch.randn_like(p))
    params = member_weights(ensemble(members), 3)
    first_layer = PolicyDriver(None, ensemble(members))._first_layer
    sim = Simulator("hard", SimConfig(delay_max_s=0.0), seed=3)
    result = sim.reset()
    for _ in range(20):
        result = sim.step(np.zeros((sim.num_slots, 2)))
    active = np.flatnonzero(sim.learners_present)
    assert len(active) >= 4
    noise = np.random.default_rng(2).integers(0, 256, (3, 16, 84, 84), dtype=np.uint8)
    for views, scalars in ((result.views[active], result.scalars[active]), (result.views[active[:1]],
                           result.scalars[active[:1]]), (noise, result.scalars[active[:3]])):
        views_t, scalars_t = torch.from_numpy(np.ascontiguousarray(views)), torch.from_numpy(scalars)
        rows, inverse = unique_patches(views_t)
        # the simulator's views are mostly flat; noise is not (the full way after the first layer)
        assert (2 * len(rows) < len(views) * 441) == (views is not noise)
        full1 = conv1(patches(views_t), *first_layer)
        distinct1 = torch.addmm(first_layer[1], rows, first_layer[0])[inverse].reshape(full1.shape)
        torch.testing.assert_close(distinct1, full1, rtol=1e-6, atol=1e-6)  # the first layer on distinct rows
        with torch.no_grad():
            pre1 = full1.reshape(len(views), 441, 3, -1).permute(2, 0, 1, 3)
            expected = after_conv1(pre1, scalars_t.expand(3, *scalars_t.shape), params, squash=False)
            got = forward_distinct(views_t, scalars_t, params, first_layer, conv2_matrices(params))
        for a, b in zip(got, expected):
            assert a.shape == (3, len(views), 2)
            torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("terminal, max_grad_norm, cost, sigma, lam, local_lr", [
    (False, 1e9, 0.0, 0.4, 1.0, 0.01), (True, 1e9, 0.0, 0.4, 1.0, 0.01), (False, 0.5, 0.0, 0.4, 1.0, 0.01),
    (False, 1e9, 0.3, (0.15, 0.4), 1.0, 0.01), (False, 1e9, 0.0, 0.4, 0.8, 0.01), (False, 1e9, 0.0, 0.05, 1.0, 0.0)])
def test_local_update_gradient_matches_autograd_through_the_policy(terminal, max_grad_norm, cost, sigma, lam,
                                                                   local_lr):
    """The update that reuses acting's first layer gives autograd's gradient on the whole segment,
    clipping, the acceleration cost and per-head sigmas included, and moves the local weights by
    -lr times it (not at all with a local step of 0, which still sums the gradient)."""
    rng = np.random.default_rng(1)
    torch.manual_seed(1)
    policy = Policy()
    config = DA3CConfig(update_interval=6, max_grad_norm=max_grad_norm, local_learning_rate=local_lr,
                        acceleration_cost=cost, gae_lambda=lam)
    n = 5
    sigmas = (sigma, sigma) if isinstance(sigma, float) else sigma
    params = {name: p.detach().clone() for name, p in policy.named_parameters()}
    start = {name: p.clone() for name, p in params.items()}
    learner = EpisodeLearner(
        params=params, base_version=0, config=config, patches=torch.zeros(7, 441, 256),
        pre1=torch.zeros(7, 441, 32), scalars=np.zeros((7, 2), np.float32),
        actions=np.zeros((6, 2), np.float32), rewards=np.zeros((6, 2), np.float32),
        grad_sum={name: torch.zeros_like(p) for name, p in params.items()})
    raw = rng.integers(0, 256, (n + 1, 16, 84, 84), dtype=np.uint8)
    speeds = rng.uniform(0, 10, (n + 1, 2)).astype(np.float32)
    actions = rng.normal(0, 0.5, (n, 2)).astype(np.float32)
    rewards = rng.normal(0, 0.1, (n, 2)).astype(np.float32)
    for t in range(n):
        learner.observe(raw[t], speeds[t])
        learner.first_layer(t)  # what acting does
        learner.record(actions[t], *rewards[t])
    learner.observe(raw[n], speeds[n])
    learner.update(sigma, terminal=terminal)

    leaves = {name: p.clone().requires_grad_(True) for name, p in start.items()}
    views, scalars = preprocess(raw, speeds)
    mu_acc, v_acc, mu_sa, v_sa = torch.func.functional_call(policy, leaves, (views, scalars))
    boot = (0.0, 0.0) if terminal else (float(v_acc[n].detach()), float(v_sa[n].detach()))
    a, r = torch.from_numpy(actions), torch.from_numpy(rewards)
    acc = stream_loss(mu_acc[:n], v_acc[:n], a[:, 0], r[:, 0], boot[0], config.gamma, sigmas[0], lam)
    sa = stream_loss(mu_sa[:n], v_sa[:n], a[:, 1], r[:, 1], boot[1], config.gamma, sigmas[1], lam)
    (acc.policy + sa.policy + config.value_coef * (acc.value + sa.value) + cost * mu_acc[:n].square().sum()).backward()
    torch.nn.utils.clip_grad_norm_(list(leaves.values()), max_grad_norm)
    for name, leaf in leaves.items():
        torch.testing.assert_close(learner.grad_sum[name], leaf.grad, atol=1e-5, rtol=1e-3)
        torch.testing.assert_close(params[name], start[name] - local_lr * leaf.grad, atol=1e-6, rtol=1e-4)
    assert any(float(g.abs().max()) > 0 for g in learner.grad_sum.values())
    if max_grad_norm < 1:
        total = math.sqrt(sum(float(g.square().sum()) for g in learner.grad_sum.values()))
        assert total == pytest.approx(max_grad_norm, rel=1e-4)
    # the last observation opens the next segment
    assert learner.length == 0
    torch.testing.assert_close(learner.patches[0], patches(torch.from_numpy(raw[n])))


@pytest.mark.parametrize("sizes", [(16, 16, 128), (16, 32, 256), (32, 32, 256), (20, 16, 300)])
def test_a_widened_network_computes_the_same_function_and_its_new_units_learn(sizes):
    from algo.policy import Policy, PolicyConfig, preprocess, widen

    torch.manual_seed(0)
    narrow = Policy(PolicyConfig())
    with torch.no_grad():  # weights away from the initial ones, mu's and biases included
        for p in narrow.parameters():
            p.add_(0.05 * torch.randn_like(p))
    wide = widen(narrow, PolicyConfig(*sizes), seed=1)
    views, speeds = preprocess(np.random.default_rng(2).integers(0, 256, (6, 16, 84, 84), dtype=np.uint8),
                               np.array([[float(i), 8.0] for i in range(6)]))
    for a, b in zip(narrow(views, speeds), wide(views, speeds)):
        assert torch.allclose(a, b, atol=1e-5)
    loss = sum(out.pow(2).sum() for out in wide(views, speeds))
    loss.backward()
    if sizes[2] > 128:  # the new hidden units' outputs get a gradient: they start to learn at once
        assert wide.acc.mu.weight.grad[:, 128:].abs().sum() > 0
    if sizes[1] > 16:  # the old hidden units' weights from the new channels too
        assert wide.acc.hidden.weight.grad[:128, 1600:100 * sizes[1]].abs().sum() > 0


def test_widen_refuses_a_smaller_network():
    from algo.policy import Policy, PolicyConfig, widen

    with pytest.raises(ValueError, match="cannot widen"):
        widen(Policy(PolicyConfig()), PolicyConfig(hidden=64))
    with pytest.raises(ValueError, match="an input go"):
        widen(Policy(PolicyConfig(standing_input=True)), PolicyConfig())


@pytest.mark.parametrize("members", [[(16, 16, 128, False)] * 2,
                                     [(16, 16, 128, False), (8, 12, 40, True), (4, 4, 16, False)]])
def test_an_ensemble_computes_the_mean_of_its_members_outputs_before_the_tanh(members):
    from algo.policy import Policy, PolicyConfig, ensemble, preprocess

    torch.manual_seed(0)
    policies = []
    for sizes in members:
        policy = Policy(PolicyConfig(*sizes))
        with torch.no_grad():  # weights away from the initial ones, mu's and biases included
            for p in policy.parameters():
                p.add_(0.05 * torch.randn_like(p))
        policies.append(policy.eval())
    joined = ensemble(policies)
    assert joined.config.hidden == sum(sizes[2] for sizes in members)
    assert joined.config.standing_input == any(sizes[3] for sizes in members)
    rng = np.random.default_rng(2)
    views, scalars = preprocess(rng.integers(0, 256, (6, 16, 84, 84), dtype=np.uint8),
                                np.array([[float(i), 8.0, 3.0 * i] for i in range(6)]))
    with torch.no_grad():
        outputs = [policy(views, scalars) for policy in policies]
        mu_acc, v_acc, mu_sa, v_sa = joined(views, scalars)
    # the value heads are linear: their mean exactly; the means are tanh of the mean pre-activation
    torch.testing.assert_close(v_acc, torch.stack([o[1] for o in outputs]).mean(0), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(v_sa, torch.stack([o[3] for o in outputs]).mean(0), atol=1e-5, rtol=1e-5)
    for joined_mu, index in ((mu_acc, 0), (mu_sa, 2)):
        pre = torch.stack([torch.atanh(o[index].double()) for o in outputs]).mean(0)
        torch.testing.assert_close(joined_mu.double(), torch.tanh(pre), atol=1e-5, rtol=1e-5)
    # not a copy of one member
    assert not torch.allclose(mu_acc, outputs[0][0], atol=1e-4)


def test_an_ensemble_of_nothing_is_refused():
    from algo.policy import ensemble

    with pytest.raises(ValueError, match="at least one"):
        ensemble([])


@pytest.mark.parametrize("sizes", [(16, 16, 128), (16, 32, 256)])
def test_the_standing_time_input_starts_unread_and_then_learns(sizes):
    """widen to standing_input: the same function whatever the standing time, until training moves
    the new input's weights; a network without the input never reads a third scalar column."""
    from algo.policy import Policy, PolicyConfig, preprocess, widen

    torch.manual_seed(0)
    paper = Policy(PolicyConfig())
    clocked = widen(paper, PolicyConfig(*sizes, standing_input=True), seed=1)
    assert clocked.acc.hidden.in_features == 100 * sizes[1] + 3
    views = np.random.default_rng(2).integers(0, 256, (4, 16, 84, 84), dtype=np.uint8)
    scalars = np.array([[3.0, 8.0, standing] for standing in (0.0, 1.0, 5.0, 40.0)], np.float32)
    inputs = preprocess(views, scalars)
    assert inputs[1][:, 2].tolist() == pytest.approx([0.0, 0.1, 0.5, 3.0])  # / 10 s, clipped at 30 s
    for a, b in zip(paper(*inputs), clocked(*inputs)):
        assert torch.allclose(a, b, atol=1e-5)
    for a, b in zip(paper(*inputs), paper(*preprocess(views, scalars[:, :2]))):
        assert torch.equal(a, b)  # the paper's network reads speed and target speed only
    sum(out.pow(2).sum() for out in clocked(*inputs)).backward()
    assert clocked.acc.hidden.weight.grad[:, -1].abs().sum() > 0  # the standing column learns at once
    with pytest.raises(ValueError, match="reads 3 scalars"):
        clocked(*preprocess(views, scalars[:, :2]))


def test_matrix_form_of_a_network_with_the_standing_input_matches_its_modules():
    from algo.policy import Policy, PolicyConfig, preprocess

    torch.manual_seed(3)
    policy = Policy(PolicyConfig(standing_input=True))
    raw = np.random.default_rng(0).integers(0, 256, (5, 16, 84, 84), dtype=np.uint8)
    scalars = np.random.default_rng(1).uniform(0, 12, (5, 3)).astype(np.float32)
    weights = {name: p.detach() for name, p in policy.named_parameters()}
    with torch.no_grad():
        pre1 = conv1(patches(torch.from_numpy(raw)), *first_layer_matrix(weights))
        mu, values = after_conv1(pre1[None], torch.from_numpy(scalars)[None],
                                 {n: w.unsqueeze(0) for n, w in weights.items()})
        mu_acc, v_acc, mu_sa, v_sa = policy(*preprocess(raw, scalars))
        moved, _ = after_conv1(pre1[None], torch.from_numpy(scalars + np.array([0, 0, 7.0], np.float32))[None],
                               {n: w.unsqueeze(0) for n, w in weights.items()})
    torch.testing.assert_close(mu[0], torch.stack([mu_acc, mu_sa], 1), atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(values[0], torch.stack([v_acc, v_sa], 1), atol=1e-5, rtol=1e-4)
    assert not torch.allclose(moved, mu)  # the standing time reaches the outputs
