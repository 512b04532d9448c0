"""The scripts behind numbers and pictures in docs/ still run and say what the docs rely on."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_view_reach_picture_shows_no_crossing_car_in_the_egos_obstacle_view(tmp_path):
    out = tmp_path / "reach.png"
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/view_reach.py"), str(out)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the claim of the picture, checked on the simulator itself: at its stop line the ego's
    # obstacle view holds the ego alone, though two crossing cars are one second from their lines
    sys.path.insert(0, str(ROOT / "docs/scripts"))
    try:
        import view_reach
    finally:
        sys.path.pop(0)
    sim, result, ego = view_reach.scene()
    obstacles = result.views[ego].reshape(4, 4, 84, 84)[2, -1]  # channel 2, newest frame
    ego_only = obstacles > 0
    assert 10 < ego_only.sum() < 60  # one car of 4.5 x 1.8 m at 0.6 m per pixel: about 25 pixels
    rows, cols = np.nonzero(ego_only)
    assert abs(rows.mean() - 41.5) < 3 and abs(cols.mean() - 41.5) < 3  # all of it at the centre
    assert sim.present.sum() == 3


def test_teacher_crashes_prints_its_counts(tmp_path):
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/teacher_crashes.py"), "--episodes", "40",
                             "--delay-max", "5"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["episodes"] >= 40 and sum(report["end_reasons"].values()) == report["episodes"]
    assert sum(report["priority_car_first_seen_at"].values()) == report["crashed_into_priority"]


def test_teacher_sight_prints_one_line_per_window():
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/teacher_sight.py"), "--episodes", "3",
                             "--scenario", "easy"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [(l["sight_m"], l["sight_shift_m"]) for l in lines] == [
        (25.0, 0.0), (25.0, 15.0), (35.0, 0.0), (35.0, 15.0), (50.0, 0.0), (None, 0.0)]
    assert all(l["episodes"] >= 12 and abs(l["reach"] + l["crash"] + l["time_over"] - 1.0) < 0.002 for l in lines)


def test_brake_learnability_scores_both_sets_after_every_epoch():
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/brake_learnability.py"), "--train-samples",
                             "1500", "--held-out-samples", "800", "--epochs", "1", "--threads", "1"],
                            capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [e["epoch"] for e in report["epochs"]] == [0, 1] and report["epochs"][1]["updates"] > 0
    for epoch in report["epochs"]:
        for name in ("train", "held_out"):
            scores = epoch[name]
            assert scores["samples"] > 0 and 0.0 <= scores["braking_share"] <= 1.0
            assert scores["mse_acc"] >= 0.0
    # the training set is the one learnt from: its error falls
    assert report["epochs"][1]["train"]["mse_acc"] < report["epochs"][0]["train"]["mse_acc"]


def test_row_seen_in_time_sorts_every_infraction():
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/row_seen_in_time.py"), "--episodes", "12"],
                            capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert (report["scenario"], report["episodes"]) == ("easy", 12)
    assert 0 <= report["seen_in_time_by_centre"] <= report["seen_in_time"] <= report["infractions"]
    assert report["infractions"] > 0  # the view-limited driver commits some in 12 synchronised easy starts


def _run_script(name: str, *args: str) -> dict:
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts" / name), *args], capture_output=True,
                            text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])


def test_crash_kinds_counts_every_episode_with_the_scripted_driver_and_with_a_policy():
    scripted = _run_script("crash_kinds.py", "--episodes", "30", "--delay-max", "3", "--brake-for-blockers")
    policy = _run_script("crash_kinds.py", "--episodes", "6", "--delay-max", "3",
                         "--checkpoint", "models/easy-student-guard.pt")
    assert scripted["driver"]["scripted_brake_for_blockers"] is True
    assert policy["driver"] == {"checkpoint": "models/easy-student-guard.pt"}
    for report in (scripted, policy):
        assert sum(report["outcomes"].values()) == report["episodes"] >= 6
        # one count of standing cars per time-over, each counting at least the car that ran out of time
        # when it stood; never more cars than the junction holds
        assert len(report["cars_standing_at_each_time_over"]) == report["outcomes"].get("time_over", 0)
        assert all(0 <= n <= 16 for n in report["cars_standing_at_each_time_over"])
        assert sum(report["crash_pairs"].values()) <= report["outcomes"].get("crash", 0)
        # the state before each entry of a car without priority into the zone, one per such crash
        assert len(report["at_that_entry"]) == report["lower_car_entered_the_zone_first"]
        assert all(entry["lower_gap_m"] >= 0.0 and entry["upper_gap_m"] >= 0.0 for entry in report["at_that_entry"])


def test_crash_kinds_drives_the_hard_teacher_with_its_options():
    report = _run_script("crash_kinds.py", "--scenario", "hard", "--episodes", "20", "--delay-max", "5",
                         "--approach-speed", "2", "--brake-for-blockers", "--wait-outside-zones",
                         "--break-wait-cycles", "--patience", "inf")
    driver = report["driver"]
    assert driver["scripted_wait_outside_zones"] and driver["scripted_break_wait_cycles"]
    assert driver["scripted_patience_s"] == "never" and driver["scripted_approach_mps"] == 2.0
    assert sum(report["outcomes"].values()) == report["episodes"] >= 20


def _hard_restarting(restart: str):
    """The hard scenario with its cars restarting after a sign redraw as ``restart`` says."""
    from dataclasses import replace

    from simcore.scenario import load_scenario

    spec = load_scenario("hard")
    return replace(spec, episodes=replace(spec.episodes, sign_change_restart=restart))


def test_burst_starts_splits_table1s_own_episodes_by_how_they_began():
    from evaluation.table1 import TestSpec, run_test
    from simcore.controller import DriverOptions

    teacher = ("--brake-for-blockers", "--wait-outside-zones", "--break-wait-cycles")
    # 90 episodes at delay_max 10 s outlast the first redraw (120 s) of the hard junction's signs
    report = _run_script("burst_starts.py", "--delays", "10", "--episodes", "90", "--workers", "1", "--seed", "5",
                         "--sign-restart", "together", *teacher)
    assert report["driver"]["scripted_wait_outside_zones"] and report["sign_change_interval_s"] == 120.0
    assert report["sign_change_restart"] == "together"
    split = report["counts"]
    assert report["summary"]["burst/all"]["episodes"] > 0 and report["summary"]["staggered/all"]["episodes"] > 0
    # the same episodes crossway evaluate table1 counts for that test (same seed), only split by start
    options = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                            wait_outside_zones=True, break_wait_cycles=True)
    table1 = run_test(TestSpec(_hard_restarting("together"), 10.0, 90, seed=5, checkpoint=None,
                               scripted=options))["counts"]
    for sign, outcomes in table1.items():
        for outcome, n in outcomes.items():
            assert sum(split[kind].get(sign, {}).get(outcome, 0) for kind in ("reset", "burst", "staggered")) == n
    assert report["summary"]["reset/all"]["episodes"] == 8  # the test's one job: its eight lanes' first episodes
    never = _run_script("burst_starts.py", "--delays", "10", "--episodes", "90", "--workers", "1", "--seed", "5",
                        "--sign-change-interval", "0", *teacher)
    assert never["counts"]["burst"] == {} and never["summary"]["staggered/all"]["episodes"] == 90 - 8


def test_burst_waits_accounts_for_every_second_of_every_episode():
    from evaluation.table1 import TestSpec, run_test
    from simcore.controller import DriverOptions
    from simcore.dynamics import DT

    # 90 episodes at delay_max 10 s outlast the first redraw (120 s): both kinds of start occur
    report = _run_script("burst_waits.py", "--delay-max", "10", "--episodes", "90", "--seed", "5", "--snapshots", "0",
                         "--sign-restart", "together")
    counts, seconds = report["counts"], report["mean_seconds_by_reason"]
    assert report["driver"]["scripted_break_wait_cycles"] and sum(
        n for group, n in counts.items() if group.count("/") == 1) == 90
    assert counts["burst/goal"] > 0 and counts["staggered/goal"] > 0
    # the teacher drives as in crossway evaluate table1 with the same seed: the same outcomes
    options = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                            wait_outside_zones=True, break_wait_cycles=True)
    table1 = run_test(TestSpec(_hard_restarting("together"), 10.0, 90, seed=5, checkpoint=None,
                               scripted=options))["counts"]
    for sign, outcomes in table1.items():
        for outcome, n in outcomes.items():
            assert sum(counts.get(f"{kind}/{sign}/{outcome}", 0) for kind in ("burst", "staggered")) == n
    for group, reasons in seconds.items():
        total = sum(reasons.values())  # every step of an episode is filed under one reason
        assert set(reasons) <= {"moving", "blocker", "priority", "blocker+priority", "other"}
        assert 1.0 < total <= 40.0 + DT, (group, total)
        if group.endswith("time_over"):
            assert abs(total - 40.0) <= 2 * DT  # a time-over lasts the whole limit
        if group.endswith("goal"):
            assert reasons["moving"] > 0.5 * total


def test_stand_labels_files_every_standing_step_and_finds_no_disagreement_when_the_teacher_drives():
    report = _run_script("stand_labels.py", "--stop-episodes", "15", "--delay-max", "10", "--seed", "5")
    assert report["driver"] == "the teacher" and report["stop_episodes"] == 15
    assert sum(counts["episodes"] for counts in report["by_outcome"].values()) == 15
    for counts in report["by_outcome"].values():
        for key in ("standing_steps", "teacher_goes", "policy_goes"):  # each step under one place
            assert counts.get(f"all/{key}", 0) == counts.get(f"before_line/{key}", 0) + counts.get(f"past_line/{key}", 0)
        # the teacher asked and the teacher driving are one driver: they always agree
        assert counts.get("all/teacher_goes_policy_holds", 0) == 0
        assert counts.get("all/policy_goes", 0) == counts.get("all/teacher_goes", 0)
        assert counts.get("all/teacher_goes_after_its_patience", 0) <= counts.get("all/teacher_goes", 0)
    assert report["by_outcome"]["goal"]["all/standing_steps"] > 0  # dense traffic: stop-sign cars stand
    policy = _run_script("stand_labels.py", "--stop-episodes", "4", "--checkpoint", "models/hard-student-untangle2.pt")
    assert policy["driver"] == "models/hard-student-untangle2.pt" and policy["stop_episodes"] == 4


def test_patience_labels_counts_nested_kinds_of_standing():
    report = _run_script("patience_labels.py", "--delay-max", "10", "--episodes", "60", "--seed", "5")
    counts = report["counts"]
    assert report["driver"]["scripted_patience_s"] == 4.0
    assert counts["car_steps"] > counts["standing_for_priority"] > 0  # dense traffic: cars wait for priority
    assert counts["standing_for_priority"] >= counts.get("patience_out_priority", 0) >= counts.get(
        "patience_out_priority_goes", 0)
    assert 0 <= counts["released_labels"] < 0.05 * counts["car_steps"]


def test_waiting_cars_prints_the_road_for_a_policy_too():
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/waiting_cars.py"), "--scenario", "easy",
                             "--episodes", "4", "--delay-max", "3", "--checkpoint", "models/easy-student-guard.pt"],
                            capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.splitlines()[-1])
    assert report["driver"] == {"checkpoint": "models/easy-student-guard.pt"}
    assert sum(report["outcomes"].values()) >= 4
    snapshot_lines = [line for line in result.stdout.splitlines() if line.startswith("  car ")]
    assert all(" stood " in line and " m/s, " in line for line in snapshot_lines)


def test_a_policy_driver_counts_standing_time_as_the_scripted_driver_does():
    sys.path.insert(0, str(ROOT / "docs/scripts"))
    try:
        from script_driver import ScriptDriver
    finally:
        sys.path.pop(0)
    from simcore.controller import DriverOptions
    from simcore.simulator import SimConfig, Simulator

    # two simulators in lockstep: both drive with the scripted driver's actions, one also runs the
    # policy driver for its standing count only
    sims = [Simulator("easy", SimConfig(delay_min_s=0.0, delay_max_s=3.0), seed=3) for _ in range(2)]
    results = [sim.reset() for sim in sims]
    scripted = ScriptDriver(sims[0], DriverOptions(brake_for_blockers=True))
    policy = ScriptDriver(sims[1], DriverOptions(), checkpoint="models/easy-student-guard.pt")
    stood = 0
    for _ in range(300):
        actions = scripted.act(results[0])
        policy.act(results[1])
        results = [sim.step(actions) for sim in sims]
        for slot in range(sims[0].num_slots):
            assert abs(scripted.standing_s(slot) - policy.standing_s(slot)) < 1e-9
            stood += scripted.standing_s(slot) > 0
    assert stood > 0  # the check compared some standing cars


def _policy_file(path, seed, **config):
    import torch

    from algo.policy import Policy, PolicyConfig

    torch.manual_seed(seed)
    policy_config = PolicyConfig(**config)
    torch.save({"policy": Policy(policy_config).state_dict(), "policy_config": vars(policy_config)}, path)
    return path


def test_weight_soup_writes_the_mean_of_the_weights_and_refuses_different_networks(tmp_path):
    import torch

    from algo.policy import load_policy

    script = str(ROOT / "docs/scripts/weight_soup.py")
    first, second = _policy_file(tmp_path / "a.pt", 1), _policy_file(tmp_path / "b.pt", 2)
    out = tmp_path / "soup.pt"
    result = subprocess.run([sys.executable, script, str(out), str(first), str(second)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    soup, a, b = (load_policy(path).state_dict() for path in (out, first, second))
    for name in a:
        assert torch.allclose(soup[name], 0.5 * (a[name] + b[name]), atol=1e-7)
    assert any(not torch.equal(soup[name], a[name]) for name in a)  # not a copy of the first
    wider = _policy_file(tmp_path / "wide.pt", 3, hidden=64)
    refused = subprocess.run([sys.executable, script, str(tmp_path / "bad.pt"), str(first), str(wider)],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode != 0
    assert "different networks" in refused.stderr
    assert not (tmp_path / "bad.pt").exists()


def test_ensemble_writes_one_network_driving_by_its_members_mean_and_refuses_other_views(tmp_path):
    import numpy as np
    import torch

    from algo.policy import Caution, load_policy, preprocess
    from evaluation.policy import export_policy

    script = str(ROOT / "docs/scripts/ensemble.py")
    first, second = _policy_file(tmp_path / "a.pt", 1), _policy_file(tmp_path / "b.pt", 2, hidden=64)
    out = tmp_path / "joined.pt"
    result = subprocess.run([sys.executable, script, str(out), str(first), str(second)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    joined, a, b = (load_policy(path) for path in (out, first, second))
    assert (joined.config.conv1_channels, joined.config.hidden) == (32, 192)
    views, scalars = preprocess(np.random.default_rng(3).integers(0, 256, (4, 16, 84, 84), dtype=np.uint8),
                                np.array([[float(i), 8.0] for i in range(4)]))
    with torch.no_grad():
        v_joined, v_a, v_b = (policy(views, scalars)[1] for policy in (joined, a, b))
    torch.testing.assert_close(v_joined, 0.5 * (v_a + v_b), atol=1e-5, rtol=1e-5)
    assert len(torch.load(out, weights_only=False)["members"]) == 2  # the members, not the joined zero blocks
    third = _policy_file(tmp_path / "c.pt", 3)
    again = tmp_path / "again.pt"  # an ensemble joins in as its members: each of the three counts a third
    result = subprocess.run([sys.executable, script, str(again), str(out), str(third)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert len(torch.load(again, weights_only=False)["members"]) == 3
    with torch.no_grad():
        v_again, v_c = load_policy(again)(views, scalars)[1], load_policy(third)(views, scalars)[1]
    torch.testing.assert_close(v_again, (v_a + v_b + v_c) / 3, atol=1e-5, rtol=1e-5)
    cautious = tmp_path / "cautious.pt"  # the same members under another rule
    result = subprocess.run([sys.executable, script, str(cautious), str(again), "--caution", "0.5",
                             "--caution-fade-standing", "3"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "caution: acceleration minus 0.5 standard deviations fading over 3 s standing" in result.stdout
    assert load_policy(cautious).caution == Caution(0.5, 3.0) and load_policy(again).caution is None
    by_sign = tmp_path / "by-sign.pt"
    result = subprocess.run([sys.executable, script, str(by_sign), str(again), "--caution", "0.5",
                             "--caution-signs", "none, yield"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "for cars at none / yield signs only" in result.stdout
    assert load_policy(by_sign).caution == Caution(0.5, signs=("none", "yield"))
    bold = tmp_path / "bold.pt"  # a negative C: boldness, here for slow cars with priority only
    result = subprocess.run([sys.executable, script, str(bold), str(again), "--caution=-1", "--caution-signs",
                             "none,yield", "--caution-full-below-speed", "4"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert ("acceleration plus 1 standard deviations, all of it at a standstill, none from 4 m/s, "
            "for cars at none / yield signs only") in result.stdout
    assert load_policy(bold).caution == Caution(-1.0, signs=("none", "yield"), full_below_speed_mps=4.0)
    exported = export_policy(cautious, tmp_path / "exported.pt")
    assert load_policy(exported).caution == Caution(0.5, 3.0)  # export keeps the rule
    state = torch.load(cautious, weights_only=False)
    state["caution"] = {"std_factor": "much"}
    torch.save(state, tmp_path / "bad-caution.pt")
    with pytest.raises(ValueError, match="bad-caution.pt: caution: std_factor"):
        load_policy(tmp_path / "bad-caution.pt")
    for bad_args, message in (([str(first), str(second), "--caution", "nan"], "std_factor must be"),
                              ([str(first), str(second), "--caution-full-below-speed", "4"], "need --caution"),
                              ([str(first)], "at least two members"),
                              ([str(first), str(second), "--caution-fade-standing", "2"], "need --caution"),
                              ([str(first), str(second), "--caution", "1", "--caution-signs", "none,amber"],
                               "signs must name some of none, yield, stop")):
        refused = subprocess.run([sys.executable, script, str(tmp_path / "bad.pt"), *bad_args],
                                 capture_output=True, text=True, timeout=120)
        assert refused.returncode != 0 and message in refused.stderr, refused.stderr
        assert not (tmp_path / "bad.pt").exists()
    other_views = tmp_path / "wide-views.pt"
    state = torch.load(first, weights_only=False)
    state["views"] = {"extent_m": 70.0, "shift_m": 0.0}
    torch.save(state, other_views)
    refused = subprocess.run([sys.executable, script, str(tmp_path / "bad.pt"), str(first), str(other_views)],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode != 0
    assert "different view squares" in refused.stderr
    assert not (tmp_path / "bad.pt").exists()

def test_blocker_labels_sorts_every_car_step_and_reports_every_crash():
    result = subprocess.run([sys.executable, str(ROOT / "docs/scripts/blocker_labels.py"),
                             "models/hard-student-untangle2.pt", "--steps", "200", "--delay-max", "5"],
                            capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    labels = report["labels"]
    assert set(labels) == {"teacher brakes for a blocker", "teacher brakes hard for another reason", "other steps"}
    assert sum(k["share"] for k in labels.values()) == pytest.approx(1.0, abs=1e-3)
    assert all(k["car_steps"] > 0 for k in labels.values())  # 200 steps of hard traffic have each kind
    # the two braking kinds brake, on average, and harder than the other steps
    assert labels["teacher brakes hard for another reason"]["teacher_mean_mps2"] <= -1.5
    assert labels["teacher brakes for a blocker"]["teacher_mean_mps2"] < labels["other steps"]["teacher_mean_mps2"]
    assert len(report["crashes"]) == report["end_reasons"].get("crash", 0)
    assert report["teacher"]["scripted_brake_for_blockers"] is True


def test_mixed_traffic_gives_each_car_to_the_driver_its_sign_names():
    sys.path.insert(0, str(ROOT / "docs/scripts"))
    try:
        from mixed_traffic import policy_mask
    finally:
        sys.path.pop(0)
    from simcore.rightofway import Sign

    sign = np.array([Sign.STOP, Sign.YIELD, Sign.NONE, Sign.STOP])
    assert policy_mask(sign, "stop").tolist() == [True, False, False, True]
    assert policy_mask(sign, "others").tolist() == [False, True, True, False]
    assert policy_mask(sign, "all").all() and not policy_mask(sign, "none").any()
    report = _run_script("mixed_traffic.py", "--checkpoint", "models/hard-student-untangle2.pt",
                         "--policy-drives", "stop", "--stop-episodes", "6", "--delay-max", "10", "--seed", "5")
    stop = report["by_sign"]["stop"]
    assert stop["episodes"] == stop["goal"] + stop["crash"] + stop["time_over"] == 6
    assert set(report["mean_speed_mps"]) == {"policy", "teacher"}  # both drove, each its own cars
    assert all(0.0 < v < 15.0 for v in report["mean_speed_mps"].values())
    teacher_only = _run_script("mixed_traffic.py", "--checkpoint", "models/hard-student-untangle2.pt",
                               "--policy-drives", "none", "--stop-episodes", "3", "--delay-max", "10", "--seed", "5")
    assert set(teacher_only["mean_speed_mps"]) == {"teacher"}
    for run in (report, teacher_only):
        stop = run["by_sign"]["stop"]  # every standing step of a stop-sign car is filed under 1+ reasons
        stood = sum(stop[o] * stop.get(f"{o}_mean_stood_s", 0.0) for o in ("goal", "crash", "time_over"))
        reasons = run["stop_sign_stood_for_s_per_episode"]
        assert sum(reasons.values()) >= stood / stop["episodes"] - 0.01
        assert max(reasons.values(), default=0.0) <= stood / stop["episodes"] + 0.01
        assert all(r in ("blocker", "other") or r.startswith("priority ") for r in reasons)
    # the teacher slows to 2 m/s for its stop line; a car without a sign keeps more of its speed
    profile = teacher_only["speed_by_place_mps"]
    assert profile["STOP"]["-4..+0 m"] < profile["NONE"]["-4..+0 m"]


def test_sign_split_drives_stop_sign_cars_with_one_policy_and_the_rest_with_the_other():
    sys.path.insert(0, str(ROOT / "docs/scripts"))
    try:
        from sign_split import SignSplitDriver
    finally:
        sys.path.pop(0)
    from algo.policy import ACTION_SCALE, load_policy, sign_in_view
    from evaluation.policy import PolicyDriver
    from simcore.simulator import SimConfig, Simulator

    stop_policy, other_policy = "models/hard-student-untangle2.pt", "models/hard-student-untangle.pt"
    sim = Simulator("hard", SimConfig(delay_max_s=0.0), seed=3)
    result = sim.reset()
    throttle = np.zeros((sim.num_slots, 2))
    throttle[:, 0] = 1.0  # m/s^2: every car rolls towards its line, until some see a stop line
    for _ in range(40):
        result = sim.step(throttle)
    active = np.flatnonzero(sim.learners_present)
    at_stop = sign_in_view(result.views[active]) == "stop"
    assert at_stop.any() and (~at_stop).any()
    actions = SignSplitDriver(sim, ROOT / stop_policy, ROOT / other_policy).act(result)
    for cars, checkpoint in ((at_stop, stop_policy), (~at_stop, other_policy)):
        slots = active[cars]
        means, _ = PolicyDriver(sim, load_policy(ROOT / checkpoint)).heads(result.views[slots], result.scalars[slots])
        np.testing.assert_allclose(actions[slots], np.clip(means, -1, 1) * ACTION_SCALE, atol=1e-6)
    report = _run_script("sign_split.py", "--stop-checkpoint", stop_policy, "--other-checkpoint", other_policy,
                         "--episodes", "12", "--seed", "4")
    assert sum(sum(c.values()) for c in report["counts"].values()) == 12
    assert set(report["reach"]) <= {"none", "yield", "stop"} and all(0 <= r <= 1 for r in report["reach"].values())
    for bad_args, message in ((["--stop-checkpoint", "missing.pt", "--other-checkpoint", other_policy],
                               "no checkpoint file 'missing.pt'"),
                              (["--stop-checkpoint", stop_policy, "--other-checkpoint", other_policy, "--episodes", "0"],
                               "--episodes must be at least 1")):
        refused = subprocess.run([sys.executable, str(ROOT / "docs/scripts/sign_split.py"), *bad_args],
                                 capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert refused.returncode != 0 and message in refused.stderr, refused.stderr


def test_reset_starts_replays_the_episodes_table1_began_at_each_jobs_reset(tmp_path):
    """docs/results/reset-starts/reset_starts.py replays a Table I run's jobs until the episodes
    begun at each reset end: the same counts as the run's own "reset" start kind, test by test."""
    teacher = ("--scripted-sight", "view", "--scripted-approach-speed", "2", "--scripted-approach-signs", "own",
               "--scripted-brake-for-blockers", "--scripted-wait-outside-zones", "--scripted-break-wait-cycles")
    run = subprocess.run([sys.executable, "-m", "crossway", "evaluate", "table1", "--scripted", *teacher,
                          "--scenario", "easy", "--episodes", "20", "--workers", "1", "--seed", "3",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    table1 = json.loads((tmp_path / "table1-easy.json").read_text())
    result = subprocess.run([sys.executable, str(ROOT / "docs/results/reset-starts/reset_starts.py"), "teacher",
                             "--scenario", "easy", "--episodes", "20", "--seed", "3",
                             "--table1-json", str(tmp_path / "table1-easy.json")],
                            capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.splitlines()[-1])
    for test in table1["tests"]:
        assert report["per_test"][f"{test['delay_max_s']:g}"] == test["counts_by_start"]["reset"]
    for sign, reach in report["reach"].items():
        assert reach["all"] == pytest.approx(table1["table"][sign]["goal"], abs=1e-4)
        assert 0.0 <= reach["without_reset"] <= 1.0
    # refused before any replay: a run of another seed, a missing checkpoint
    for bad_args, message in ((["teacher", "--scenario", "easy", "--episodes", "20", "--seed", "4",
                                "--table1-json", str(tmp_path / "table1-easy.json")], "with --seed 3 and --episodes 20"),
                              (["missing.pt", "--scenario", "easy"], "no checkpoint file 'missing.pt'")):
        refused = subprocess.run([sys.executable, str(ROOT / "docs/results/reset-starts/reset_starts.py"), *bad_args],
                                 capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert refused.returncode != 0 and message in refused.stderr and not refused.stdout, refused.stderr


def test_rule_recall_drives_the_network_alone_and_scores_the_checkpoints_rule(tmp_path):
    wide = tmp_path / "wide-margin.pt"
    exported = subprocess.run([sys.executable, "-m", "crossway", "evaluate", "export", "--checkpoint", "models/hard.pt",
                               "--out", str(wide), "--emergency-braking", "--emergency-margin", "4"],
                              capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert exported.returncode == 0, exported.stderr
    plain = _run_script("rule_recall.py", "--checkpoint", "models/hard.pt", "--episodes", "12", "--delay-max", "3")
    wider = _run_script("rule_recall.py", "--checkpoint", str(wide), "--episodes", "12", "--delay-max", "3")
    assert plain["rule"] == {"margin_m": 1.5, "reaction_s": 0.5, "deceleration_mps2": 2.0}  # the defaults
    assert wider["rule"]["margin_m"] == 4.0
    # the rule is only scored, never applied: both runs drive the same episodes to the same ends
    assert (plain["car_steps"], plain["outcomes"]) == (wider["car_steps"], wider["outcomes"])
    assert abs(sum(plain["outcomes"].values()) - 1.0) < 1e-3 and plain["episodes"] >= 12
    # a wider margin brakes earlier and harder on the same states
    assert 0.0 < plain["override_share"] <= wider["override_share"] < 1.0
    assert 0.0 < plain["correction_mps2_per_car_step"] <= wider["correction_mps2_per_car_step"]
    for report in (plain, wider):
        assert 0.0 <= report["recall"] <= 1.0
        assert -3.0 <= report["rule_mean_mps2"] < report["network_mean_mps2"] <= 3.0


def test_split_ensemble_writes_members_that_join_again_into_the_same_network(tmp_path):
    import numpy as np
    import torch

    from algo.braking import EmergencyBraking
    from algo.policy import load_policy, preprocess

    first, second = _policy_file(tmp_path / "a.pt", 1), _policy_file(tmp_path / "b.pt", 2, hidden=64)
    joined = tmp_path / "joined.pt"
    assert subprocess.run([sys.executable, str(ROOT / "docs/scripts/ensemble.py"), str(joined), str(first),
                           str(second)], capture_output=True, text=True, timeout=120).returncode == 0
    state = torch.load(joined, weights_only=False)
    state["emergency_braking"] = EmergencyBraking(margin_m=2.0).record()
    torch.save(state, joined)
    split = subprocess.run([sys.executable, str(ROOT / "docs/scripts/split_ensemble.py"), str(joined),
                            str(tmp_path / "members")], capture_output=True, text=True, timeout=120)
    assert split.returncode == 0, split.stderr
    members = [tmp_path / "members" / f"member-{k}.pt" for k in (1, 2)]
    assert sorted((tmp_path / "members").iterdir()) == members
    views, scalars = preprocess(np.random.default_rng(5).integers(0, 256, (3, 16, 84, 84), dtype=np.uint8),
                                np.array([[float(i), 8.0] for i in range(3)]))
    with torch.no_grad():
        for member, original in zip(members, (first, second)):
            policy = load_policy(member)
            assert policy.emergency_braking == EmergencyBraking(margin_m=2.0)  # the ensemble's rule goes along
            for got, want in zip(policy(views, scalars), load_policy(original)(views, scalars)):
                torch.testing.assert_close(got, want)
    rejoined = tmp_path / "rejoined.pt"
    assert subprocess.run([sys.executable, str(ROOT / "docs/scripts/ensemble.py"), str(rejoined),
                           *map(str, members)], capture_output=True, text=True, timeout=120).returncode == 0
    with torch.no_grad():
        for got, want in zip(load_policy(rejoined)(views, scalars), load_policy(joined)(views, scalars)):
            torch.testing.assert_close(got, want)
    refused = subprocess.run([sys.executable, str(ROOT / "docs/scripts/split_ensemble.py"), str(first),
                              str(tmp_path / "none")], capture_output=True, text=True, timeout=120)
    assert refused.returncode != 0 and "not an output ensemble" in refused.stderr
    assert not (tmp_path / "none").exists()
