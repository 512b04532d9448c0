"""crossway pretrain: the demonstration buffer, the imitation loss and the DAgger loop."""

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import torch

from algo.imitation import DemonstrationBuffer, Episode, discounted_returns, imitation_loss, newest_frames
from algo.policy import ACTION_SCALE, Policy, load_policy


def episode(length: int, first_value: int, rewards=None) -> Episode:
    """An episode whose step t has every pixel of its frame equal to first_value + t (channel c adds c)."""
    frames = [np.stack([np.full((84, 84), first_value + t + c, np.uint8) for c in range(4)]) for t in range(length)]
    scalars = [np.array([float(t), 8.0, 0.0], np.float32) for t in range(length)]  # speed, target, standing
    targets = [np.array([0.1 * t, -0.1], np.float32) for t in range(length)]
    rewards = rewards or [(0.0, 0.0)] * length
    return Episode(frames, scalars, targets, rewards)


def test_discounted_returns_by_hand():
    rewards = np.array([[0.0, 1.0], [0.0, 0.0], [1.0, -1.0]])
    returns = discounted_returns(rewards, gamma=0.5)
    assert returns[:, 0] == pytest.approx([0.25, 0.5, 1.0])
    assert returns[:, 1] == pytest.approx([1.0 - 0.25, -0.5, -1.0])


def test_newest_frames_takes_frame_3_of_each_channel():
    views = np.zeros((1, 16, 84, 84), np.uint8)
    for c in range(4):
        views[0, c * 4 + 3] = 10 + c
    assert [int(f[0, 0]) for f in newest_frames(views)[0]] == [10, 11, 12, 13]


def test_the_buffer_rebuilds_four_frame_histories_within_an_episode():
    buffer = DemonstrationBuffer(capacity=100, gamma=0.5)
    buffer.add(episode(5, first_value=100, rewards=[(0.0, 0.0)] * 4 + [(1.0, 1.0)]), terminal=True)
    buffer.add(episode(3, first_value=200), terminal=False)  # cut short: no value targets
    views, scalars = buffer.observations(np.array([0, 4, 5, 7]))
    # layout c*4 + k, k = 3 newest; channel 0 here: the frame value of each history step
    history = views[:, 0:4, 0, 0].tolist()
    assert history[0] == [100, 100, 100, 100]  # an episode's first step: its first frame four times
    assert history[1] == [101, 102, 103, 104]  # step 4 sees steps 1-4
    assert history[2] == [200, 200, 200, 200]  # the next episode does not see the last one's frames
    assert history[3] == [200, 200, 201, 202]
    assert views[1, 12 + 3, 0, 0] == 104 + 3  # channel 3 (traffic sign), newest frame
    assert scalars[:, 0].tolist() == [0.0, 4.0, 0.0, 2.0]
    batch = buffer.batch(np.array([0, 4, 5]))
    assert batch["returns"][:, 0] == pytest.approx([0.0625, 1.0, 0.0])
    assert batch["value_known"].tolist() == [True, True, False]
    assert batch["targets"][1] == pytest.approx([0.4, -0.1])


def test_a_full_buffer_forgets_the_oldest_samples_and_never_samples_a_broken_history():
    buffer = DemonstrationBuffer(capacity=10, gamma=0.9)
    buffer.add(episode(6, first_value=0), terminal=True)
    buffer.add(episode(7, first_value=50), terminal=True)  # 13 added: samples 0-2 are gone
    assert len(buffer) == 10 and buffer.added == 13
    drawn = buffer.sample_indices(2000, np.random.default_rng(0))
    assert drawn.min() >= 3 + 3 and drawn.max() == 12  # the three oldest kept ones may miss history
    views, _ = buffer.observations(np.array([6, 12]))
    assert views[:, 0:4, 0, 0].tolist() == [[50, 50, 50, 50], [53, 54, 55, 56]]
    with pytest.raises(ValueError, match="capacity"):
        DemonstrationBuffer(capacity=0, gamma=0.9)


def test_prioritized_sampling_draws_each_sample_in_proportion_to_its_error_plus_the_floor():
    from algo.imitation import PRIORITY_FLOOR

    buffer = DemonstrationBuffer(capacity=100, gamma=0.9, priority_exponent=1.0)
    measured = episode(4, first_value=0)
    measured.errors = [0.0, 0.95, 0.0, 0.45]  # priorities 0.05, 1.0, 0.05, 0.5 (floor 0.05)
    buffer.add(measured, terminal=True)
    drawn = buffer.sample_indices(60_000, np.random.default_rng(0))
    share = np.bincount(drawn, minlength=4) / len(drawn)
    expected = (np.array(measured.errors) + PRIORITY_FLOOR) / (np.sum(measured.errors) + 4 * PRIORITY_FLOOR)
    assert share == pytest.approx(expected, abs=0.01)  # 0.031, 0.625, 0.031, 0.313
    # an episode the student did not measure is as likely as the likeliest stored sample (1.0)
    buffer.add(episode(2, first_value=10), terminal=True)
    assert buffer.priorities[4:6].tolist() == [1.0, 1.0]
    # training measures again: sample 1 now fits, sample 0 does not
    buffer.update_priorities(np.array([0, 1]), np.array([0.95, 0.0]))
    share = np.bincount(buffer.sample_indices(60_000, np.random.default_rng(1)), minlength=6) / 60_000
    assert share[0] > 0.25 > 0.03 > share[1]  # 1.0 / 3.6 against 0.05 / 3.6
    with pytest.raises(ValueError, match="one per step"):
        wrong = episode(3, first_value=0)
        wrong.errors = [0.1]
        buffer.add(wrong, terminal=True)
    with pytest.raises(ValueError, match="priority_exponent"):
        DemonstrationBuffer(capacity=10, gamma=0.9, priority_exponent=-1.0)


def test_uniform_sampling_is_unchanged_and_ignores_priorities():
    """Exponent 0 (the default) draws exactly what runs before prioritized sampling drew."""
    buffer = DemonstrationBuffer(capacity=50, gamma=0.9)
    measured = episode(20, first_value=0)
    measured.errors = [float(t == 3) for t in range(20)]
    buffer.add(measured, terminal=True)
    buffer.update_priorities(np.arange(5), np.ones(5))
    assert buffer.sample_indices(500, np.random.default_rng(3)).tolist() == \
        np.random.default_rng(3).integers(0, 20, size=500).tolist()
    assert (buffer.priorities == 1.0).all()


def _a_network_and_its_outputs_on_four_samples():
    """A seeded random network, a batch of 4 samples and its (mu_acc, v_acc, mu_sa, v_sa) on them."""
    from algo.policy import preprocess

    torch.manual_seed(0)
    policy = Policy()
    buffer = DemonstrationBuffer(capacity=20, gamma=0.9)
    buffer.add(episode(4, first_value=0), terminal=False)
    batch = buffer.batch(np.arange(4))
    with torch.no_grad():
        return policy, batch, policy(*preprocess(batch["views"], batch["scalars"]))


def test_imitation_loss_is_zero_where_the_network_already_agrees_and_ignores_unknown_values():
    policy, batch, (mu_acc, v_acc, mu_sa, v_sa) = _a_network_and_its_outputs_on_four_samples()
    batch["targets"] = torch.stack([mu_acc, mu_sa], 1).numpy()
    batch["returns"][:] = 123.0  # far off, but unknown: must not count
    loss, metrics = imitation_loss(policy, batch, value_coef=1.0)
    assert float(loss.detach()) == pytest.approx(0.0, abs=1e-10)
    assert metrics["value_loss_acc"] == 0.0
    batch["value_known"][:] = True
    loss, metrics = imitation_loss(policy, batch, value_coef=1.0)
    assert metrics["value_loss_acc"] == pytest.approx(float(((v_acc - 123.0) ** 2).mean()), rel=1e-5)


def test_brake_weight_counts_hard_braking_labels_that_many_times():
    policy, batch, (mu_acc, _, mu_sa, _) = _a_network_and_its_outputs_on_four_samples()
    # two hard braking labels (<= -0.5) and two others; the steering labels are the means themselves
    labels = np.array([-0.6, -0.9, 0.2, -0.4], np.float32)
    batch["targets"] = np.stack([labels, mu_sa.numpy()], 1).astype(np.float32)
    errors = labels - mu_acc.numpy()
    _, plain = imitation_loss(policy, batch, value_coef=0.0)
    _, weighted = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0)
    squared = errors.astype(np.float64) ** 2
    assert plain["action_loss_acc"] == pytest.approx(squared.mean(), rel=1e-5)
    by_hand = (5.0 * squared[:2].sum() + squared[2:].sum()) / (5.0 * 2 + 2)
    assert weighted["action_loss_acc"] == pytest.approx(by_hand, rel=1e-5)


def test_absolute_acceleration_loss_is_the_weighted_mean_absolute_error_and_unknown_names_are_refused():
    policy, batch, (mu_acc, _, mu_sa, _) = _a_network_and_its_outputs_on_four_samples()
    labels = np.array([-0.6, -0.9, 0.2, -0.4], np.float32)  # two hard brakes, two others
    batch["targets"] = np.stack([labels, mu_sa.numpy()], 1).astype(np.float32)
    absolute = np.abs(labels - mu_acc.numpy()).astype(np.float64)
    _, plain = imitation_loss(policy, batch, value_coef=0.0, acceleration_loss="absolute")
    _, weighted = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0, acceleration_loss="absolute")
    assert plain["action_loss_acc"] == pytest.approx(absolute.mean(), rel=1e-5)
    assert weighted["action_loss_acc"] == pytest.approx((5.0 * absolute[:2].sum() + absolute[2:].sum()) / 12.0,
                                                        rel=1e-5)
    assert plain["action_loss_sa"] == pytest.approx(0.0, abs=1e-10)  # steering keeps its squared error
    with pytest.raises(ValueError, match="acceleration_loss must be one of"):
        imitation_loss(policy, batch, value_coef=0.0, acceleration_loss="huber")


def test_the_absolute_acceleration_loss_learns_the_commoner_decision_where_the_squared_one_compromises():
    """One view, labelled 'go' (+0.6) in 7 of 10 samples and 'brake' (-0.9) in 3, as where the views
    cannot tell the teacher's states apart: the squared error drives the network towards the labels'
    mean (+0.15, a car that neither goes nor brakes), the absolute error towards their median (+0.6)."""
    from algo.policy import preprocess

    buffer = DemonstrationBuffer(capacity=20, gamma=0.9)
    buffer.add(episode(1, first_value=0), terminal=False)
    batch = buffer.batch(np.zeros(10, np.int64))
    batch["targets"] = np.array([[0.6, 0.0]] * 7 + [[-0.9, 0.0]] * 3, np.float32)
    learnt = {}
    for name in ("squared", "absolute"):
        torch.manual_seed(0)
        policy = Policy()
        optimizer = torch.optim.Adam(policy.parameters(), lr=3e-3)
        for _ in range(300):
            loss, _ = imitation_loss(policy, batch, value_coef=0.0, acceleration_loss=name)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        with torch.no_grad():
            learnt[name] = float(policy(*preprocess(batch["views"][:1], batch["scalars"][:1]))[0])
    assert learnt["squared"] == pytest.approx(0.15, abs=0.05)
    assert learnt["absolute"] == pytest.approx(0.6, abs=0.05)


def test_blocker_weight_multiplies_the_weight_of_labels_that_brake_for_a_blocker():
    policy, batch, (mu_acc, _, mu_sa, _) = _a_network_and_its_outputs_on_four_samples()
    labels = np.array([-0.6, -0.9, 0.2, -0.4], np.float32)  # two hard brakes, two others
    batch["targets"] = np.stack([labels, mu_sa.numpy()], 1).astype(np.float32)
    batch["blocker"] = np.array([True, False, False, True])  # a hard brake and a mild one for a blocker
    squared = (labels - mu_acc.numpy()).astype(np.float64) ** 2
    _, weighted = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0, blocker_weight=3.0)
    weights = np.array([5.0 * 3.0, 5.0, 1.0, 3.0])
    assert weighted["action_loss_acc"] == pytest.approx((weights * squared).sum() / weights.sum(), rel=1e-5)
    # weight 1 (the default), or a batch without the flags, is the loss without it
    _, plain = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0)
    del batch["blocker"]
    _, unflagged = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0, blocker_weight=3.0)
    by_hand = (5.0 * squared[:2].sum() + squared[2:].sum()) / 12.0
    assert plain["action_loss_acc"] == pytest.approx(by_hand, rel=1e-5)
    assert unflagged["action_loss_acc"] == pytest.approx(by_hand, rel=1e-5)


def test_patience_weight_multiplies_the_weight_of_labels_that_go_once_the_patience_ran_out():
    policy, batch, (mu_acc, _, mu_sa, _) = _a_network_and_its_outputs_on_four_samples()
    labels = np.array([-0.6, 0.9, 0.2, 0.5], np.float32)
    batch["targets"] = np.stack([labels, mu_sa.numpy()], 1).astype(np.float32)
    batch["blocker"] = np.array([True, False, False, False])
    batch["released"] = np.array([False, True, False, True])
    squared = (labels - mu_acc.numpy()).astype(np.float64) ** 2
    _, weighted = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0, blocker_weight=3.0,
                                 patience_weight=20.0)
    weights = np.array([5.0 * 3.0, 20.0, 1.0, 20.0])
    assert weighted["action_loss_acc"] == pytest.approx((weights * squared).sum() / weights.sum(), rel=1e-5)
    del batch["released"]  # a batch without the flags: weight 1
    _, unflagged = imitation_loss(policy, batch, value_coef=0.0, brake_weight=5.0, blocker_weight=3.0,
                                  patience_weight=20.0)
    weights = np.array([5.0 * 3.0, 1.0, 1.0, 1.0])
    assert unflagged["action_loss_acc"] == pytest.approx((weights * squared).sum() / weights.sum(), rel=1e-5)


def test_the_buffer_keeps_each_steps_blocker_flag_and_refuses_a_wrong_count():
    buffer = DemonstrationBuffer(capacity=10, gamma=0.9)
    flagged = episode(4, first_value=0)
    flagged.blocker = [False, True, True, False]
    buffer.add(flagged, terminal=True)
    buffer.add(episode(3, first_value=50), terminal=True)  # not recorded: no flag
    assert buffer.batch(np.arange(7))["blocker"].tolist() == [False, True, True, False, False, False, False]
    buffer.add(flagged, terminal=True)  # wraps: rows 7, 8, 9, 0
    assert buffer.batch(np.array([8, 9, 10]))["blocker"].tolist() == [True, True, False]
    wrong = episode(3, first_value=0)
    wrong.blocker = [True]
    with pytest.raises(ValueError, match="blocker flags"):
        buffer.add(wrong, terminal=True)
    released = episode(2, first_value=0)
    released.released = [True, False]
    buffer.add(released, terminal=True)  # rows 1, 2
    assert buffer.batch(np.array([11, 12]))["released"].tolist() == [True, False]
    assert not buffer.batch(np.array([8, 9]))["released"].any()  # episodes without the record: False
    wrong = episode(3, first_value=0)
    wrong.released = [True]
    with pytest.raises(ValueError, match="released flags"):
        buffer.add(wrong, terminal=True)


def test_pretraining_with_a_blocker_weight_records_the_teachers_braking_for_blockers():
    """--blocker-weight: the teacher's flag reaches the buffer, training reports the share of such
    labels drawn, and the option is refused without a teacher that brakes for blockers."""
    from learner.pretrain import PretrainConfig, Pretrainer

    trainer = Pretrainer(PretrainConfig(scenario="hard", teacher_sight="view", teacher_brake_for_blockers=True,
                                        teacher_wait_outside_zones=True, teacher_half_life=float("inf"),
                                        blocker_weight=5.0, torch_threads=1, seed=3))
    trainer.collect(600)
    stored = trainer.buffer.blocker[: trainer.buffer.added]
    labels = trainer.buffer.targets[: trainer.buffer.added, 0]
    assert 0.0 < stored.mean() < 0.5  # measured: 10.9% of 1,555 car-steps (seed 3)
    assert labels[stored].mean() < labels[~stored].mean() - 0.3  # they are braking labels
    metrics = trainer.train(20)
    assert 0.0 <= metrics["blocker_label_share"] <= 1.0 and "brake_label_share" in metrics
    with pytest.raises(ValueError, match="teacher_brake_for_blockers"):
        Pretrainer(PretrainConfig(scenario="easy", blocker_weight=5.0))
    with pytest.raises(ValueError, match="blocker_weight must be > 0"):
        Pretrainer(PretrainConfig(scenario="easy", teacher_brake_for_blockers=True, blocker_weight=float("nan")))


def test_pretraining_with_a_patience_weight_records_the_teachers_going_after_its_patience():
    """--patience-weight: the teacher's flag reaches the buffer, its labels go, training reports the
    share drawn, and the option is refused with a teacher that never runs out of patience."""
    from learner.pretrain import PretrainConfig, Pretrainer

    trainer = Pretrainer(PretrainConfig(scenario="hard", teacher_sight="view", teacher_brake_for_blockers=True,
                                        teacher_wait_outside_zones=True, teacher_break_wait_cycles=True,
                                        teacher_approach_mps=2.0, teacher_approach_signs="own", delay_max_s=10.0,
                                        teacher_half_life=float("inf"), patience_weight=20.0, torch_threads=1,
                                        seed=3))
    trainer.collect(3000)
    stored = trainer.buffer.released[: trainer.buffer.added]
    labels = trainer.buffer.targets[: trainer.buffer.added, 0]
    assert 0.0 < stored.mean() < 0.05  # rare: about 0.2% of the hard teacher's car-steps
    assert (labels[stored] > 0.0).all()  # it goes
    metrics = trainer.train(5)
    assert 0.0 <= metrics["released_label_share"] <= 1.0
    with pytest.raises(ValueError, match="finite teacher_patience_s"):
        Pretrainer(PretrainConfig(scenario="easy", teacher_patience_s=float("inf"), patience_weight=20.0))
    with pytest.raises(ValueError, match="patience_weight must be > 0"):
        Pretrainer(PretrainConfig(scenario="easy", patience_weight=0.0))


def test_imitation_loss_returns_each_samples_acceleration_error_on_request():
    policy, batch, (mu_acc, _, _, _) = _a_network_and_its_outputs_on_four_samples()
    loss, metrics, errors = imitation_loss(policy, batch, value_coef=0.0, return_errors=True)
    assert errors.shape == (4,)
    assert errors == pytest.approx(np.abs(mu_acc.numpy() - batch["targets"][:, 0]), abs=1e-6)
    assert metrics["action_loss_acc"] == pytest.approx(float((errors.astype(np.float64) ** 2).mean()), rel=1e-5)


def test_prioritized_pretraining_measures_the_students_errors_and_draws_more_braking_labels():
    """--priority-exponent: every stored step carries the student's error from collection, training
    re-measures what it draws, and the draws lean to what the student gets wrong (hard brakes)."""
    from learner.pretrain import PretrainConfig, Pretrainer

    shares = {}
    for exponent in (0.0, 2.0):
        trainer = Pretrainer(PretrainConfig(scenario="easy", teacher_half_life=float("inf"), torch_threads=1,
                                            priority_exponent=exponent, seed=5))
        trainer.collect(400)
        stored = trainer.buffer.priorities[: trainer.buffer.added]
        if exponent == 0:
            assert (stored == 1.0).all()
        else:  # measured on every step: the untrained student is off by different amounts
            assert len(np.unique(stored)) > 50 and stored.min() >= 0.05 ** 2
        shares[exponent] = trainer.train(40)["brake_label_share"]
        labels = trainer.buffer.targets[: trainer.buffer.added, 0]
        assert 0.0 < (labels <= -0.5).mean() < 0.5  # the teacher brakes hard in some steps
    assert shares[2.0] > 2 * shares[0.0]  # measured: 0.042 -> 0.178 of draws, 3.5% of labels (seed 5)
    with pytest.raises(ValueError, match="priority_exponent"):
        Pretrainer(PretrainConfig(scenario="easy", priority_exponent=float("nan")))


def test_a_student_given_the_standing_time_drives_as_before_and_then_learns_to_read_it(tmp_path):
    """--standing-input on a loaded policy: the same actions at first (the input's weights are
    zero), the buffer keeps each car's standing time, and training moves the new weights."""
    from evaluation.policy import PolicyDriver
    from learner.pretrain import PretrainConfig, Pretrainer

    trainer = Pretrainer(PretrainConfig(scenario="easy", init_from="models/easy-student-guard.pt", standing_input=True,
                                        teacher_half_life=float("inf"), torch_threads=1, learning_rate=1e-3))
    assert trainer.policy.config.standing_input and not load_policy("models/easy-student-guard.pt").config.standing_input
    result = trainer.result
    before = PolicyDriver(trainer.sim, load_policy("models/easy-student-guard.pt")).act(result)
    np.testing.assert_allclose(PolicyDriver(trainer.sim, trainer.policy).act(result), before, atol=1e-5)
    trainer.collect(600)
    standing = trainer.buffer.scalars[: trainer.buffer.added, 2]
    assert standing.max() > 0.5  # cars stood at the junction, and the samples say how long
    column = trainer.policy.acc.hidden.weight[:, -1]
    assert (column == 0).all()
    trainer.train(20)
    assert (trainer.policy.acc.hidden.weight[:, -1] != 0).any()
    path = trainer.export(tmp_path / "clocked.pt", note="test")
    assert load_policy(path).config.standing_input


def test_training_on_the_teachers_labels_brings_the_network_towards_them():
    from learner.pretrain import PretrainConfig, Pretrainer

    trainer = Pretrainer(PretrainConfig(scenario="easy", teacher_half_life=float("inf"), learning_rate=1e-3,
                                        torch_threads=1))
    trainer.collect(400)
    assert trainer.buffer.added > 200 and trainer.episodes_finished["teacher"] > 0
    assert trainer.episodes_finished["student"] == 0 and not trainer.outcomes["student"]
    held_out = trainer.buffer.batch(np.arange(0, trainer.buffer.added, 3))
    with torch.no_grad():
        before, _ = imitation_loss(trainer.policy, held_out, value_coef=0.0)
    trainer.train(120)
    with torch.no_grad():
        after, _ = imitation_loss(trainer.policy, held_out, value_coef=0.0)
    assert float(after) < 0.4 * float(before)  # measured: 0.326 -> 0.064 (seed 0)


def test_a_teacher_with_an_approach_speed_labels_slower_driving():
    """--teacher-approach-speed reaches the teacher: the cars it drives are slower on the same seed."""
    from learner.pretrain import PretrainConfig, Pretrainer

    mean_speed = {}
    for approach in (None, 1.0):
        trainer = Pretrainer(PretrainConfig(scenario="easy", teacher_sight="view", teacher_approach_mps=approach,
                                            teacher_half_life=float("inf"), torch_threads=1))
        assert trainer.teacher.approach_speed_mps == approach and trainer.teacher.approach_signs == "all"
        trainer.collect(300)
        mean_speed[approach] = float(trainer.buffer.scalars[: trainer.buffer.added, 0].mean())  # speed input
    assert mean_speed[1.0] < 0.9 * mean_speed[None]  # measured: 6.43 against 7.59 m/s (seed 0)
    own = Pretrainer(PretrainConfig(scenario="easy", teacher_approach_mps=1.0, teacher_approach_signs="own"))
    assert own.teacher.approach_signs == "own" and not own.teacher.brake_for_blockers
    guarded = Pretrainer(PretrainConfig(scenario="easy", teacher_brake_for_blockers=True))
    assert guarded.teacher.brake_for_blockers and not guarded.teacher.wait_outside_zones
    untangled = Pretrainer(PretrainConfig(scenario="easy", teacher_wait_outside_zones=True,
                                          teacher_break_wait_cycles=True))
    assert untangled.teacher.wait_outside_zones and untangled.teacher.break_wait_cycles
    with pytest.raises(ValueError, match="teacher_approach_mps"):
        Pretrainer(PretrainConfig(scenario="easy", teacher_approach_mps=0.0))


def test_the_averaged_weights_are_the_moving_average_of_the_adam_iterates(tmp_path):
    """--average-half-life: after each Adam step the average moves towards the new weights by
    1 - 0.5 ** (1 / half-life); pretrained.pt holds the average, pretrained-last.pt the last weights."""
    from learner.pretrain import PretrainConfig, Pretrainer, run_pretrain

    trainer = Pretrainer(PretrainConfig(scenario="easy", teacher_half_life=float("inf"), learning_rate=1e-3,
                                        average_half_life=2.0, torch_threads=1))
    name = "acc.mu.weight"  # the acceleration head's last layer
    by_hand = dict(trainer.policy.named_parameters())[name].detach().clone()
    trainer.collect(200)
    decay = 0.5 ** (1 / 2.0)
    for _ in range(4):
        trainer.train(1)
        by_hand = decay * by_hand + (1 - decay) * dict(trainer.policy.named_parameters())[name].detach()
    assert torch.allclose(trainer.averaged[name], by_hand, atol=1e-6)
    assert not torch.allclose(trainer.averaged[name], dict(trainer.policy.named_parameters())[name])

    out = tmp_path / "pre"
    run_pretrain(PretrainConfig(scenario="easy", rounds=2, steps_per_round=150, teacher_half_life=300,
                                average_half_life=5.0, torch_threads=1), out, "test", log=lambda line: None)
    averaged, last = load_policy(out / "pretrained.pt"), load_policy(out / "pretrained-last.pt")
    differ = [n for n, p in averaged.named_parameters() if not torch.equal(p, dict(last.named_parameters())[n])]
    assert differ  # two rounds of Adam steps moved the last weights away from their average
    with pytest.raises(ValueError, match="average_half_life"):
        Pretrainer(PretrainConfig(scenario="easy", average_half_life=0.0))


def crossway(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=timeout)


def test_pretrain_end_to_end_writes_a_policy_the_other_commands_take(tmp_path):
    out = tmp_path / "pre"
    result = crossway("pretrain", "--scenario", "easy", "--rounds", "3", "--steps-per-round", "200",
                      "--teacher-half-life", "300", "--threads", "1", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "teacher drives 100%" in result.stdout and "wrote" in result.stdout
    policy = load_policy(out / "pretrained.pt")  # what train --init-from and evaluate use
    assert isinstance(policy, Policy)
    from algo.policy import policy_views

    assert policy_views(out / "pretrained.pt") == (50.0, 0.0)  # recorded: easy shows the paper's views
    rows = list(csv.DictReader((out / "progress.csv").open()))
    assert rows and {"round", "teacher_probability", "samples", "action_loss_acc", "student_reach_rate",
                     "brake_label_share"} <= set(rows[0])
    probabilities = [float(r["teacher_probability"]) for r in rows]
    assert len(rows) == 3 and [r["round"] for r in rows] == ["0", "1", "2"]
    # round 0's episodes (all three lanes start at once, ~13 s each) end within its 20 s
    assert probabilities[0] == 1.0 and probabilities[1] < 0.5  # DAgger hands over to the student
    assert int(rows[-1]["updates"]) > 0 and int(rows[-1]["samples"]) > int(rows[0]["samples"]) > 0


@pytest.mark.parametrize("args, message", [
    (["--scenario", "nowhere"], "nowhere"),
    (["--minutes", "0"], "--minutes"),
    (["--rounds", "-1"], "--rounds"),
    (["--teacher-half-life", "0"], "--teacher-half-life"),
    (["--gamma", "1.5"], "--gamma"),
    (["--buffer-samples", "0"], "--buffer-samples must be >= 1"),
    (["--learning-rate", "nan"], "--learning-rate must be > 0"),
    (["--brake-weight", "0"], "--brake-weight must be > 0"),
    (["--priority-exponent", "-1"], "--priority-exponent must be >= 0"),
    (["--blocker-weight", "0", "--teacher-brake-for-blockers"], "--blocker-weight must be > 0"),
    (["--blocker-weight", "5"], "--blocker-weight weighs the teacher's braking for blockers"),
    (["--patience-weight", "-1"], "--patience-weight must be > 0"),
    (["--patience-weight", "20", "--teacher-patience", "inf"], "needs a finite --teacher-patience"),
    (["--teacher-approach-speed", "0"], "--teacher-approach-speed must be a speed > 0"),
    (["--teacher-approach-speed", "nan"], "--teacher-approach-speed must be a speed > 0"),
    (["--average-half-life", "0"], "--average-half-life must be > 0"),
    (["--teacher-approach-signs", "own"], "--teacher-approach-signs goes with --teacher-approach-speed"),
    (["--teacher-patience", "0"], "--teacher-patience must be > 0 s"),
    (["--teacher-blocker-patience", "nan"], "--teacher-blocker-patience must be > 0 s"),
    (["--network", "32,32"], "expected three positive integers"),
    (["--network", "32,0,256"], "expected three positive integers"),
    (["--network", "8,16,128", "--init-from", "models/easy-student-guard.pt"], "can only be widened"),
])
def test_pretrain_refuses_bad_input(tmp_path, args, message):
    result = crossway("pretrain", "--out", str(tmp_path / "never"), *args)
    assert result.returncode == 2 and message in result.stderr
    assert not (tmp_path / "never").exists()


def test_pretrain_refuses_to_overwrite_a_finished_policy_or_write_into_a_file(tmp_path):
    out = tmp_path / "pre"
    out.mkdir()
    (out / "pretrained.pt").write_bytes(b"fifteen minutes of work")
    result = crossway("pretrain", "--out", str(out))
    assert result.returncode == 2 and "pretrained.pt' exists" in result.stderr
    assert (out / "pretrained.pt").read_bytes() == b"fifteen minutes of work"
    assert not (out / "progress.csv").exists()
    a_file = tmp_path / "file"
    a_file.write_text("x")
    result = crossway("pretrain", "--out", str(a_file))
    assert result.returncode == 2 and "is a file" in result.stderr


def test_pretrain_refuses_a_bad_initial_checkpoint(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_text("nope")
    result = crossway("pretrain", "--init-from", str(bad), "--out", str(tmp_path / "never"))
    assert result.returncode == 2 and "is not a crossway checkpoint" in result.stderr
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("stop_signal", ["SIGINT", "SIGTERM"])
def test_ctrl_c_or_sigterm_writes_the_policy_learnt_so_far(tmp_path, stop_signal):
    """Ctrl-C, or SIGTERM from a scheduler, stops the run and writes what it learnt; before that,
    --save-every has written snapshots a run killed outright would leave."""
    import signal
    import time

    out = tmp_path / "pre"
    process = subprocess.Popen([sys.executable, "-m", "crossway", "pretrain", "--scenario", "easy", "--minutes", "5",
                                "--steps-per-round", "150", "--threads", "1", "--save-every", "0.001",
                                "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               # a suite started in the background by a shell inherits SIGINT ignored, and
                               # Python then keeps it ignored: give the child the default disposition
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    progress = out / "progress.csv"
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and (not progress.exists() or len(progress.read_text().splitlines()) < 3):
        time.sleep(0.5)  # wait for two rounds: the loop is running
    load_policy(out / "pretrained.pt")  # a snapshot, written after a round while the run goes on
    assert "a snapshot after" in torch.load(out / "pretrained.pt", weights_only=False)["note"]
    assert process.poll() is None
    process.send_signal(getattr(signal, stop_signal))
    try:
        stdout, stderr = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:  # say where it was: its last lines, and py-spy's stack where installed
        spy = shutil.which("py-spy") or shutil.which("py-spy", path=os.path.dirname(sys.executable))
        stack = subprocess.run([spy, "dump", "--pid", str(process.pid)], capture_output=True, text=True,
                               timeout=60).stdout if spy else "(no py-spy)"
        process.kill()
        stdout, stderr = process.communicate()
        pytest.fail(f"still running 120 s after {stop_signal}:\n{stack}\nstdout: {stdout[-1500:]}\n"
                    f"stderr: {stderr[-1500:]}")
    assert process.returncode == 0, stderr
    assert "interrupted, writing the policy" in stdout
    load_policy(out / "pretrained.pt")
    note = torch.load(out / "pretrained.pt", weights_only=False)["note"]
    assert "a snapshot" not in note and "rounds" in note
    assert (out / "pretrain.json").exists()
    assert not list(out.glob(".*.tmp"))


def test_a_stop_signal_swallowed_by_a_finalizer_still_ends_the_run(tmp_path, monkeypatch):
    """A KeyboardInterrupt that the stop handler raises while a finalizer runs is swallowed by
    Python ("Exception ignored in ..."); the run must stop at the end of that round all the same,
    write what it learnt and put the signal handlers back."""
    import signal

    from learner.pretrain import PretrainConfig, run_pretrain

    swallowed = []
    monkeypatch.setattr(sys, "unraisablehook", lambda hook_args: swallowed.append(hook_args.exc_type))

    class SignalsWhenCollected:
        def __del__(self):
            signal.raise_signal(signal.SIGTERM)  # the handler runs here, inside the finalizer

    def log(line: str) -> None:
        if " round 0 " in line:  # the log counts rounds from 0: the first
            SignalsWhenCollected()  # collected at once: its finalizer signals

    before = signal.getsignal(signal.SIGTERM)
    config = PretrainConfig(scenario="easy", rounds=30, steps_per_round=50, torch_threads=1, minutes=5.0)
    path = run_pretrain(config, tmp_path / "pre", "test", log=log, save_every_s=0.0)
    assert swallowed == [KeyboardInterrupt]  # the exception did not reach the loop
    record = json.loads((tmp_path / "pre" / "pretrain.json").read_text())
    assert record["rounds"] == 1  # stopped at the end of the round it came in, not after 30
    assert "1 rounds" in torch.load(path, weights_only=False)["note"]
    assert signal.getsignal(signal.SIGTERM) is before


def test_pretrain_widens_the_initial_network_and_keeps_its_driving(tmp_path):
    out = tmp_path / "wide"
    result = crossway("pretrain", "--scenario", "easy", "--rounds", "1", "--steps-per-round", "50",
                      "--init-from", "models/easy-student-guard.pt", "--network", "16,24,160", "--threads", "1",
                      "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "network 16,24,160" in result.stdout
    wide = load_policy(out / "pretrained.pt")
    assert (wide.config.conv1_channels, wide.config.conv2_channels, wide.config.hidden) == (16, 24, 160)
    # a few Adam steps from the widened start: the policy still drives as the one it grew from
    narrow = load_policy("models/easy-student-guard.pt")
    views = torch.randint(0, 256, (8, 16, 84, 84), dtype=torch.uint8).float() / 255
    speeds = torch.rand(8, 2)
    with torch.no_grad():
        drift = max(float((a - b).abs().max()) for a, b in zip(wide(views, speeds), narrow(views, speeds)))
    assert drift < 0.2


def _with_other_views(checkpoint: str, tmp_path):
    """A copy of ``checkpoint`` that says it learnt from a 70 m view square 15 m ahead."""
    wide = tmp_path / "wide-views.pt"
    state = torch.load(checkpoint, weights_only=False)
    state["views"] = {"extent_m": 70.0, "shift_m": 15.0}
    torch.save(state, wide)
    return wide


def test_a_policy_teacher_labels_every_car_with_its_gaussian_means(tmp_path):
    """--teacher-checkpoint (policy distillation): the labels are the teacher's means as
    ``crossway evaluate`` drives it, for the cars the teacher drives and the student drives alike."""
    from evaluation.policy import PolicyDriver
    from learner.pretrain import PretrainConfig, Pretrainer

    teacher_file = "models/easy-student-guard.pt"
    trainer = Pretrainer(PretrainConfig(scenario="easy", teacher_checkpoint=teacher_file, teacher_half_life=1.0,
                                        torch_threads=1, seed=4))
    teacher = PolicyDriver(trainer.sim, load_policy(teacher_file))
    checked = 0
    for step in range(60):
        if step == 1:
            trainer.by_teacher[::2] = False  # the student drives these cars' episodes from now on
        result, present = trainer.result, np.flatnonzero(trainer.sim.learners_present)
        expected = np.clip(teacher.act(result)[present] / ACTION_SCALE, -1.0, 1.0)
        lengths = [len(trainer.episodes[slot].targets) for slot in present]
        trainer.collect(1)
        for k, slot in enumerate(present.tolist()):
            targets = trainer.episodes[slot].targets
            if len(targets) == lengths[k] + 1:  # the episode goes on: its newest label is this step's
                np.testing.assert_allclose(targets[-1], expected[k], atol=1e-5)
                checked += 1
    assert checked > 60 and not trainer.by_teacher[present].all()  # labelled whoever drove
    with pytest.raises(ValueError, match="teacher_sight, teacher_brake_for_blockers shape the scripted teacher"):
        Pretrainer(PretrainConfig(scenario="easy", teacher_checkpoint=teacher_file, teacher_sight="view",
                                  teacher_brake_for_blockers=True))
    with pytest.raises(ValueError, match="learnt from a 70 m view square 15 m ahead"):
        Pretrainer(PretrainConfig(scenario="easy", teacher_checkpoint=_with_other_views(teacher_file, tmp_path)))


def test_every_pretrain_setting_has_the_flag_its_messages_name():
    import dataclasses

    from crossway.cli import build_parser
    from crossway.commands.pretrain import flag
    from learner.pretrain import PretrainConfig

    subparsers = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    options = {o for action in subparsers.choices["pretrain"]._actions for o in action.option_strings}
    fields = [field.name for field in dataclasses.fields(PretrainConfig)]
    assert [name for name in fields if flag(name) not in options] == []
    assert flag("torch_threads") == "--threads" and flag("brake_weight") == "--brake-weight"


@pytest.mark.parametrize("args, message", [
    (["--teacher-checkpoint", "models/easy-student-guard.pt", "--teacher-sight", "view",
      "--teacher-patience", "2"], "--teacher-sight, --teacher-patience shape the scripted teacher"),
    (["--teacher-checkpoint", "models/nothing-here.pt"], "no checkpoint file"),
])
def test_pretrain_refuses_a_policy_teacher_with_scripted_options_or_no_file(tmp_path, args, message):
    result = crossway("pretrain", "--out", str(tmp_path / "never"), *args)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert not (tmp_path / "never").exists()


def test_a_driver_checkpoint_drives_the_students_episodes_and_the_teacher_still_labels_them(tmp_path):
    """--driver-checkpoint: where the teacher does not drive, the fixed policy's means are the actions
    the simulator gets (not the student's); the labels stay the scripted teacher's, and the prioritized
    error stays the student's own."""
    from evaluation.policy import PolicyDriver
    from learner.pretrain import PretrainConfig, Pretrainer

    driver_file = "models/easy-student-guard.pt"
    trainer = Pretrainer(PretrainConfig(scenario="easy", driver_checkpoint=driver_file, teacher_half_life=1.0,
                                        priority_exponent=1.0, torch_threads=1, seed=6))
    sim = trainer.sim
    driver = PolicyDriver(sim, load_policy(driver_file))
    student = PolicyDriver(sim, trainer.policy)  # random weights: it drives unlike the driver
    sent = []
    real_step = sim.step
    sim.step = lambda actions: sent.append(actions.copy()) or real_step(actions)
    checked, apart = 0, 0.0
    for step in range(40):
        trainer.by_teacher[:] = step % 2 == 1  # the driver on even steps, the teacher on odd ones
        result = trainer.result
        present = np.flatnonzero(sim.learners_present & ~result.started)  # a new episode draws its driver anew
        expected, own = driver.act(result), student.act(result)
        lengths = [len(trainer.episodes[slot].errors) for slot in present]
        trainer.collect(1)
        if step % 2 == 0 and len(present):
            np.testing.assert_allclose(sent[-1][present], expected[present], atol=1e-6)
            apart = max(apart, np.abs(sent[-1][present, 0] - own[present, 0]).max())
            for k, slot in enumerate(present.tolist()):
                episode = trainer.episodes[slot]
                if len(episode.errors) == lengths[k] + 1:  # the episode goes on: its newest step is this one
                    label = episode.targets[-1][0]
                    assert episode.errors[-1] == pytest.approx(abs(own[slot, 0] / ACTION_SCALE[0] - label), abs=1e-5)
                    checked += 1
    assert checked > 20 and apart > 1.0  # [m/s2]: the cars got the driver's accelerations, not the student's
    sim.step = real_step
    trainer.by_teacher[:] = False
    trainer.config = replace(trainer.config, teacher_half_life=1e-9)  # from now on the driver drives every episode
    trainer.collect(400)
    assert trainer.episodes_finished["student"] >= 3 and trainer.outcomes["student"].count("goal") >= 3
    with pytest.raises(ValueError, match="driver .* learnt from a 70 m view square 15 m ahead"):
        Pretrainer(PretrainConfig(scenario="easy", driver_checkpoint=_with_other_views(driver_file, tmp_path)))


def test_pretrain_refuses_a_driver_checkpoint_that_is_no_policy(tmp_path):
    result = crossway("pretrain", "--out", str(tmp_path / "never"), "--driver-checkpoint", "models/nothing-here.pt")
    assert result.returncode == 2 and "no checkpoint file" in result.stderr, result.stderr
    assert not (tmp_path / "never").exists()


def test_pretrain_takes_the_absolute_acceleration_loss_and_records_it(tmp_path):
    import json

    from learner.pretrain import PretrainConfig, Pretrainer

    out = tmp_path / "median"
    result = crossway("pretrain", "--scenario", "easy", "--rounds", "1", "--steps-per-round", "50",
                      "--acceleration-loss", "absolute", "--threads", "1", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "absolute acceleration error" in result.stdout
    assert json.loads((out / "pretrain.json").read_text())["config"]["acceleration_loss"] == "absolute"
    refused = crossway("pretrain", "--scenario", "easy", "--acceleration-loss", "huber", "--out", str(tmp_path / "x"))
    assert refused.returncode == 2 and "invalid choice: 'huber'" in refused.stderr
    assert not (tmp_path / "x").exists()
    with pytest.raises(ValueError, match="acceleration_loss must be one of"):
        Pretrainer(PretrainConfig(scenario="easy", acceleration_loss="huber"))
