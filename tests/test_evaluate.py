"""crossway evaluate: the Table I protocol end to end on tiny budgets."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from algo.policy import PolicyConfig
from evaluation.table1 import delay_schedule, summarise
from learner.core import LearnerCore
from simcore.controller import DriverOptions


def crossway(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=timeout)


def test_delay_schedule_matches_the_paper():
    assert delay_schedule(30) == [10, 20, 30]
    assert len(delay_schedule(50)) == 5 and len(delay_schedule(100)) == 10


def test_summary_averages_fractions_over_tests():
    tests = [
        {"counts": {"stop": {"goal": 3, "crash": 1}}, "speed_sum": {"stop": 32.0}},
        {"counts": {"stop": {"goal": 1, "time_over": 1}}, "speed_sum": {"stop": 10.0}},
    ]
    table = summarise(tests)
    assert table["stop"]["goal"] == pytest.approx((0.75 + 0.5) / 2)
    assert table["stop"]["crash"] == pytest.approx(0.125)
    assert table["stop"]["time_over"] == pytest.approx(0.25)
    assert table["stop"]["speed_mps"] == pytest.approx((8.0 + 5.0) / 2)
    assert table["stop"]["episodes"] == 6 and "none" not in table


def test_table1_scripted_end_to_end(tmp_path):
    result = crossway("evaluate", "table1", "--scripted", "--scenario", "easy", "--episodes", "6",
                      "--workers", "2", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "| Reaches |" in result.stdout
    report = json.loads((tmp_path / "table1-easy.json").read_text())
    assert [t["delay_max_s"] for t in report["tests"]] == [10.0, 20.0, 30.0]
    assert sum(sum(c.values()) for t in report["tests"] for c in t["counts"].values()) == 18
    rows = list(csv.DictReader(open(tmp_path / "table1-easy.csv")))
    assert set(rows[0]) == {"sign", "metric", "ours", "paper"}
    assert {r["metric"] for r in rows} == {"goal", "crash", "off_path", "time_over", "speed_mps", "goal_stderr"}
    tests = list(csv.DictReader(open(tmp_path / "table1-easy-tests.csv")))
    assert list(tests[0]) == ["delay_max_s", "sign", "episodes", "goal", "crash", "off_path", "time_over",
                              "speed_mps"]
    every = [r for r in tests if r["sign"] == "all"]
    assert [float(r["delay_max_s"]) for r in every] == [10.0, 20.0, 30.0]
    assert [int(r["episodes"]) for r in every] == [6, 6, 6]
    page = (tmp_path / "table1-easy.md").read_text()
    assert "(paper)" in page and "| Reaches, standard error |" in page and "## Per test" in page
    assert f"torch {torch.__version__}" in page  # the page says what it ran on
    import cairo  # the per-test picture: a real PNG, linked from the page

    picture = cairo.ImageSurface.create_from_png(str(tmp_path / "table1-easy-tests.png"))
    assert (picture.get_width(), picture.get_height()) == (800, 480)
    assert "](table1-easy-tests.png)" in page


def test_table1_sweep_up_to_runs_the_densest_tests_with_their_own_seeds(tmp_path):
    """--sweep-up-to S runs only the tests with delay_max <= S, each with the seeds it has in the
    whole protocol: the same episodes as those tests of a whole run, and the page says it is a part."""
    whole = crossway("evaluate", "table1", "--scripted", "--scenario", "easy", "--episodes", "6",
                     "--workers", "2", "--out", str(tmp_path / "whole"))
    part = crossway("evaluate", "table1", "--scripted", "--scenario", "easy", "--episodes", "6",
                    "--workers", "1", "--sweep-up-to", "20", "--out", str(tmp_path / "part"))
    assert whole.returncode == 0 and part.returncode == 0, whole.stderr + part.stderr
    whole_report = json.loads((tmp_path / "whole" / "table1-easy.json").read_text())
    part_report = json.loads((tmp_path / "part" / "table1-easy.json").read_text())
    assert part_report["meta"]["delays_max_s"] == [10.0, 20.0]
    assert part_report["meta"]["protocol_delays_max_s"] == [10.0, 20.0, 30.0]
    assert [t["counts"] for t in part_report["tests"]] == [t["counts"] for t in whole_report["tests"][:2]]
    assert "Only the tests with delay_max 10 to 20 s of the protocol's 10 to 30 s" in \
        (tmp_path / "part" / "table1-easy.md").read_text()
    assert "Only the tests" not in (tmp_path / "whole" / "table1-easy.md").read_text()
    refused = crossway("evaluate", "table1", "--scripted", "--scenario", "easy", "--episodes", "6",
                       "--sweep-up-to", "5", "--out", str(tmp_path / "none"))
    assert refused.returncode != 0 and "--sweep-up-to must be at least" in refused.stderr
    assert not (tmp_path / "none" / "table1-easy.json").exists()


def test_table1_splits_hards_episodes_by_how_they_began(tmp_path):
    """Hard redraws its signs every 120 s and restarts every lane: Table I says how the episodes
    that began right after a redraw did, apart from the others (none of them on easy). With
    --sign-restart together every lane starts at once then, a burst of eight; by default each
    waits its own random delay, and few episodes begin within two steps of a redraw. Every lane's
    first episode of a job began at the job's reset, all lanes at once: those are counted apart too."""
    result = crossway("evaluate", "table1", "--scripted", "--scenario", "hard", "--episodes", "40",
                      "--workers", "2", "--sign-restart", "together", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "table1-hard.json").read_text())
    assert report["meta"]["sign_change_restart"] == "together" and report["meta"]["sign_change_interval_s"] == 120
    starts = report["by_start"]
    assert starts["burst"]["all"]["episodes"] > 0 and starts["staggered"]["all"]["episodes"] > 0
    assert starts["burst"]["all"]["episodes"] + starts["staggered"]["all"]["episodes"] + \
        starts["reset"]["all"]["episodes"] == 400
    # one job per test (40 episodes): its eight lanes' first episodes, unless a redraw cut one
    assert 0 < starts["reset"]["all"]["episodes"] <= 8 * 10
    for sign in ("none", "yield", "stop"):  # every counted episode in one of the two, sign by sign
        pooled = sum(starts[k][sign]["episodes"] for k in starts if sign in starts[k])
        assert pooled == report["table"][sign]["episodes"]
    for rows in starts.values():
        for row in rows.values():
            assert sum(row[o] for o in ("goal", "crash", "off_path", "time_over")) == pytest.approx(1.0)
    lines = list(csv.DictReader(open(tmp_path / "table1-hard-starts.csv")))
    assert list(lines[0]) == ["began", "sign", "episodes", "goal", "crash", "off_path", "time_over"]
    assert {r["began"] for r in lines} == {"reset", "burst", "staggered"}
    assert "when every lane starts at once" in (tmp_path / "table1-hard.md").read_text()

    delayed = crossway("evaluate", "table1", "--scripted", "--scenario", "hard", "--episodes", "40",
                       "--workers", "2", "--out", str(tmp_path / "delayed"))
    assert delayed.returncode == 0, delayed.stderr
    report = json.loads((tmp_path / "delayed" / "table1-hard.json").read_text())
    assert report["meta"]["sign_change_restart"] == "delayed"  # the scenario file's default
    bursts = report["by_start"].get("burst", {}).get("all", {}).get("episodes", 0)
    assert bursts + report["by_start"]["staggered"]["all"]["episodes"] + \
        report["by_start"]["reset"]["all"]["episodes"] == 400
    assert bursts < starts["burst"]["all"]["episodes"] / 4  # the cars no longer start together
    cut = sum(sum(t["cut_by_redraw"].values()) for t in report["tests"])
    assert cut > 0  # 40 episodes a test outlast a redraw; those cut short are counted apart
    page = (tmp_path / "delayed" / "table1-hard.md").read_text()
    assert f"Episodes cut short by a sign redraw, not counted above: {cut} (" in page
    # the counted episodes that began 40 s or more before the next redraw: a subset, reported apart
    uncut = report["uncuttable"]["all"]
    assert 0 < uncut["episodes"] < 400 and sum(uncut[o] for o in ("goal", "crash", "off_path", "time_over")) == \
        pytest.approx(1.0)
    assert f"which no redraw could cut ({uncut['episodes']}, all tests pooled)" in page

    # easy never redraws, so no bursts; each of its three tests (one job of 20 episodes) begins with
    # its three lanes at once, and nothing cuts those episodes short
    easy = crossway("evaluate", "table1", "--scripted", "--scenario", "easy", "--episodes", "20", "--workers", "1",
                    "--out", str(tmp_path / "easy"))
    assert easy.returncode == 0, easy.stderr
    starts = json.loads((tmp_path / "easy" / "table1-easy.json").read_text())["by_start"]
    assert set(starts) == {"reset", "staggered"}
    assert starts["reset"]["all"]["episodes"] == 3 * 3 and starts["staggered"]["all"]["episodes"] == 3 * 20 - 9
    page = (tmp_path / "easy" / "table1-easy.md").read_text()
    assert "## By how the episodes began" in page and "burst:" not in page and "| reset |" in page


def test_table1_scripted_with_the_views_sight(tmp_path):
    result = crossway("evaluate", "table1", "--scripted", "--scripted-sight", "view", "--scripted-approach-speed",
                      "3", "--scripted-approach-signs", "own", "--scripted-brake-for-blockers",
                      "--scripted-wait-outside-zones", "--scripted-break-wait-cycles", "--scripted-patience", "inf",
                      "--scripted-blocker-patience", "6", "--scenario", "easy",
                      "--episodes", "3", "--workers", "1", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "table1-easy.json").read_text())
    assert report["meta"]["scripted_sight_m"] == 25.0  # half the 50 m view
    assert report["meta"]["scripted_approach_mps"] == 3.0
    assert report["meta"]["scripted_approach_signs"] == "own"
    assert report["meta"]["scripted_brake_for_blockers"] is True
    assert report["meta"]["scripted_wait_outside_zones"] is True and report["meta"]["scripted_break_wait_cycles"]
    assert report["meta"]["scripted_patience_s"] == "never" and report["meta"]["scripted_blocker_patience_s"] == 6.0
    alone = crossway("evaluate", "table1", "--scripted", "--scripted-approach-signs", "own", "--out",
                     str(tmp_path / "never"))
    assert alone.returncode == 2 and "--scripted-approach-signs goes with --scripted-approach-speed" in alone.stderr
    for option in (["--scripted-sight", "view"], ["--scripted-approach-speed", "3"], ["--scripted-brake-for-blockers"],
                   ["--scripted-wait-outside-zones"], ["--scripted-break-wait-cycles"], ["--scripted-patience", "inf"],
                   ["--scripted-blocker-patience", "3"]):
        refused = crossway("evaluate", "table1", "--checkpoint", str(tmp_path / "x.pt"), *option,
                           "--out", str(tmp_path / "never"))
        assert refused.returncode == 2 and "go with --scripted, not with --checkpoint" in refused.stderr
    negative = crossway("evaluate", "table1", "--scripted", "--scripted-approach-speed", "-1", "--out",
                        str(tmp_path / "never"))
    assert negative.returncode == 2 and "must be >= 0 m/s" in negative.stderr
    impatient = crossway("evaluate", "table1", "--scripted", "--scripted-patience", "0", "--out", str(tmp_path / "never"))
    assert impatient.returncode == 2 and "--scripted-patience must be > 0 s" in impatient.stderr
    assert not (tmp_path / "never").exists()


def test_table1_with_a_checkpoint_and_a_refused_one(tmp_path):
    good = tmp_path / "good.pt"
    torch.save(LearnerCore().state_dict(), good)
    result = crossway("evaluate", "table1", "--checkpoint", str(good), "--scenario", "easy", "--episodes", "2",
                      "--workers", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "out" / "table1-easy.md").exists()
    other = tmp_path / "other.pt"
    torch.save(LearnerCore(policy_config=PolicyConfig(hidden=32)).state_dict(), other)
    state = torch.load(other, weights_only=False)
    state["policy_config"] = {"conv1_channels": 16, "conv2_channels": 16, "hidden": 128}  # lies about its sizes
    torch.save(state, other)
    refused = crossway("evaluate", "table1", "--checkpoint", str(other), "--episodes", "1", "--out", str(tmp_path))
    assert refused.returncode == 2
    assert "do not match the network" in refused.stderr and "Traceback" not in refused.stderr
    neither = crossway("evaluate", "table1", "--out", str(tmp_path))
    assert neither.returncode == 2 and "--checkpoint" in neither.stderr


def test_right_of_way_scripted_end_to_end(tmp_path):
    result = crossway("evaluate", "right-of-way", "--scripted", "--scenario", "easy", "--episodes", "4",
                      "--workers", "2", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "| No infraction |" in result.stdout
    summary = json.loads((tmp_path / "right-of-way-easy.json").read_text())
    assert summary["episodes"] == 4
    assert 0.0 <= summary["no_infraction"] <= 1.0
    assert summary["no_infraction"] + summary["infraction"] == pytest.approx(1.0)
    assert sum(summary["agent_end_reasons"].values()) == 4 * 3  # every lane's car ended, every episode
    rows = list(csv.DictReader(open(tmp_path / "right-of-way-easy.csv")))
    assert rows[0]["paper_no_infraction"] == "0.985"
    rate = summary["no_infraction"]
    assert summary["no_infraction_stderr"] == pytest.approx((rate * (1 - rate) / 4) ** 0.5)
    assert float(rows[0]["no_infraction_stderr"]) == pytest.approx(summary["no_infraction_stderr"], abs=1e-4)
    assert summary["scripted_sight"] is None
    assert "| No infraction the offender saw in time |" in result.stdout
    assert {"no_seen_infraction", "infractions", "infractions_seen_in_time", "infractions_offender_crashed"} <= set(rows[0])

    limited = crossway("evaluate", "right-of-way", "--scripted", "--scripted-sight", "view", "--scripted-approach-speed",
                       "3", "--scenario", "easy", "--episodes", "2", "--workers", "1", "--out", str(tmp_path / "view"))
    assert limited.returncode == 0, limited.stderr
    limited_summary = json.loads((tmp_path / "view" / "right-of-way-easy.json").read_text())
    assert (limited_summary["scripted_sight"], limited_summary["scripted_approach_mps"]) == ("view", 3.0)
    assert limited_summary["scripted_approach_signs"] == "all"  # the default
    assert limited_summary["scripted_brake_for_blockers"] is False  # the default
    for run in (summary, limited_summary):  # the anatomy adds up
        assert 0 <= run["infractions_seen_in_time"] <= run["infractions"]
        assert 0 <= run["infractions_offender_crashed"] <= run["infractions"]
        assert run["no_infraction"] <= run["no_seen_infraction"] <= 1.0
        assert (run["infractions"] == 0) == (run["no_infraction"] == 1.0)
        assert (run["view_extent_m"], run["view_shift_m"]) == (50.0, 0.0)
    refused = crossway("evaluate", "right-of-way", "--checkpoint", str(tmp_path / "any.pt"), "--scripted-sight", "view",
                       "--episodes", "2", "--out", str(tmp_path / "refused"))
    assert refused.returncode != 0 and "go with --scripted, not with --checkpoint" in refused.stderr


def test_right_of_way_numbers_do_not_depend_on_the_workers(tmp_path, monkeypatch):
    from evaluation import right_of_way

    monkeypatch.setattr(right_of_way, "CHUNK_EPISODES", 2)  # three jobs from five episodes
    assert right_of_way.chunk_sizes(5) == [2, 2, 1]
    runs = {}
    for workers in (1, 3):
        summary = right_of_way.run_right_of_way("easy", None, 5, workers, seed=4, out_dir=tmp_path / str(workers),
                                                command="test", scripted=DriverOptions(sight="view"))
        assert summary["episodes_per_job"] == 2 and summary["workers"] == workers
        runs[workers] = {k: v for k, v in summary.items() if k not in ("workers", "wall_s", "paths")}
    assert runs[1] == runs[3]
    assert sum(runs[1]["agent_end_reasons"].values()) == 5 * 3


def test_ttc_comparison_end_to_end(tmp_path):
    good = tmp_path / "good.pt"
    torch.save(LearnerCore().state_dict(), good)
    result = crossway("evaluate", "ttc", "--checkpoint", str(good), "--episodes", "2", "--delays", "20",
                      "--workers", "2", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader(open(tmp_path / "out" / "ttc-comparison.csv")))
    assert {r["driver"] for r in rows} == {"ttc", "policy"}
    assert {r["level"] for r in rows} == {"low", "medium", "high"}
    assert {"goal_rate", "crash_rate", "off_path_rate", "time_over_rate", "episodes"} <= set(rows[0])
    assert all(int(r["episodes"]) == 2 for r in rows)
    for name in ("ttc-goal.png", "ttc-time_over.png"):
        assert (tmp_path / "out" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ttc_sweep_reports_and_rejects_bad_input(tmp_path):
    bad = crossway("evaluate", "ttc", "--delays", "20,x", "--out", str(tmp_path))
    assert bad.returncode == 2 and "--delays" in bad.stderr
    swept = crossway("evaluate", "ttc", "--sweep", "1000", "--episodes", "1", "--delays", "20", "--workers", "2",
                     "--out", str(tmp_path))
    # with an unreachable threshold the ego never goes: no crash, so 1000 s is chosen
    assert swept.returncode == 0, swept.stderr
    assert "sweep: chose 1000 s" in swept.stdout


def test_evaluation_is_reproducible_from_its_seed(tmp_path):
    from evaluation.table1 import TestSpec, run_test

    spec = TestSpec("easy", 10.0, 5, seed=7, checkpoint=None)
    assert run_test(spec) == run_test(spec)
    assert run_test(spec) != run_test(TestSpec("easy", 10.0, 5, seed=8, checkpoint=None))


def test_export_keeps_the_policy_and_evaluates_the_same(tmp_path):
    from evaluation.policy import load_policy

    import numpy as np

    checkpoint = tmp_path / "ckpt.pt"
    core = LearnerCore()
    core.apply({n: np.ones(s, np.float32) for n, s in core.shapes.items()}, 0, 10)  # Adam state exists now
    torch.save(core.state_dict(), checkpoint)
    result = crossway("evaluate", "export", "--checkpoint", str(checkpoint), "--out", str(tmp_path / "small.pt"),
                      "--note", "unit test")
    assert result.returncode == 0, result.stderr
    small = tmp_path / "small.pt"
    assert small.stat().st_size < 0.5 * checkpoint.stat().st_size  # no optimiser state
    original, exported = load_policy(checkpoint), load_policy(small)
    for (name, a), (_, b) in zip(original.state_dict().items(), exported.state_dict().items()):
        assert torch.equal(a, b), name
    assert torch.load(small, weights_only=False)["note"] == "unit test"



def test_an_ensemble_file_loads_as_one_network_exports_as_its_members_and_bad_ones_are_refused(tmp_path):
    from dataclasses import asdict

    from algo.policy import Policy, PolicyConfig, ensemble
    from evaluation.policy import load_policy

    torch.manual_seed(3)
    members = [Policy(PolicyConfig()), Policy(PolicyConfig(hidden=64))]
    path = tmp_path / "ensemble.pt"
    torch.save({"members": [{"policy": m.state_dict(), "policy_config": asdict(m.config)} for m in members]}, path)
    joined = load_policy(path)
    for (name, a), b in zip(joined.state_dict().items(), ensemble(members).state_dict().values()):
        assert torch.equal(a, b), name
    result = crossway("evaluate", "export", "--checkpoint", str(path), "--out", str(tmp_path / "small.pt"))
    assert result.returncode == 0, result.stderr
    assert len(torch.load(tmp_path / "small.pt", weights_only=False)["members"]) == 2
    for (name, a), b in zip(load_policy(tmp_path / "small.pt").state_dict().items(), joined.state_dict().values()):
        assert torch.equal(a, b), name
    torch.save({"members": []}, tmp_path / "empty.pt")
    with pytest.raises(ValueError, match="without members"):
        load_policy(tmp_path / "empty.pt")
    torch.save({"members": [{"policy": members[0].state_dict(), "policy_config": {"hidden": 64}}]}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match=r"member 1\).*do not match"):
        load_policy(tmp_path / "bad.pt")

def test_ttc_comparison_reuses_the_sweeps_cells_at_the_chosen_threshold(tmp_path):
    """The sweep and the comparison seed each cell alike, so a TTC cell at the chosen threshold is the
    same episodes in both: the comparison takes it from the sweep instead of driving it again."""
    from evaluation.ttc_test import TRAFFIC_LEVELS, run_comparison, sweep_thresholds

    delays, threshold_s = [20.0, 40.0], 1.0  # a reckless threshold: outcomes depend on the traffic drawn
    _, sweep_rows = sweep_thresholds([threshold_s, 1000.0], 4, delays, 2, seed=5)
    fresh = run_comparison(None, threshold_s, 4, delays, 2, 5, tmp_path / "fresh", "test")
    reused = run_comparison(None, threshold_s, 4, delays, 2, 5, tmp_path / "reused", "test", sweep_rows=sweep_rows)
    assert fresh["meta"]["ttc_cells_from_sweep"] == 0 and fresh["meta"]["platform"]["torch"] == torch.__version__
    assert reused["meta"]["ttc_cells_from_sweep"] == len(TRAFFIC_LEVELS) * len(delays)
    assert reused["rows"] == fresh["rows"]  # the same episodes, whether driven again or not
    assert [r for r in sweep_rows if r["threshold_s"] == threshold_s] == fresh["rows"]
    other_seed = run_comparison(None, threshold_s, 4, delays, 2, 6, tmp_path / "other", "test")
    assert other_seed["rows"] != fresh["rows"]  # so the equalities above say something


def test_evaluations_run_a_scenario_file_with_its_own_views(tmp_path):
    """Workers get the scenario itself, not a name they would have to find: a file works."""
    from simcore.scenario import SCENARIO_DIR

    scenario = tmp_path / "easy-wide.toml"
    scenario.write_text((SCENARIO_DIR / "easy.toml").read_text().replace('name = "easy"', 'name = "easy-wide"')
                        + "\n[views]\nextent_m = 70.0\nshift_m = 15.0\n")
    table1 = crossway("evaluate", "table1", "--scripted", "--scripted-sight", "view", "--scenario", str(scenario),
                      "--episodes", "2", "--workers", "2", "--out", str(tmp_path / "t1"))
    assert table1.returncode == 0, table1.stderr
    meta = json.loads((tmp_path / "t1" / "table1-easy-wide.json").read_text())["meta"]
    assert (meta["scenario"], meta["scripted_sight_m"], meta["scripted_sight_shift_m"]) == ("easy-wide", 35.0, 15.0)
    assert meta["platform"]["torch"] == torch.__version__ and meta["platform"]["torch_cpu_capability"]
    rules = crossway("evaluate", "right-of-way", "--scripted", "--scenario", str(scenario), "--episodes", "2",
                     "--workers", "2", "--portable-kernels", "--out", str(tmp_path / "row"))
    assert rules.returncode == 0, rules.stderr
    assert (tmp_path / "row" / "right-of-way-easy-wide.csv").exists()
    row = json.loads((tmp_path / "row" / "right-of-way-easy-wide.json").read_text())
    assert row["platform"]["numpy"] == np.__version__
    assert row["platform"]["kernel_variables"]["MKL_CBWR"] == "AVX2"  # --portable-kernels
    assert "MKL_CBWR=AVX2" in (tmp_path / "row" / "right-of-way-easy-wide.md").read_text()
    assert "MKL_CBWR" not in meta["platform"]["kernel_variables"] or "MKL_CBWR" in os.environ
    # a policy records the view square it learnt from: it is refused on a junction shown through another
    wide = tmp_path / "wide.pt"
    core = LearnerCore()
    core.views = (70.0, 15.0)
    torch.save(core.state_dict(), wide)
    on_its_own = crossway("evaluate", "table1", "--checkpoint", str(wide), "--scenario", str(scenario),
                          "--episodes", "1", "--workers", "1", "--out", str(tmp_path / "own"))
    assert on_its_own.returncode == 0, on_its_own.stderr
    for command in (("table1",), ("right-of-way",), ("reaction",)):
        refused = crossway("evaluate", *command, "--checkpoint", str(wide), "--scenario", "easy",
                           "--episodes", "1", "--out", str(tmp_path / "never"))
        assert refused.returncode == 2, refused.stderr
        assert ("learnt from views 70 m wide, centred 15 m ahead of the car, but scenario 'easy' shows views 50 m "
                "wide" in refused.stderr), refused.stderr
    ttc = crossway("evaluate", "ttc", "--checkpoint", str(wide), "--episodes", "1", "--out", str(tmp_path / "never"))
    assert ttc.returncode == 2 and "scenario 'hard' shows views 50 m wide" in ttc.stderr, ttc.stderr
    assert not (tmp_path / "never").exists()


def test_a_policy_file_without_a_views_record_reads_as_the_papers_views(tmp_path):
    """models/*.pt predate the record; exporting keeps a record and keeps its absence."""
    from algo.policy import PAPER_VIEWS, policy_views

    assert policy_views("models/easy.pt") == PAPER_VIEWS == (50.0, 0.0)
    core = LearnerCore()
    assert core.state_dict()["views"] is None
    fresh = tmp_path / "fresh.pt"
    torch.save(core.state_dict(), fresh)
    assert policy_views(fresh) is None  # no actor has reported yet: any views go
    core.views = (70.0, 15.0)
    torch.save(core.state_dict(), tmp_path / "wide.pt")
    exported = crossway("evaluate", "export", "--checkpoint", str(tmp_path / "wide.pt"), "--out",
                        str(tmp_path / "small.pt"))
    assert exported.returncode == 0, exported.stderr
    assert policy_views(tmp_path / "small.pt") == (70.0, 15.0)
    old = crossway("evaluate", "export", "--checkpoint", "models/easy.pt", "--out", str(tmp_path / "old.pt"))
    assert old.returncode == 0, old.stderr
    assert "views" not in torch.load(tmp_path / "old.pt", weights_only=False)


def _pool_workers(pid: int) -> list[int]:
    """The spawned worker processes among ``pid``'s children (not its resource tracker)."""
    from pathlib import Path

    children = Path(f"/proc/{pid}/task/{pid}/children")
    pids = [int(c) for c in children.read_text().split()] if children.exists() else []
    return [c for c in pids if b"spawn_main" in Path(f"/proc/{c}/cmdline").read_bytes()]


def _running(pid: int) -> bool:
    """Alive and not a zombie waiting for a parent to reap it."""
    from pathlib import Path

    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("stop_signal", ["SIGTERM", "SIGKILL"])
def test_stopping_an_evaluation_stops_its_workers(tmp_path, stop_signal):
    """A scheduler's SIGTERM ends the pool before the command exits; after a SIGKILL, which
    nothing can catch, the orphaned workers notice their parent is gone and exit."""
    import signal
    import time

    command = [sys.executable, "-m", "crossway", "evaluate", "right-of-way", "--scripted", "--scenario", "hard",
               "--episodes", "2000", "--workers", "2", "--out", str(tmp_path)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while len(workers := _pool_workers(process.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert len(workers) == 2, "the workers did not start"
        time.sleep(1.0)  # they are driving now
        process.send_signal(getattr(signal, stop_signal))
        process.wait(timeout=30)
        if stop_signal == "SIGTERM":
            assert process.returncode == 128 + signal.SIGTERM
        deadline = time.monotonic() + 10
        while any(_running(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_running(w) for w in workers), f"workers {workers} outlived the command"
        assert not (tmp_path / "right-of-way-hard.json").exists()
    finally:
        if process.poll() is None:
            process.kill()
        process.stderr.close()


def test_a_stopped_table1_run_goes_on_from_its_finished_chunks_and_ends_as_an_unbroken_run(tmp_path):
    """Nothing finished is lost: SIGTERM after some chunks, the same command again runs the rest."""
    import signal
    import time

    command = [sys.executable, "-m", "crossway", "evaluate", "table1", "--scripted", "--scenario", "easy",
               "--episodes", "260", "--workers", "1", "--seed", "3"]  # three tests, one chunk each
    unbroken = subprocess.run(command + ["--out", str(tmp_path / "unbroken")], capture_output=True, text=True,
                              timeout=600)
    assert unbroken.returncode == 0, unbroken.stderr
    assert not (tmp_path / "unbroken" / ".partial").exists()  # removed once the outputs are written
    out = tmp_path / "broken"
    kept = out / ".partial" / "table1-easy"
    log_path = tmp_path / "broken.log"
    with open(log_path, "w") as log:
        process = subprocess.Popen(command + ["--out", str(out)], stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 300
        while not list(kept.glob("*.pkl")) and time.monotonic() < deadline:
            time.sleep(0.1)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=120) == 128 + signal.SIGTERM, log_path.read_text()
    finally:
        if process.poll() is None:
            process.kill()
    finished = len(list(kept.glob("*.pkl")))
    assert 1 <= finished < 3, f"stopped too late to test anything: {log_path.read_text()}"
    assert not (out / "table1-easy.json").exists() and not list(kept.glob(".*.tmp"))
    resumed = subprocess.run(command + ["--out", str(out)], capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{finished} of 3 jobs already done by an earlier run" in resumed.stderr
    before = json.loads((tmp_path / "unbroken" / "table1-easy.json").read_text())
    after = json.loads((out / "table1-easy.json").read_text())
    assert after["tests"] == before["tests"] and after["table"] == before["table"]
    assert after["meta"]["jobs_from_an_earlier_run"] == finished
    assert not (out / ".partial").exists()


def test_kept_jobs_belong_to_one_checkpoint_file(tmp_path):
    """A checkpoint rewritten at the same path does not take the old one's results."""
    from evaluation.parallel import cache_salt, job_key, kept_jobs
    from evaluation.table1 import run_test

    checkpoint = tmp_path / "policy.pt"
    checkpoint.write_bytes(b"first weights")
    job = ("same", "arguments")
    first = job_key(run_test, job, cache_salt(checkpoint))
    assert job_key(run_test, job, cache_salt(checkpoint)) == first
    checkpoint.write_bytes(b"second weights")
    assert job_key(run_test, job, cache_salt(checkpoint)) != first
    assert job_key(run_test, ("other", "arguments"), cache_salt(None)) != job_key(run_test, job, cache_salt(None))
    # only a job's own file counts as done: not another command's, not another checkpoint's
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / f"{first}.pkl").write_bytes(b"the first checkpoint's result")
    (kept / "stray.pkl").write_bytes(b"another job's result")
    salt = cache_salt(checkpoint)
    assert kept_jobs(run_test, [job], kept, salt) == 0
    (kept / f"{job_key(run_test, job, salt)}.pkl").write_bytes(b"this one's")
    assert kept_jobs(run_test, [job, ("other", "arguments")], kept, salt) == 1


def test_kept_jobs_belong_to_one_version_of_the_code(tmp_path, monkeypatch):
    """A run resumed after the simulator's or a driver's code changed runs its jobs again."""
    from evaluation import parallel

    package = tmp_path / "package"
    (package / "sub").mkdir(parents=True)
    (package / "a.py").write_text("x = 1\n")
    (package / "sub" / "b.py").write_text("y = 2\n")
    (package / "notes.txt").write_text("not code")
    before = parallel.source_digest([package])
    assert parallel.source_digest([package]) == before
    (package / "notes.txt").write_text("still not code")
    assert parallel.source_digest([package]) == before
    (package / "sub" / "b.py").write_text("y = 3\n")
    changed = parallel.source_digest([package])
    assert changed != before
    (package / "sub" / "c.py").write_text("")
    assert parallel.source_digest([package]) != changed
    # the salt carries the digest of the packages that decide a result
    real = parallel.source_digest([Path(__import__(name).__file__).parent for name in parallel.RESULT_PACKAGES])
    assert f"code {real[:16]}" in parallel.cache_salt(None)
    salt = parallel.cache_salt(None)
    monkeypatch.setattr(parallel, "_code_digest", "0" * 64)  # as if the code had changed
    assert parallel.cache_salt(None) != salt and "code 0000000000000000" in parallel.cache_salt(None)


def test_kept_jobs_belong_to_one_numeric_platform(monkeypatch):
    """A run resumed on a machine whose float kernels differ runs its jobs again: there the same
    seed gives other episodes (docs/evaluation.md, "Same numbers on another machine")."""
    import numpy
    import torch

    from evaluation import parallel

    for name in parallel.KERNEL_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    here = parallel.numeric_platform()
    assert (here["torch"], here["numpy"]) == (torch.__version__, numpy.__version__)
    assert here["torch_cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    assert set(here["cpu_flags"]) <= set(parallel.KERNEL_CPU_FLAGS) and here["kernel_variables"] == {}
    salt = parallel.cache_salt(None)
    assert parallel.cache_salt(None) == salt
    # a worker started with MKL limited to AVX2 multiplies otherwise: another platform
    monkeypatch.setenv("MKL_ENABLE_INSTRUCTIONS", "AVX2")
    assert parallel.numeric_platform()["kernel_variables"] == {"MKL_ENABLE_INSTRUCTIONS": "AVX2"}
    assert parallel.cache_salt(None) != salt
    monkeypatch.delenv("MKL_ENABLE_INSTRUCTIONS")
    monkeypatch.setattr(torch.backends.cpu, "get_cpu_capability", lambda: "DEFAULT")  # as on an older CPU
    assert parallel.cache_salt(None) != salt


def test_portable_kernels_reach_the_workers(monkeypatch):
    """--portable-kernels sets MKL's code path in the environment the spawned workers start with."""
    import os

    from evaluation import parallel

    monkeypatch.setenv("MKL_CBWR", "")  # restored (absent) after the test
    monkeypatch.delenv("MKL_CBWR")
    parallel.use_portable_kernels()
    # os.getenv(name, progress) in a real worker process: that worker's value of the variable
    assert parallel.run_parallel(os.getenv, [("MKL_CBWR",)], 0, 1, "kernels") == [parallel.PORTABLE_MKL_BRANCH]
    assert parallel.numeric_platform()["kernel_variables"] == {"MKL_CBWR": parallel.PORTABLE_MKL_BRANCH}


def test_portable_kernels_refuse_another_mkl_code_path(monkeypatch):
    """A user's own MKL_CBWR is not overwritten: --portable-kernels refuses, naming both values."""
    from evaluation import parallel

    monkeypatch.setenv("MKL_CBWR", "COMPATIBLE")
    with pytest.raises(ValueError, match="MKL_CBWR=COMPATIBLE"):
        parallel.use_portable_kernels()
    assert os.environ["MKL_CBWR"] == "COMPATIBLE"
    monkeypatch.setenv("MKL_CBWR", parallel.PORTABLE_MKL_BRANCH)  # the same choice twice is no conflict
    parallel.use_portable_kernels()
    assert os.environ["MKL_CBWR"] == parallel.PORTABLE_MKL_BRANCH


def test_a_kept_result_that_does_not_read_is_run_again(tmp_path, capfd):
    from evaluation.parallel import cache_salt, job_key, run_parallel
    from evaluation.table1 import TestSpec, run_test
    from simcore.controller import DriverOptions
    from simcore.scenario import load_scenario

    job = (TestSpec(load_scenario("easy"), 10.0, 2, 7, None, DriverOptions()),)
    salt = cache_salt(None)
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / f"{job_key(run_test, job, salt)}.pkl").write_bytes(b"half a pickle")
    results = run_parallel(run_test, [job], 2, 1, "table1 easy", cache_dir=kept, salt=salt, sizes=[2])
    assert "ignored a kept result that does not read" in capfd.readouterr().err
    assert sum(sum(counts.values()) for counts in results[0]["counts"].values()) >= 2
    # the rerun's result replaced the broken one: a third run takes it without driving
    again = run_parallel(run_test, [job], 2, 1, "table1 easy", cache_dir=kept, salt=salt, sizes=[2])
    assert again == results and "1 of 1 jobs already done" in capfd.readouterr().err


def _report(folder: Path) -> dict:
    return json.loads((folder / "table1-hard.json").read_text())


def test_table1_shares_merge_into_the_whole_protocol(tmp_path):
    """--share I/N runs the I-th of N parts of every test's 500-episode jobs with their protocol
    seeds; 'evaluate merge' joins parts into the very report one run over all the jobs writes. A
    run of fewer --episodes, from before --share (no 'jobs' record), is the protocol's first jobs."""
    common = ("evaluate", "table1", "--scripted", "--scenario", "hard", "--sweep-up-to", "10", "--workers", "2")
    first = crossway(*common, "--episodes", "500", "--out", str(tmp_path / "first"))
    second = crossway(*common, "--episodes", "1000", "--share", "2/2", "--out", str(tmp_path / "second"))
    whole = crossway(*common, "--episodes", "1000", "--out", str(tmp_path / "whole"))
    assert first.returncode == second.returncode == whole.returncode == 0, first.stderr + second.stderr + whole.stderr
    meta = _report(tmp_path / "second")["meta"]
    assert (meta["jobs"], meta["protocol_jobs"], meta["episodes_per_test"], meta["share"]) == ([1, 2], 2, 500, [2, 2])
    assert "Share 2/2 of the protocol: job 2 of each test's 2" in (tmp_path / "second" / "table1-hard.md").read_text()
    old = _report(tmp_path / "first")  # as a report written before --share was
    for key in ("jobs", "protocol_jobs", "protocol_episodes_per_test", "share", "checkpoint_sha256"):
        del old["meta"][key]
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "table1-hard.json").write_text(json.dumps(old))

    joined = crossway("evaluate", "merge", str(tmp_path / "second"), str(tmp_path / "old"), "--out", str(tmp_path / "joined"))
    assert joined.returncode == 0, joined.stderr
    assert "joined 2 runs, 1000 episodes per test" in joined.stdout
    merged, reference = _report(tmp_path / "joined"), _report(tmp_path / "whole")
    for key in ("counts", "counts_by_start", "counts_uncuttable", "cut_by_redraw"):
        assert merged["tests"][0][key] == reference["tests"][0][key]
    assert merged["table"]["stop"]["goal"] == reference["table"]["stop"]["goal"]
    assert merged["table"]["stop"]["speed_mps"] == pytest.approx(reference["table"]["stop"]["speed_mps"])
    assert merged["by_start"] == reference["by_start"]
    assert merged["meta"]["jobs"] == [0, 2] and [p["jobs"] for p in merged["meta"]["merged_from"]] == [[0, 1], [1, 2]]
    page = (tmp_path / "joined" / "table1-hard.md").read_text()
    assert "Joined from runs over other jobs of each test" in page and "--share 2/2" in page
    # each part ran two workers on its own: the joined run records that, not a sum no run had
    assert merged["meta"]["workers"] == 2 and [p["workers"] for p in merged["meta"]["merged_from"]] == [2, 2]
    assert "s on 2 workers: `" in page
    assert merged["meta"]["jobs_not_joined"] == 0 and "note:" not in joined.stderr
    as_of_three = _report(tmp_path / "second")  # as if share 2/3 of a protocol of three jobs per test
    as_of_three["meta"].update(protocol_jobs=3, share=[2, 3], protocol_episodes_per_test=1500)
    (tmp_path / "of-three").mkdir()
    (tmp_path / "of-three" / "table1-hard.json").write_text(json.dumps(as_of_three))
    short = crossway("evaluate", "merge", str(tmp_path / "old"), str(tmp_path / "of-three"), "--out", str(tmp_path / "short"))
    assert short.returncode == 0 and _report(tmp_path / "short")["meta"]["jobs_not_joined"] == 1
    assert "note: the shares' protocol has 1 more job(s) per test that no run given holds" in short.stderr
    assert "1 more job(s) per test that no part holds: this is each test's first 1000 episodes" in \
        (tmp_path / "short" / "table1-hard.md").read_text()

    def refused(*runs):
        out = tmp_path / f"refused{len(list(tmp_path.iterdir()))}"
        result = crossway("evaluate", "merge", *map(str, runs), "--out", str(out))
        assert result.returncode != 0 and not out.exists()
        return result.stderr

    assert "overlap" in refused(tmp_path / "second", tmp_path / "whole")
    assert "leave a gap" in refused(tmp_path / "second", tmp_path / "second" / "table1-hard.json")
    assert "two or more" in refused(tmp_path / "second")
    other_seed = _report(tmp_path / "second")
    other_seed["meta"]["seed"] = 7
    (tmp_path / "other-seed.json").write_text(json.dumps(other_seed))
    assert "seed 7 against 0" in refused(tmp_path / "first", tmp_path / "other-seed.json")
    assert "no such file" in refused(tmp_path / "first", tmp_path / "missing")
    for name, digest in (("first", "a" * 64), ("second", "b" * 64)):  # as if of two checkpoints
        report = _report(tmp_path / name)
        report["meta"]["checkpoint_sha256"] = digest
        (tmp_path / f"{name}-digest.json").write_text(json.dumps(report))
    assert "other checkpoints (SHA-256 bbbbbbbbbbbb against aaaaaaaaaaaa)" in \
        refused(tmp_path / "first-digest.json", tmp_path / "second-digest.json")


def test_peek_reads_the_finished_jobs_of_a_run_still_going(tmp_path):
    """evaluate peek prints what a Table I run has finished so far (its kept jobs), while it runs."""
    import signal
    import time

    out = tmp_path / "run"
    running = subprocess.Popen([sys.executable, "-m", "crossway", "evaluate", "table1", "--scripted", "--scenario",
                                "hard", "--sweep-up-to", "20", "--episodes", "1000", "--workers", "1", "--out", str(out)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while not list((out / ".partial" / "table1-hard").glob("*.pkl")) and time.monotonic() < deadline:
            time.sleep(0.5)
        seen = crossway("evaluate", "peek", str(out))
        assert running.poll() is None, "the run ended before a look at it"
    finally:
        running.send_signal(signal.SIGTERM)
        running.wait(timeout=60)
    assert seen.returncode == 0, seen.stderr
    assert "## table1-hard: 1 job finished" in seen.stdout
    assert "Jobs finished per test: 10 s: 1" in seen.stdout  # one worker: the first job first
    assert "(500) |\n" in seen.stdout  # the first job's 500 episodes, all signs
    assert "| Reaches, standard error |" in seen.stdout
    nothing = crossway("evaluate", "peek", str(tmp_path / "none"))
    assert nothing.returncode != 0 and "no Table I run in progress" in nothing.stderr


def test_right_of_way_shares_merge_into_the_whole_test(tmp_path, monkeypatch):
    """right-of-way --share I/N runs the I-th of N parts of the test's jobs with their seeds in the
    whole test; merge joins them (and a report from before --share, which holds rates alone) into
    the counts one run over every job gives, and refuses parts that overlap or differ."""
    from evaluation import right_of_way
    from evaluation.shares import merge_reports

    monkeypatch.setattr(right_of_way, "CHUNK_EPISODES", 2)  # three jobs from five episodes
    options = DriverOptions(sight="view")

    def run(name, episodes=5, share=None, seed=4):
        return right_of_way.run_right_of_way("easy", None, episodes, 2, seed, tmp_path / name, f"run {name}", options,
                                             share=share)

    first, second, whole = run("first", share=(1, 2)), run("second", share=(2, 2)), run("whole")
    assert (first["jobs"], second["jobs"], first["protocol_jobs"]) == ([0, 1], [1, 3], 3)
    assert (first["episodes"], second["episodes"], whole["episodes"]) == (2, 3, 5)
    assert "Share 2/2 of the test: jobs 2-3 of its 3, 3 of its 5 episodes" in \
        (tmp_path / "second" / "right-of-way-easy.md").read_text()
    old = json.loads((tmp_path / "first" / "right-of-way-easy.json").read_text())  # as written before --share
    for key in ("jobs", "protocol_jobs", "protocol_episodes", "share", "no_infraction_episodes",
                "no_seen_infraction_episodes", "platform",  # nor, before session 28, its machine
                "scripted_patience_s", "scripted_blocker_patience_s"):  # nor options added later (the defaults)
        del old[key]
    (tmp_path / "old-right-of-way-easy.json").write_text(json.dumps(old))
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "right-of-way-easy.json").write_text(json.dumps(old))

    joined = merge_reports([tmp_path / "second", tmp_path / "old"], tmp_path / "joined", "merge")
    assert joined["kind"] == "right-of-way"
    merged = json.loads((tmp_path / "joined" / "right-of-way-easy.json").read_text())
    for key in ("episodes", "no_infraction", "no_seen_infraction", "no_infraction_episodes", "infractions",
                "infractions_seen_in_time", "infractions_offender_crashed", "agent_end_reasons"):
        assert merged[key] == whole[key], key
    assert sum(merged["agent_end_reasons"].values()) == 5 * 3
    assert [p["jobs"] for p in merged["merged_from"]] == [[0, 1], [1, 3]] and merged["jobs_not_joined"] == 0
    # a part of one job ran one worker: the joined test records the most any part ran, not their sum
    assert merged["workers"] == 2 and [p["workers"] for p in merged["merged_from"]] == [1, 2]
    page = (tmp_path / "joined" / "right-of-way-easy.md").read_text()
    assert "s on 1 worker: `" in page and "s on 2 workers: `" in page
    assert "Joined from runs over other jobs of the test" in page
    assert merged["platform"] == second["platform"] and "(the machine it ran on is not on record)" in page
    assert (tmp_path / "joined" / "right-of-way-easy.csv").read_text().splitlines()[1].startswith("easy,5,")

    with pytest.raises(ValueError, match="overlap"):
        merge_reports([tmp_path / "first", tmp_path / "whole"], tmp_path / "refused", "merge")
    with pytest.raises(ValueError, match="leave a gap"):
        merge_reports([tmp_path / "second", tmp_path / "second"], tmp_path / "refused", "merge")
    run("other-seed", share=(1, 2), seed=5)
    with pytest.raises(ValueError, match="seed 5 against 4|seed 4 against 5"):
        merge_reports([tmp_path / "other-seed", tmp_path / "second"], tmp_path / "refused", "merge")
    (tmp_path / "table1").mkdir()
    (tmp_path / "table1" / "table1-easy.json").write_text("{}")
    with pytest.raises(ValueError, match="different protocols"):
        merge_reports([tmp_path / "first", tmp_path / "table1"], tmp_path / "refused", "merge")
    del old["scripted_sight"]  # a missing key is its default ("full" sight), not this run's "view"
    (tmp_path / "no-sight").mkdir()
    (tmp_path / "no-sight" / "right-of-way-easy.json").write_text(json.dumps(old))
    with pytest.raises(ValueError, match="scripted_sight None against 'view'"):
        merge_reports([tmp_path / "second", tmp_path / "no-sight"], tmp_path / "refused", "merge")
    assert not (tmp_path / "refused").exists()
    run("one-of-three", share=(2, 3))
    short = merge_reports([tmp_path / "old", tmp_path / "one-of-three"], tmp_path / "short", "merge")
    assert short["meta"]["jobs"] == [0, 2] and short["meta"]["jobs_not_joined"] == 1  # share 3/3 left out
    assert "1 more job(s) that no part holds: this is its first 4 episodes" in \
        (tmp_path / "short" / "right-of-way-easy.md").read_text()
    with pytest.raises(ValueError, match="share out"):
        run("too-many", share=(1, 4))


def test_ttc_shares_merge_into_the_whole_comparison(tmp_path):
    """ttc --share I/N runs both drivers on the I-th of N parts of the (level, delay) cells; merge
    joins the parts into the rows and figures one run over every cell writes."""
    policy = tmp_path / "policy.pt"
    torch.save(LearnerCore().state_dict(), policy)
    common = ("evaluate", "ttc", "--checkpoint", str(policy), "--threshold", "10", "--episodes", "2", "--delays",
              "20", "--workers", "2")
    first = crossway(*common, "--share", "1/2", "--out", str(tmp_path / "first"))
    second = crossway(*common, "--share", "2/2", "--out", str(tmp_path / "second"))
    whole = crossway(*common, "--out", str(tmp_path / "whole"))
    assert first.returncode == second.returncode == whole.returncode == 0, first.stderr + second.stderr + whole.stderr
    assert "share 1/2: cells 1-1 of 3" in first.stdout
    assert not (tmp_path / "first" / "ttc-goal.png").exists()  # a share's figures would miss cells
    meta = json.loads((tmp_path / "second" / "ttc-comparison.json").read_text())["meta"]
    assert (meta["cells"], meta["protocol_cells"], meta["share"]) == ([1, 3], 3, [2, 2])

    joined = crossway("evaluate", "merge", str(tmp_path / "second"), str(tmp_path / "first"), "--out",
                      str(tmp_path / "joined"))
    assert joined.returncode == 0, joined.stderr
    assert "joined 2 runs, 3 (level, delay) cells" in joined.stdout
    merged = json.loads((tmp_path / "joined" / "ttc-comparison.json").read_text())
    reference = json.loads((tmp_path / "whole" / "ttc-comparison.json").read_text())
    assert merged["rows"] == reference["rows"]
    assert (tmp_path / "joined" / "ttc-comparison.csv").read_text() == (tmp_path / "whole" / "ttc-comparison.csv").read_text()
    for name in ("ttc-goal.png", "ttc-time_over.png"):
        assert (tmp_path / "joined" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert merged["meta"]["cells"] == [0, 3] and merged["meta"]["cells_not_joined"] == 0
    assert merged["meta"]["workers"] == 2 and [p["workers"] for p in merged["meta"]["merged_from"]] == [2, 2]

    only_first = crossway("evaluate", "merge", str(tmp_path / "first"), str(tmp_path / "first"), "--out",
                          str(tmp_path / "refused"))
    assert only_first.returncode != 0 and "overlap" in only_first.stderr and not (tmp_path / "refused").exists()
    swept = crossway(*common, "--sweep", "8,10", "--share", "1/2", "--out", str(tmp_path / "refused"))
    assert swept.returncode != 0 and "--share goes with --threshold" in swept.stderr
    for bad, says in (("0/2", "1 <= I <= N"), ("3/2", "1 <= I <= N"), ("half", "--share takes I/N"),
                      ("1/4", "only 3 (traffic level, delay) cells to share out")):
        refused = crossway(*common, "--share", bad, "--out", str(tmp_path / "refused"))
        assert refused.returncode != 0 and says in refused.stderr, refused.stderr
    assert not (tmp_path / "refused").exists()
