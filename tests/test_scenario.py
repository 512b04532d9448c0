"""Scenario files: the paper's three junctions, and clear errors for bad files."""

import pytest

from simcore.scenario import ScenarioError, build_intersection, load_scenario

GOOD = """
name = "custom"
lanes_per_direction = 1
[episodes]
delay_max_s = 20.0
[[branches]]
name = "east"
angle_deg = 0
[[branches]]
name = "north"
angle_deg = 90
[[branches]]
name = "south"
angle_deg = 270
"""


def lane_routes(intersection):
    return {lane.name: sorted(intersection.routes[r].turn for r in lane.routes) for lane in intersection.lanes}


def test_easy_is_a_three_way_junction():
    spec = load_scenario("easy")
    intersection = build_intersection(spec)
    assert len(intersection.lanes) == 3
    assert lane_routes(intersection) == {
        "east_0": ["left", "straight"], "west_0": ["right", "straight"], "south_0": ["left", "right"],
    }
    assert (spec.episodes.delay_min_s, spec.episodes.delay_max_s) == (0.0, 30.0)


def test_medium_is_a_four_way_single_lane_junction():
    spec = load_scenario("medium")
    intersection = build_intersection(spec)
    assert len(intersection.lanes) == 4
    assert all(turns == ["left", "right", "straight"] for turns in lane_routes(intersection).values())
    assert spec.episodes.delay_max_s == 50.0


def test_hard_has_eight_lanes_without_lane_changes():
    spec = load_scenario("hard")
    intersection = build_intersection(spec)
    routes = lane_routes(intersection)
    assert len(routes) == 8
    for arm in ("east", "north", "west", "south"):
        assert routes[f"{arm}_0"] == ["left", "straight"]  # inner lane
        assert routes[f"{arm}_1"] == ["right", "straight"]  # outer lane
    # no lane change: every route ends in the exit lane with its entry lane's number
    for route in intersection.routes:
        lane = intersection.lanes[route.entry_lane]
        offset = abs(sum(p * q for p, q in zip(route.path.position(route.path.length, 0.0),
                                                 _normal(spec.branches[route.exit_branch].angle_deg))))
        assert offset == pytest.approx((lane.lane + 0.5) * spec.lane_width_m)
    assert spec.episodes.delay_max_s == 100.0
    assert spec.episodes.sign_change_interval_s > 0


def _normal(angle_deg):
    import math

    a = math.radians(angle_deg)
    return (-math.sin(a), math.cos(a))


def test_custom_file_loads(tmp_path):
    file = tmp_path / "custom.toml"
    file.write_text(GOOD)
    spec = load_scenario(file)
    assert spec.name == "custom" and spec.episodes.delay_max_s == 20.0
    assert len(build_intersection(spec).lanes) == 3


@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace("lanes_per_direction = 1", "lane_widht_m = 3.0"), "lane_widht_m: unknown field"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_max_s = 'soon'"), "episodes.delay_max_s: expected a finite number"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_min_s = 30.0\ndelay_max_s = 20.0"), "episodes.delay_min_s: must not exceed"),
    (lambda t: t.replace('angle_deg = 90', 'angle_deg = "north"'), "branches[1].angle_deg"),
    (lambda t: t.replace('angle_deg = 90', 'angle_deg = 20'), "closer than 60 deg"),
    (lambda t: t.split("[[branches]]\nname = \"south\"")[0], "branches: expected a list of 3 or 4"),
    (lambda t: t.replace('name = "north"', 'name = "north"\nlane_turns = [["uturn"]]'), "branches[1].lane_turns[0]"),
    (lambda t: t.replace('name = "south"', 'name = "south"\nlane_turns = [["left"]]'), "no arm lies left of south"),
    (lambda t: t.replace("lanes_per_direction = 1", "lanes_per_direction = 9"), "lanes_per_direction"),
    (lambda t: t.replace('name = "custom"', 'name = "custom"\n[extra'), "not valid TOML"),
])
def test_bad_files_name_the_field(tmp_path, edit, field):
    file = tmp_path / "bad.toml"
    file.write_text(edit(GOOD))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    assert field in str(caught.value)
    assert str(file) in str(caught.value)


def test_every_problem_is_reported_together(tmp_path):
    file = tmp_path / "bad.toml"
    file.write_text(GOOD.replace("lanes_per_direction = 1", "lane_widht_m = 3.0\ncorner_radius_m = -1")
                    .replace("delay_max_s = 20.0", "delay_max_s = -5"))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    problems = caught.value.problems
    assert len(problems) >= 3
    assert any(p.startswith("lane_widht_m") for p in problems)
    assert any(p.startswith("corner_radius_m") for p in problems)
    assert any(p.startswith("episodes.delay_max_s") for p in problems)


def test_missing_file_is_named():
    with pytest.raises(ScenarioError, match="not a built-in scenario"):
        load_scenario("nowhere.toml")
