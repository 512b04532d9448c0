"""crossway evaluate reaction: the counterfactual probe of how a policy reacts to priority cars."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from evaluation.reaction import APPROACH_WINDOW_M, encounter_slots, erase_priority_cars
from learner.core import LearnerCore
from simcore.simulator import SimConfig, Simulator

SIGNS = (("south", "stop"), ("east", "none"), ("west", "none"), ("north", "none"))


def put(sim, slot: int, lane: str, turn: str, metres_before_zone_with=None, other_slot=None, s=None):
    """Place a learner on ``lane``'s ``turn`` route at arc length ``s``, or this far before the zone
    it shares with the car on ``other_slot``."""
    lanes = sim.intersection.lanes
    lane_index = next(i for i, l in enumerate(lanes) if l.name == lane)
    route = next(r for r in lanes[lane_index].routes if sim.intersection.routes[r].turn == turn)
    sim._place(slot, lane_index, route)
    if s is None:
        s = sim.priority.zone_start[route, sim.route[other_slot]] - metres_before_zone_with
    path = sim.intersection.routes[route].path
    sim.x[slot], sim.y[slot] = path.position(s, 0.0)
    sim.heading[slot] = path.heading_at(s)
    sim._localise(np.array([slot]))


@pytest.fixture()
def crossing():
    """Medium junction, two learners: south (stop sign) and east (no sign, on south's right)."""
    sim = Simulator("medium", SimConfig(lanes=("south_0", "east_0"), signs=SIGNS, observe=False,
                                        start_all_at_reset=False), seed=0)
    sim.reset()
    assert [sim.intersection.lanes[i].name for i in sim.slot_lanes] == ["east_0", "south_0"]
    put(sim, 0, "east_0", "straight", s=30.0)
    return sim


def test_a_car_approaching_a_zone_a_priority_car_has_not_cleared_is_an_encounter(crossing):
    put(crossing, 1, "south_0", "straight", 8.0, other_slot=0)
    assert crossing.priorities(np.array([0, 1]))[1, 0]  # east has priority over south (sign)
    assert encounter_slots(crossing) == [1]  # south must give way; east has no one to give way to


@pytest.mark.parametrize("before_m", [APPROACH_WINDOW_M + 5.0, -1.0])
def test_too_far_or_already_inside_is_not(crossing, before_m):
    put(crossing, 1, "south_0", "straight", before_m, other_slot=0)
    assert encounter_slots(crossing) == []


def test_a_lone_car_has_no_encounter(crossing):
    put(crossing, 1, "south_0", "straight", 8.0, other_slot=0)
    crossing.present[0] = False
    assert encounter_slots(crossing) == []


def test_erasing_clears_only_black_obstacle_pixels():
    views = np.zeros((1, 16, 84, 84), np.uint8)
    views[0, 8:12, 10, 10] = 128  # a priority car in every obstacle frame
    views[0, 9, 20, 20] = 255  # the ego, white
    views[0, 15, 30, 30] = 128  # a stop line in the sign channel: same code, other channel
    erased = erase_priority_cars(views)
    assert not (erased[0, 8:12] == 128).any()
    assert erased[0, 9, 20, 20] == 255 and erased[0, 15, 30, 30] == 128
    assert (views[0, 8:12, 10, 10] == 128).all()  # the input is left alone


def crossway(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "crossway", *args], capture_output=True, text=True, timeout=timeout)


def test_reaction_end_to_end_and_a_refused_checkpoint(tmp_path):
    good = tmp_path / "good.pt"
    torch.save(LearnerCore().state_dict(), good)
    result = crossway("evaluate", "reaction", "--checkpoint", str(good), "--scenario", "easy", "--episodes", "4",
                      "--workers", "1", "--delay-max", "0", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "out" / "reaction-easy.json").read_text())
    assert report["meta"]["episodes"] == 4 and report["summary"]["episodes"] >= 4
    assert report["meta"]["platform"]["cpu_flags"] is not None
    summary = report["summary"]
    if summary["encounter_steps"]:
        assert {"acceleration_with_mps2", "acceleration_without_mps2", "give_way_fraction",
                "value_with", "value_without"} <= set(summary)
        assert -3.0 <= summary["acceleration_with_mps2"] <= 3.0
    risk = summary["risk"]
    assert risk["steps"] > 0 and 0 <= risk["steps_before_a_crash"] <= risk["steps"]
    assert risk["value_crash_auc"] is None or 0.0 <= risk["value_crash_auc"] <= 1.0
    crashes = summary["crashes"]
    assert 0 <= crashes["ran_into_priority"] <= crashes["crashed_cars"]
    assert "Crashes: " in (tmp_path / "out" / "reaction-easy.md").read_text()
    assert "# Reaction to priority cars, easy" in (tmp_path / "out" / "reaction-easy.md").read_text()
    bad = tmp_path / "bad.pt"
    bad.write_text("nope")
    refused = crossway("evaluate", "reaction", "--checkpoint", str(bad), "--out", str(tmp_path / "never"))
    assert refused.returncode != 0 and "is not a crossway checkpoint" in refused.stderr
    assert not (tmp_path / "never").exists()


def test_crash_anatomy_by_hand():
    from evaluation.reaction import crash_anatomy, markdown

    # two cars ran into a car with priority (at 95% and 50% of their target speed), one was run into
    anatomy = crash_anatomy([(True, 0.95), (False, 0.99), (True, 0.5)])
    assert anatomy == {"crashed_cars": 3, "ran_into_priority": 2, "at_fault_speed_ratio_median": pytest.approx(0.725),
                       "at_fault_full_speed_fraction": pytest.approx(0.5)}
    assert crash_anatomy([(False, 1.0)]) == {"crashed_cars": 1, "ran_into_priority": 0}
    assert crash_anatomy([]) == {"crashed_cars": 0, "ran_into_priority": 0}
    risk = {"steps": 10, "steps_before_a_crash": 0, "value_crash_auc": None}
    text = markdown({"encounter_steps": 0, "risk": risk, "crashes": anatomy})
    assert "3 cars crashed; 2 of them ran into a car with priority over them, at a median 72% of their target" in text
    assert "(50% of them at 90% or more" in text
    assert "Crashes: none." in markdown({"encounter_steps": 0, "risk": risk, "crashes": crash_anatomy([])})


def test_roc_auc_by_hand():
    from evaluation.reaction import roc_auc

    assert roc_auc(np.array([0.1, 0.4, 0.35, 0.8]), np.array([0, 0, 1, 1])) == pytest.approx(0.75)
    assert roc_auc(np.array([3.0, 2.0, 1.0]), np.array([1, 0, 0])) == pytest.approx(1.0)
    assert roc_auc(np.array([1.0, 1.0, 1.0, 1.0]), np.array([1, 0, 1, 0])) == pytest.approx(0.5)  # ties
    assert roc_auc(np.array([1.0, 2.0]), np.array([0, 0])) is None
