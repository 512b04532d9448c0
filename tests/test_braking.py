"""algo.braking: the emergency-braking rule read from the views, and its way through checkpoints."""

import subprocess
import sys

import numpy as np
import pytest
import torch

from algo.braking import EmergencyBraking, emergency_braking_from, path_gaps
from simcore.dynamics import VEHICLE_LENGTH, VEHICLE_WIDTH

METRES_PER_PX = 50.0 / 84
FRONT_M = 0.5 * VEHICLE_LENGTH
PATH_PLANES = range(4, 8)  # channel 1 (path), frames 0..3
OBSTACLE_PLANES = range(8, 12)  # channel 2 (obstacles), frames 0..3


def rows_for(forward_m: float, length_m: float) -> slice:
    """View rows covering [forward_m, forward_m + length_m] ahead of the ego's centre (row 0: farthest ahead)."""
    top = int(np.floor(42 - (forward_m + length_m) / METRES_PER_PX))
    bottom = int(np.ceil(42 - forward_m / METRES_PER_PX))
    return slice(max(top, 0), max(min(bottom, 84), 0))


def cols_for(left_m: float, width_m: float) -> slice:
    """View columns covering [left_m - width/2, left_m + width/2] to the ego's left (image left)."""
    first = int(np.floor(42 - (left_m + 0.5 * width_m) / METRES_PER_PX))
    last = int(np.ceil(42 - (left_m - 0.5 * width_m) / METRES_PER_PX))
    return slice(first, last)


def views_with(gaps_m: list[float | None], left_m: float = 0.0) -> np.ndarray:
    """One car's views [1, 16, 84, 84]: a straight path corridor (3.5 m wide) up the image, the ego
    at the centre, and another car whose rear lies ``gaps_m[k]`` ahead of the ego's front in frame k
    (None: not in sight), ``left_m`` to its left."""
    views = np.zeros((1, 16, 84, 84), np.uint8)
    for plane in PATH_PLANES:
        views[0, plane][:, cols_for(0.0, 3.5)] = 255
    for frame, gap in enumerate(gaps_m):
        plane = views[0, OBSTACLE_PLANES[frame]]
        plane[rows_for(-FRONT_M, VEHICLE_LENGTH), cols_for(0.0, VEHICLE_WIDTH)] = 255  # the ego
        if gap is not None:
            plane[rows_for(FRONT_M + gap, VEHICLE_LENGTH), cols_for(left_m, VEHICLE_WIDTH)] = 128
    return views


def test_the_gap_is_the_distance_to_the_car_on_the_path_to_a_pixel():
    for gap in (1.0, 4.0, 9.5, 15.0):
        measured = path_gaps(views_with([gap] * 4), frame=3)[0]
        assert abs(measured - gap) <= METRES_PER_PX, (gap, measured)
    assert path_gaps(views_with([None] * 4), frame=3)[0] == np.inf  # only the ego: its own body is not in its way
    assert path_gaps(views_with([5.0] * 4, left_m=4.0), frame=3)[0] == np.inf  # beside the corridor
    assert path_gaps(views_with([21.0] * 4), frame=3)[0] == np.inf  # in sight, beyond the 20 m searched


def test_a_moving_car_brakes_for_a_car_it_closes_on_and_not_otherwise():
    rule = EmergencyBraking()
    speed = np.array([6.0])
    cruise = np.array([0.5])
    # a car standing 8 m ahead: the gap shrank by 6 m/s x 0.3 s over the four frames
    approaching = views_with([9.8, 9.2, 8.6, 8.0])
    acceleration, braked = rule.apply(approaching, speed, cruise)
    closing = 1.8 / 0.3
    assert braked[0] and acceleration[0] <= -min(closing ** 2 / (2 * (8.0 + METRES_PER_PX - 1.5)), 3.0) + 1e-9
    # the same car driving away as fast: no braking, the network's acceleration stands
    receding = views_with([8.0, 8.6, 9.2, 9.8])
    acceleration, braked = rule.apply(receding, speed, cruise)
    assert not braked[0] and acceleration[0] == 0.5
    # a car that has just entered the path: its closing speed is taken as the ego's own
    entering = views_with([None, None, None, 7.0])
    assert rule.apply(entering, speed, cruise)[1][0]
    # far enough to stop comfortably: closing 6 m/s needs 6^2 / 4 + 6 x 0.5 = 12 m beyond the 1.5 m margin
    assert not rule.apply(views_with([None, None, None, 16.0]), speed, cruise)[1][0]
    # the network braking harder than the rule asks keeps its own braking
    acceleration, braked = rule.apply(approaching, speed, np.array([-3.0]))
    assert braked[0] and acceleration[0] == -3.0
    # the rule's braking lies within the action's limits
    acceleration, _ = rule.apply(views_with([1.6, 1.3, 1.0, 0.7]), speed, cruise)
    assert acceleration[0] == -3.0


def test_a_standing_car_does_not_start_into_a_car_within_the_margin():
    rule = EmergencyBraking(margin_m=1.5)
    standing = np.array([0.0])
    acceleration, braked = rule.apply(views_with([1.0] * 4), standing, np.array([2.0]))
    assert acceleration[0] == 0.0 and not braked[0]  # held, not counted as braking
    acceleration, _ = rule.apply(views_with([5.0] * 4), standing, np.array([2.0]))
    assert acceleration[0] == 2.0


def test_rows_apply_independently():
    rule = EmergencyBraking()
    views = np.concatenate([views_with([9.8, 9.2, 8.6, 8.0]), views_with([None] * 4), views_with([8.0, 8.6, 9.2, 9.8])])
    acceleration, braked = rule.apply(views, np.array([6.0, 6.0, 6.0]), np.array([1.0, 1.0, 1.0]))
    assert braked.tolist() == [True, False, False] and acceleration[1:].tolist() == [1.0, 1.0]


def test_bad_settings_and_entries_are_refused_with_their_name():
    with pytest.raises(ValueError, match="margin_m"):
        EmergencyBraking(margin_m=-1.0)
    with pytest.raises(ValueError, match="deceleration_mps2"):
        EmergencyBraking(deceleration_mps2=5.0)
    assert emergency_braking_from("x.pt", None) is None
    assert emergency_braking_from("x.pt", EmergencyBraking(2.0).record()) == EmergencyBraking(2.0)
    with pytest.raises(ValueError, match=r"x\.pt: its emergency_braking entry does not match"):
        emergency_braking_from("x.pt", {"margin": 1.0})
    with pytest.raises(ValueError, match=r"x\.pt: emergency braking: reaction_s"):
        emergency_braking_from("x.pt", {"reaction_s": float("nan")})


def crossway(*args):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=120)


def test_export_stores_keeps_and_drops_the_rule_and_the_driver_applies_it(tmp_path):
    from algo.policy import Policy, PolicyConfig, load_policy
    from evaluation.policy import PolicyDriver
    from simcore.simulator import SimConfig, Simulator

    torch.manual_seed(5)
    plain = tmp_path / "plain.pt"
    torch.save({"policy": Policy(PolicyConfig()).state_dict(), "policy_config": {}}, plain)
    braking = tmp_path / "braking.pt"
    result = crossway("evaluate", "export", "--checkpoint", str(plain), "--out", str(braking), "--emergency-braking",
                      "--emergency-margin", "2")
    assert result.returncode == 0, result.stderr
    assert "emergency braking" in result.stdout
    assert load_policy(braking).emergency_braking == EmergencyBraking(margin_m=2.0)
    kept, dropped = tmp_path / "kept.pt", tmp_path / "dropped.pt"
    assert crossway("evaluate", "export", "--checkpoint", str(braking), "--out", str(kept)).returncode == 0
    assert load_policy(kept).emergency_braking == EmergencyBraking(margin_m=2.0)
    assert crossway("evaluate", "export", "--checkpoint", str(braking), "--out", str(dropped),
                    "--no-emergency-braking").returncode == 0
    assert load_policy(dropped).emergency_braking is None
    refused = crossway("evaluate", "export", "--checkpoint", str(plain), "--out", str(tmp_path / "x.pt"),
                       "--emergency-margin", "2")
    assert refused.returncode != 0 and "go with --emergency-braking" in refused.stderr
    assert not (tmp_path / "x.pt").exists()

    # a real simulator: the hard junction full of cars driving on untrained weights (about 0.5 m/s^2,
    # never braking), so they close on each other; the rule brakes some of them, and only those
    sim = Simulator("hard", SimConfig(delay_min_s=0.0, delay_max_s=2.0), seed=1)
    with_rule, without = PolicyDriver(sim, load_policy(braking)), PolicyDriver(sim, load_policy(plain))
    result = sim.reset()
    changed = 0
    for _ in range(300):
        actions = with_rule.act(result)
        network = without.act(result)
        differs = np.flatnonzero(np.abs(actions - network).sum(1) > 0)
        assert (actions[differs, 0] <= np.minimum(network[differs, 0], 0.0)).all()  # only ever slower, never faster
        assert np.array_equal(actions[:, 1], network[:, 1])  # steering untouched
        changed += len(differs)
        result = sim.step(actions)
    assert with_rule.braked_car_steps > 0 and changed >= with_rule.braked_car_steps
    assert without.braked_car_steps == 0


def test_table1_reports_how_often_the_rule_overrode_the_network(tmp_path):
    import json

    from algo.policy import Policy, PolicyConfig

    torch.manual_seed(5)
    checkpoint = tmp_path / "braking.pt"
    torch.save({"policy": Policy(PolicyConfig()).state_dict(), "policy_config": {},
                "emergency_braking": EmergencyBraking().record()}, checkpoint)
    result = crossway("evaluate", "table1", "--checkpoint", str(checkpoint), "--scenario", "hard", "--episodes", "8",
                      "--sweep-up-to", "10", "--workers", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    test = json.loads((tmp_path / "out" / "table1-hard.json").read_text())["tests"][0]
    assert 0 < test["braked_car_steps"] < test["car_steps"]
    page = (tmp_path / "out" / "table1-hard.md").read_text()
    assert f"overrode the network in {test['braked_car_steps']} of {test['car_steps']} car-steps" in page
