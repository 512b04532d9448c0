"""Scenario files: the paper's three junctions, and clear errors for bad files."""

import math

import pytest

from simcore.scenario import (
    ScenarioError,
    ViewSpec,
    build_intersection,
    classify_turn,
    load_scenario,
    parse_scenario,
)

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


def lane_exits(intersection):
    """{lane name: {turn: exit arm name}}."""
    return {
        lane.name: {intersection.routes[r].turn: intersection.branches[intersection.routes[r].exit_branch].name
                    for r in lane.routes}
        for lane in intersection.lanes
    }


@pytest.fixture(scope="module")
def built():
    return {name: build_intersection(load_scenario(name)) for name in ("easy", "medium", "hard")}


def test_easy_is_a_three_way_junction(built):
    intersection = built["easy"]
    spec = intersection.spec
    assert sorted(b.angle_deg for b in spec.branches) == [0.0, 180.0, 270.0]  # a T: no north arm
    assert len(intersection.lanes) == 3 and len(intersection.routes) == 6
    assert lane_exits(intersection) == {
        "east_0": {"left": "south", "straight": "west"},
        "west_0": {"straight": "east", "right": "south"},
        "south_0": {"left": "west", "right": "east"},
    }
    assert (spec.episodes.delay_min_s, spec.episodes.delay_max_s) == (0.0, 30.0)
    assert spec.episodes.sign_change_interval_s == 0.0  # a new sign with every episode


def test_medium_is_a_four_way_single_lane_junction(built):
    intersection = built["medium"]
    spec = intersection.spec
    assert len(intersection.lanes) == 4 and len(intersection.routes) == 12
    assert all(turns == ["left", "right", "straight"] for turns in lane_routes(intersection).values())
    assert lane_exits(intersection)["south_0"] == {"left": "west", "straight": "north", "right": "east"}
    assert lane_exits(intersection)["east_0"] == {"left": "south", "straight": "west", "right": "north"}
    assert (spec.episodes.delay_min_s, spec.episodes.delay_max_s) == (0.0, 50.0)


def test_hard_has_eight_lanes_without_lane_changes(built):
    intersection = built["hard"]
    spec = intersection.spec
    routes = lane_routes(intersection)
    assert len(routes) == 8 and len(intersection.routes) == 16
    for arm in ("east", "north", "west", "south"):
        assert routes[f"{arm}_0"] == ["left", "straight"]  # inner lane
        assert routes[f"{arm}_1"] == ["right", "straight"]  # outer lane
    # no lane change: every route ends in the exit lane with its entry lane's number
    for route in intersection.routes:
        lane = intersection.lanes[route.entry_lane]
        offset = abs(sum(p * q for p, q in zip(route.path.position(route.path.length, 0.0),
                                                 _normal(spec.branches[route.exit_branch].angle_deg))))
        assert offset == pytest.approx((lane.lane + 0.5) * spec.lane_width_m)
    assert (spec.episodes.delay_min_s, spec.episodes.delay_max_s) == (0.0, 100.0)
    assert spec.episodes.sign_change_interval_s > 0
    assert spec.episodes.sign_change_restart == "delayed"  # each agent then waits its random delay


@pytest.mark.parametrize("name", ["easy", "medium", "hard"])
def test_routes_start_right_of_the_arm_axis_and_turn_as_named(built, name):
    """Right-hand traffic: inbound lanes lie right of the arm's axis, lane 0 next to it."""
    intersection = built[name]
    spec = intersection.spec
    half = intersection.half_size_m
    assert half == pytest.approx(spec.lanes_per_direction * spec.lane_width_m + spec.corner_radius_m)
    for route in intersection.routes:
        lane = intersection.lanes[route.entry_lane]
        angle = spec.branches[lane.branch].angle_deg
        entry_arm, exit_arm = math.radians(angle), math.radians(spec.branches[route.exit_branch].angle_deg)
        x, y = route.path.position(0.0, 0.0)
        heading = route.path.heading_at(0.0)
        assert math.remainder(heading - (entry_arm + math.pi), 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
        cross = math.cos(heading) * y - math.sin(heading) * x  # > 0: left of the arm's axis
        assert cross == pytest.approx(-(lane.lane + 0.5) * spec.lane_width_m)
        along = x * math.cos(entry_arm) + y * math.sin(entry_arm)
        assert along == pytest.approx(half + spec.approach_length_m)
        # the goal is on the exit arm, exit_length past the junction edge
        gx, gy = route.path.position(route.path.length, 0.0)
        assert gx * math.cos(exit_arm) + gy * math.sin(exit_arm) == pytest.approx(half + spec.exit_length_m)
        assert route.turn == classify_turn(angle, spec.branches[route.exit_branch].angle_deg)
        assert route.junction_entry_s == pytest.approx(spec.approach_length_m)
        assert route.path.length - route.junction_exit_s == pytest.approx(spec.exit_length_m)


def _normal(angle_deg):
    a = math.radians(angle_deg)
    return (-math.sin(a), math.cos(a))


@pytest.mark.parametrize("lanes, expected", [
    (2, [["left", "straight"], ["right", "straight"]]),
    (3, [["left", "straight"], ["straight"], ["right", "straight"]]),
])
def test_lane_turns_default_by_lane_count(tmp_path, lanes, expected):
    """Without lane_turns: inner lane left + straight, outer straight + right, middle straight."""
    file = tmp_path / "multi.toml"
    file.write_text(GOOD.replace("lanes_per_direction = 1", f"lanes_per_direction = {lanes}")
                    + '[[branches]]\nname = "west"\nangle_deg = 180\n')
    intersection = build_intersection(load_scenario(file))
    routes = lane_routes(intersection)
    assert len(routes) == 4 * lanes
    for arm in ("east", "north", "west", "south"):
        assert [routes[f"{arm}_{k}"] for k in range(lanes)] == expected


def test_classify_turn():
    # right-hand traffic: entering from the south (270), east (0) is a right turn
    assert classify_turn(270.0, 0.0) == "right"
    assert classify_turn(270.0, 90.0) == "straight"
    assert classify_turn(270.0, 180.0) == "left"
    assert classify_turn(0.0, 10.0) is None


def test_custom_file_loads(tmp_path):
    file = tmp_path / "custom.toml"
    file.write_text(GOOD)
    spec = load_scenario(file)
    assert spec.name == "custom" and spec.episodes.delay_max_s == 20.0
    assert spec.episodes.time_limit_s == 40.0  # defaults fill what the file leaves out
    assert len(build_intersection(spec).lanes) == 3
    assert load_scenario(str(file)) == spec  # a path as a string works too


@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace("lanes_per_direction = 1", "lane_widht_m = 3.0"), "lane_widht_m: unknown field"),
    (lambda t: t.replace("lanes_per_direction = 1", 'lane_width_m = "wide"'), "lane_width_m: expected a finite number"),
    (lambda t: t.replace("lanes_per_direction = 1", "approach_length_m = 2.0"), "approach_length_m: must be >= 10"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_max_s = 'soon'"),
     "episodes.delay_max_s: expected a finite number"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_max_s = true"), "episodes.delay_max_s: expected a finite number"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_mx_s = 20.0"), "episodes.delay_mx_s: unknown field"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_min_s = 30.0\ndelay_max_s = 20.0"),
     "episodes.delay_min_s: must not exceed episodes.delay_max_s"),
    (lambda t: t.replace("delay_max_s = 20.0", "time_limit_s = 0.0"), "episodes.time_limit_s: must be > 0"),
    (lambda t: t.replace("[episodes]\ndelay_max_s = 20.0", 'episodes = "busy"'), "episodes: expected a table"),
    (lambda t: t.replace('angle_deg = 90', 'angle_deg = "north"'), "branches[1].angle_deg: expected a finite number"),
    (lambda t: t.replace('angle_deg = 90', 'angel_deg = 90'), "branches[1].angel_deg: unknown field"),
    (lambda t: t.replace('name = "north"', 'name = "north arm"'), "branches[1].name"),
    (lambda t: t.replace('name = "north"', 'name = "east"'), "branches: name 'east' is used more than once"),
    (lambda t: t.replace('angle_deg = 90', 'angle_deg = 30'), "branches: arms at 0 and 30 deg are closer than 60 deg"),
    (lambda t: t.replace('angle_deg = 90', 'angle_deg = 330'),
     "branches: arms at 330 and 0 deg are closer than 60 deg"),
    (lambda t: t.split("[[branches]]\nname = \"south\"")[0], "branches: expected a list of 3 or 4"),
    (lambda t: t.replace('name = "north"', 'name = "north"\nlane_turns = [["uturn"]]'),
     "branches[1].lane_turns[0]: expected a non-empty list drawn from"),
    (lambda t: t.replace('name = "north"', 'name = "north"\nlane_turns = [[]]'), "branches[1].lane_turns[0]"),
    (lambda t: t.replace('name = "north"', 'name = "north"\nlane_turns = [["left"], ["right"]]'),
     "branches[1].lane_turns: expected one entry per lane (1), got 2"),
    (lambda t: t.replace('name = "south"', 'name = "south"\nlane_turns = [["left"]]'),
     "branches[2].lane_turns[0]: no arm lies left of south"),
    (lambda t: t.replace("lanes_per_direction = 1", "lanes_per_direction = 9"),
     "lanes_per_direction: expected an integer"),
    (lambda t: t.replace("lanes_per_direction = 1", "lanes_per_direction = 1.5"),
     "lanes_per_direction: expected an integer"),
    (lambda t: t.replace('name = "custom"', 'name = "custom"\n[extra'), "not valid TOML"),
    (lambda t: t.replace('name = "custom"', 'name = ""'), "name: expected a non-empty string"),
    (lambda t: t.replace("[episodes]", "[views]\nextent_m = 5.0\n[episodes]"),
     "views.extent_m: must be >= 10"),
    (lambda t: t.replace("[episodes]", "[views]\nextent_m = 300.0\n[episodes]"),
     "views.extent_m: at most 200 m"),
    (lambda t: t.replace("[episodes]", "[views]\nshift_m = 23.0\n[episodes]"),
     "views.shift_m: the car must stay inside its own view"),
    (lambda t: t.replace("[episodes]", "[views]\nshift_m = 'ahead'\n[episodes]"),
     "views.shift_m: expected a finite number"),
    (lambda t: t.replace("[episodes]", "[views]\nwidth_m = 60.0\n[episodes]"),
     "views.width_m: unknown field"),
    (lambda t: t.replace('name = "custom"', 'name = "custom"\nviews = 70'), "views: expected a table"),
    (lambda t: t.replace("delay_max_s = 20.0", "delay_max_s = 20.0\nsign_change_restart = 'soon'"),
     "episodes.sign_change_restart: expected one of delayed, together, got 'soon'"),
])
def test_bad_files_name_the_field(tmp_path, edit, field):
    file = tmp_path / "bad.toml"
    file.write_text(edit(GOOD))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    assert field in str(caught.value)
    assert str(file) in str(caught.value)
    assert isinstance(caught.value, ValueError)


def test_a_scenario_error_survives_pickling():  # a worker process hands it back to its parent
    import pickle

    error = pickle.loads(pickle.dumps(ScenarioError("bad.toml", ["views.extent_m: must be >= 10"])))
    assert isinstance(error, ScenarioError) and error.problems == ["views.extent_m: must be >= 10"]
    assert "bad.toml" in str(error)


def test_views_default_to_the_papers_and_a_file_may_change_them(tmp_path):
    file = tmp_path / "wide.toml"
    file.write_text(GOOD.replace("[episodes]", "[views]\nextent_m = 70.0\nshift_m = 15.0\n[episodes]"))
    assert load_scenario(file).views == ViewSpec(extent_m=70.0, shift_m=15.0)
    assert load_scenario("hard").views == ViewSpec(extent_m=50.0, shift_m=0.0)  # the paper's, centred


def test_two_arms_in_the_same_turn_direction_are_refused():
    data = {"name": "fan", "branches": [
        {"name": "east", "angle_deg": 0}, {"name": "a", "angle_deg": 150}, {"name": "b", "angle_deg": 220},
    ]}
    with pytest.raises(ScenarioError, match=r"branches\[0\] \(east\): two arms \(a, b\) are both a straight turn"):
        parse_scenario(data)


def test_every_problem_is_reported_together(tmp_path):
    file = tmp_path / "bad.toml"
    file.write_text(GOOD.replace("lanes_per_direction = 1", "lane_widht_m = 3.0\ncorner_radius_m = -1")
                    .replace("delay_max_s = 20.0", "delay_min_s = 60.0\ndelay_max_s = 30.0")
                    .replace("angle_deg = 90", 'angle_deg = "north"'))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    problems = caught.value.problems
    assert len(problems) == 4, problems
    assert any(p.startswith("lane_widht_m: unknown field") for p in problems)
    assert any(p.startswith("corner_radius_m: must be > 0") for p in problems)
    assert any(p.startswith("episodes.delay_min_s: must not exceed") for p in problems)
    assert any(p.startswith("branches[1].angle_deg: expected a finite number") for p in problems)
    message = str(caught.value)
    assert all(p in message for p in problems)  # every one of them in the one message


def test_parse_refuses_a_non_table():
    with pytest.raises(ScenarioError, match="top level: expected a table"):
        parse_scenario(["not", "a", "table"])


def test_missing_file_is_named(tmp_path):
    missing = tmp_path / "nowhere.toml"
    with pytest.raises(ScenarioError, match="not a built-in scenario") as caught:
        load_scenario(missing)
    assert str(missing) in str(caught.value)
    with pytest.raises(ScenarioError, match="easy, medium, hard"):
        load_scenario("medium2")


def test_a_corner_too_tight_to_drive_is_refused(tmp_path):
    file = tmp_path / "tight.toml"
    file.write_text(GOOD.replace("lanes_per_direction = 1", "corner_radius_m = 5.0"))
    with pytest.raises(ScenarioError, match="corner_radius_m"):
        load_scenario(file)
