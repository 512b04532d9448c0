"""Scenarios as validated data: TOML files loaded into frozen dataclasses, then built into lanes.

A scenario file names the junction's branches, its episode settings (paper, sections
"Environment" and "Training settings") and, optionally, the agents' view square (``[views]``);
``build_intersection`` turns it into entry lanes and the paths that leave them. Unknown keys,
wrong types and impossible values are all collected and reported together, each with the name
of the field (``branches[2].angle_deg: ...``).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path as FilePath
from typing import Any

from simcore.dynamics import MAX_STEERING, turning_radius
from simcore.geometry import Path, fillet_path

SCENARIO_DIR = FilePath(__file__).parent / "scenarios"
BUILTIN_SCENARIOS = ("easy", "medium", "hard")
TURNS = ("left", "straight", "right")


class ScenarioError(ValueError):
    """A scenario file or mapping is invalid; ``problems`` lists every field at fault."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = problems
        super().__init__(f"invalid scenario {source}:\n" + "\n".join(f"  - {p}" for p in problems))

    def __reduce__(self):  # picklable, so that a worker process can hand it back to its parent
        return (ScenarioError, (self.source, self.problems))


@dataclass(frozen=True)
class BranchSpec:
    """One road arm of the junction."""

    name: str
    angle_deg: float  # direction from the junction centre out along the arm [deg], CCW from east
    # Turns allowed from each inbound lane, inner lane (next to the centre line) first.
    # Empty: derived from the lane count (1 lane: all; 2 lanes: inner left+straight, outer straight+right).
    lane_turns: tuple[tuple[str, ...], ...] = ()


SIGN_CHANGE_RESTARTS = ("delayed", "together")  # EpisodeSpec.sign_change_restart


@dataclass(frozen=True)
class EpisodeSpec:
    """Episode timing (paper, "Training settings")."""

    delay_min_s: float = 0.0  # lower end of the random wait between an agent's episodes [s]
    delay_max_s: float = 30.0  # upper end of that wait [s]; lower means denser traffic
    time_limit_s: float = 40.0  # an episode longer than this ends as "time over" [s]
    # > 0: every branch's sign is redrawn at this interval and every agent's episode restarts
    # (the paper's rule for "hard"); 0: each agent draws its sign when its episode starts.
    sign_change_interval_s: float = 0.0
    # how the agents start again after a redraw: "delayed", each waits U[delay_min, delay_max] as
    # after any episode (paper, "Training settings": every agent waits a random delay before a new
    # episode); "together", every agent starts at the next step (crossway's reading until session 30:
    # eight cars at once, the right-of-way test's situation inside Table I)
    sign_change_restart: str = "delayed"


@dataclass(frozen=True)
class ViewSpec:
    """The square each agent sees (paper, "Environment": 50 x 50 m around it, 84 x 84 pixels).

    Not the paper's when changed: a larger square sees cars with priority earlier at a coarser
    resolution (extent / 84 m per pixel), and a shift puts more of it ahead of the car than behind.
    """

    extent_m: float = 50.0  # side of the square [m]
    shift_m: float = 0.0  # its centre lies this far ahead of the car's centre [m]; 0: centred


@dataclass(frozen=True)
class ScenarioSpec:
    """A junction and its episode settings, as read from a scenario file."""

    name: str
    branches: tuple[BranchSpec, ...]
    episodes: EpisodeSpec = EpisodeSpec()
    description: str = ""
    lanes_per_direction: int = 1
    lane_width_m: float = 3.5
    # curb radius at the junction's corners [m]; right turns follow it at lane_width/2 inside,
    # so it must exceed the bicycle model's smallest turning radius (13.4 m at 0.2 rad)
    corner_radius_m: float = 14.0
    approach_length_m: float = 40.0  # from an agent's start to the junction edge [m]
    exit_length_m: float = 30.0  # from the junction edge to the goal [m]
    views: ViewSpec = ViewSpec()  # what each agent sees; the default is the paper's


def _field_names(cls: type) -> set[str]:
    return {f.name for f in fields(cls)}


def _number(value: Any, where: str, problems: list[str], minimum: float | None = None,
            strictly: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        problems.append(f"{where}: expected a finite number, got {value!r}")
        return math.nan
    if minimum is not None and (value <= minimum if strictly else value < minimum):
        relation = ">" if strictly else ">="
        problems.append(f"{where}: must be {relation} {minimum}, got {value!r}")
    return float(value)


def _check_keys(data: dict, allowed: set[str], where: str, problems: list[str]) -> None:
    for key in sorted(set(data) - allowed):
        prefix = f"{where}." if where else ""
        problems.append(f"{prefix}{key}: unknown field (allowed: {', '.join(sorted(allowed))})")


def _sub_table(data: dict, key: str, spec: type, problems: list[str]) -> dict:
    """``data[key]`` (a table whose fields are ``spec``'s; empty when absent), its problems noted."""
    table = data.get(key, {})
    if not isinstance(table, dict):
        problems.append(f"{key}: expected a table, got {table!r}")
        return {}
    _check_keys(table, _field_names(spec), key, problems)
    return table


def parse_scenario(data: dict[str, Any], source: str = "<mapping>") -> ScenarioSpec:
    """Validate a decoded scenario mapping; raise ``ScenarioError`` listing every problem."""
    problems: list[str] = []
    if not isinstance(data, dict):
        raise ScenarioError(source, [f"top level: expected a table, got {type(data).__name__}"])
    _check_keys(data, _field_names(ScenarioSpec), "", problems)

    name = data.get("name")
    if not isinstance(name, str) or not name:
        problems.append(f"name: expected a non-empty string, got {name!r}")
        name = "?"
    description = data.get("description", "")
    if not isinstance(description, str):
        problems.append(f"description: expected a string, got {description!r}")
        description = ""
    lanes = data.get("lanes_per_direction", 1)
    if isinstance(lanes, bool) or not isinstance(lanes, int) or not 1 <= lanes <= 4:
        problems.append(f"lanes_per_direction: expected an integer from 1 to 4, got {lanes!r}")
        lanes = 1
    lane_width = _number(data.get("lane_width_m", 3.5), "lane_width_m", problems, 2.0)
    corner = _number(data.get("corner_radius_m", 14.0), "corner_radius_m", problems, 0.0, strictly=True)
    smallest_radius = turning_radius(MAX_STEERING)
    if corner > 0.0 and lane_width >= 2.0 and corner + 0.5 * lane_width < smallest_radius:
        problems.append(
            f"corner_radius_m: right turns follow an arc of corner_radius_m + lane_width_m / 2 = "
            f"{corner + 0.5 * lane_width:g} m, tighter than the {smallest_radius:.1f} m a car can turn "
            f"at {MAX_STEERING} rad; use at least {smallest_radius - 0.5 * lane_width:.1f}"
        )
    approach = _number(data.get("approach_length_m", 40.0), "approach_length_m", problems, 10.0)
    exit_length = _number(data.get("exit_length_m", 30.0), "exit_length_m", problems, 10.0)

    episodes_data = _sub_table(data, "episodes", EpisodeSpec, problems)
    defaults = EpisodeSpec()
    episode_values: dict[str, Any] = {
        f.name: _number(episodes_data.get(f.name, getattr(defaults, f.name)), f"episodes.{f.name}",
                        problems, 0.0)
        for f in fields(EpisodeSpec) if f.name != "sign_change_restart"
    }
    restart = episodes_data.get("sign_change_restart", defaults.sign_change_restart)
    if restart not in SIGN_CHANGE_RESTARTS:
        problems.append(f"episodes.sign_change_restart: expected one of {', '.join(SIGN_CHANGE_RESTARTS)}, "
                        f"got {restart!r}")
        restart = defaults.sign_change_restart
    episode_values["sign_change_restart"] = restart
    if episode_values["time_limit_s"] == 0.0:
        problems.append("episodes.time_limit_s: must be > 0")
    if episode_values["delay_min_s"] > episode_values["delay_max_s"]:
        problems.append(
            f"episodes.delay_min_s: must not exceed episodes.delay_max_s "
            f"({episode_values['delay_min_s']} > {episode_values['delay_max_s']})"
        )
    episodes = EpisodeSpec(**episode_values)

    views_data = _sub_table(data, "views", ViewSpec, problems)
    view_defaults = ViewSpec()
    view_extent = _number(views_data.get("extent_m", view_defaults.extent_m), "views.extent_m", problems, 10.0)
    view_shift = _number(views_data.get("shift_m", view_defaults.shift_m), "views.shift_m", problems)
    if math.isfinite(view_extent) and math.isfinite(view_shift) and abs(view_shift) > 0.5 * view_extent - 3.0:
        problems.append(f"views.shift_m: the car must stay inside its own view, 3 m from its edge: |shift_m| "
                        f"<= extent_m / 2 - 3 = {0.5 * view_extent - 3.0:g}, got {view_shift:g}")
    if math.isfinite(view_extent) and view_extent > 200.0:
        problems.append(f"views.extent_m: at most 200 m (2.4 m per pixel), got {view_extent:g}")
    views = ViewSpec(view_extent, view_shift)

    raw_branches = data.get("branches")
    branches: list[BranchSpec] = []
    if not isinstance(raw_branches, list) or not 3 <= len(raw_branches) <= 4:
        problems.append(f"branches: expected a list of 3 or 4 branch tables, got {raw_branches!r}")
        raw_branches = []
    for i, branch in enumerate(raw_branches):
        where = f"branches[{i}]"
        if not isinstance(branch, dict):
            problems.append(f"{where}: expected a table, got {branch!r}")
            continue
        _check_keys(branch, _field_names(BranchSpec), where, problems)
        branch_name = branch.get("name")
        if not isinstance(branch_name, str) or not branch_name.isidentifier():
            problems.append(f"{where}.name: expected an identifier-like string, got {branch_name!r}")
            branch_name = f"branch{i}"
        angle = _number(branch.get("angle_deg"), f"{where}.angle_deg", problems)
        lane_turns_raw = branch.get("lane_turns", [])
        lane_turns: list[tuple[str, ...]] = []
        if not isinstance(lane_turns_raw, list):
            problems.append(f"{where}.lane_turns: expected a list of lists of turns, got {lane_turns_raw!r}")
            lane_turns_raw = []
        if lane_turns_raw and len(lane_turns_raw) != lanes:
            problems.append(
                f"{where}.lane_turns: expected one entry per lane ({lanes}), got {len(lane_turns_raw)}"
            )
        for k, turns in enumerate(lane_turns_raw):
            if not isinstance(turns, list) or not turns or any(t not in TURNS for t in turns):
                problems.append(
                    f"{where}.lane_turns[{k}]: expected a non-empty list drawn from {list(TURNS)}, got {turns!r}"
                )
                continue
            lane_turns.append(tuple(turns))
        branches.append(BranchSpec(branch_name, angle % 360.0 if math.isfinite(angle) else angle,
                                   tuple(lane_turns)))

    names = [b.name for b in branches]
    for dup in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"branches: name {dup!r} is used more than once")
    angles = sorted(b.angle_deg for b in branches if math.isfinite(b.angle_deg))
    for a, b in zip(angles, angles[1:] + [angles[0] + 360.0] if angles else []):
        if b - a < 60.0 - 1e-9 and len(angles) > 1:
            problems.append(f"branches: arms at {a % 360:g} and {b % 360:g} deg are closer than 60 deg")

    if problems:
        raise ScenarioError(source, problems)
    spec = ScenarioSpec(
        name=name, branches=tuple(branches), episodes=episodes, description=description,
        lanes_per_direction=lanes, lane_width_m=lane_width, corner_radius_m=corner,
        approach_length_m=approach, exit_length_m=exit_length, views=views,
    )
    # geometric checks need the built layout; they raise ScenarioError themselves
    build_intersection(spec, source=source)
    return spec


def load_scenario(name_or_path: str | FilePath) -> ScenarioSpec:
    """Load a built-in scenario by name (``easy``, ``medium``, ``hard``) or a TOML file by path."""
    text_name = str(name_or_path)
    if text_name in BUILTIN_SCENARIOS:
        file = SCENARIO_DIR / f"{text_name}.toml"
    else:
        file = FilePath(text_name)
        if not file.exists():
            raise ScenarioError(
                text_name,
                [f"no such file, and not a built-in scenario (built-in: {', '.join(BUILTIN_SCENARIOS)})"],
            )
    try:
        data = tomllib.loads(file.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ScenarioError(str(file), [f"not valid TOML: {error}"]) from None
    return parse_scenario(data, source=str(file))


# ---------------------------------------------------------------------------------------------
# Built layout


@dataclass(frozen=True)
class Route:
    """A path from one entry lane to one exit lane."""

    index: int
    entry_lane: int  # index into Intersection.lanes
    exit_branch: int  # index into Intersection.branches
    turn: str  # "left", "straight" or "right"
    path: Path
    junction_entry_s: float  # arc length where the path enters the junction (the sign line) [m]
    junction_exit_s: float  # arc length where it leaves the junction [m]


@dataclass(frozen=True)
class EntryLane:
    """An inbound lane: one agent at most drives from it at a time (paper, "Environment")."""

    index: int
    name: str  # e.g. "south_0": branch name and lane number, 0 next to the centre line
    branch: int
    lane: int
    routes: tuple[int, ...]  # indices into Intersection.routes
    sign_line: tuple[tuple[float, float], tuple[float, float]]  # across the lane at the junction edge [m]


@dataclass(frozen=True)
class Intersection:
    spec: ScenarioSpec
    half_size_m: float  # distance from the centre to where the arms begin (the sign lines) [m]
    road_half_width_m: float
    lanes: tuple[EntryLane, ...]
    routes: tuple[Route, ...]
    extent_m: float  # every path lies within [-extent, extent] in x and y [m]

    @property
    def branches(self) -> tuple[BranchSpec, ...]:
        return self.spec.branches


@dataclass(frozen=True)
class RoadRegion:
    """A shape to paint, in order, to draw the road surface: a polygon or a disc [m]."""

    is_road: bool  # True: road; False: cut back to off-road
    polygon: tuple[tuple[float, float], ...] = ()
    center: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0  # > 0: a disc instead of the polygon


def road_regions(intersection: "Intersection", arm_length_m: float | None = None) -> list[RoadRegion]:
    """The road surface as painting steps: the junction square, curb fillets cut from its corners
    (a straight curb where no arm lies between two arms), then every arm on top."""
    spec = intersection.spec
    half = intersection.half_size_m
    hw = intersection.road_half_width_m
    far = half + max(spec.approach_length_m, spec.exit_length_m) if arm_length_m is None else arm_length_m
    regions = [RoadRegion(True, ((-half, -half), (half, -half), (half, half), (-half, half)))]
    arms = sorted(spec.branches, key=lambda b: b.angle_deg)
    for a, b in zip(arms, arms[1:] + arms[:1]):
        gap = (b.angle_deg - a.angle_deg) % 360.0
        ua, ub = _unit(a.angle_deg), _unit(b.angle_deg)
        va, vb = _unit(a.angle_deg + 90.0), _unit(b.angle_deg - 90.0)  # each arm's side facing the gap
        if gap > 179.0:
            corners = [(half, hw, ua, va), (half, half, ua, va), (half, half, ub, vb), (half, hw, ub, vb)]
            regions.append(RoadRegion(False, tuple(
                (d * u[0] + o * v[0], d * u[1] + o * v[1]) for d, o, u, v in corners)))
            continue
        # the curb circle is tangent to both arms' edges: on the lines at distance hw + radius
        offset = hw + spec.corner_radius_m
        det = va[0] * vb[1] - va[1] * vb[0]
        center = (offset * (vb[1] - va[1]) / det, offset * (va[0] - vb[0]) / det)
        regions.append(RoadRegion(False, center=center, radius=spec.corner_radius_m))
    for branch in spec.branches:
        u, n = _unit(branch.angle_deg), _unit(branch.angle_deg + 90.0)
        regions.append(RoadRegion(True, (
            (-hw * n[0], -hw * n[1]), (far * u[0] - hw * n[0], far * u[1] - hw * n[1]),
            (far * u[0] + hw * n[0], far * u[1] + hw * n[1]), (hw * n[0], hw * n[1]),
        )))
    return regions


def classify_turn(entry_angle_deg: float, exit_angle_deg: float) -> str | None:
    """Turn from an arm at ``entry_angle_deg`` into the arm at ``exit_angle_deg`` (right-hand traffic)."""
    relative = (exit_angle_deg - entry_angle_deg) % 360.0
    if 45.0 < relative < 135.0:
        return "right"
    if 135.0 <= relative <= 225.0:
        return "straight"
    if 225.0 < relative < 315.0:
        return "left"
    return None


def _unit(angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return (math.cos(a), math.sin(a))


def build_intersection(spec: ScenarioSpec, source: str = "<spec>") -> Intersection:
    """Lay out lanes and routes. Inbound lanes sit right of the centre line (right-hand traffic)."""
    problems: list[str] = []
    w = spec.lane_width_m
    road_half_width = spec.lanes_per_direction * w
    half = road_half_width + spec.corner_radius_m

    def lateral(angle_deg: float, offset: float, distance: float) -> tuple[float, float]:
        # n_right is the right-hand side of inbound traffic on this arm: (-sin, cos) of the arm angle
        ux, uy = _unit(angle_deg)
        return (distance * ux - offset * uy, distance * uy + offset * ux)

    lanes: list[EntryLane] = []
    routes: list[Route] = []
    for b, branch in enumerate(spec.branches):
        exits_by_turn: dict[str, int] = {}
        for x, other in enumerate(spec.branches):
            if x == b:
                continue
            turn = classify_turn(branch.angle_deg, other.angle_deg)
            if turn is None:
                continue
            if turn in exits_by_turn:
                problems.append(
                    f"branches[{b}] ({branch.name}): two arms ({spec.branches[exits_by_turn[turn]].name}, "
                    f"{other.name}) are both a {turn} turn from it"
                )
            exits_by_turn[turn] = x
        for k in range(spec.lanes_per_direction):
            if branch.lane_turns:
                wanted = branch.lane_turns[k]
            elif spec.lanes_per_direction == 1:
                wanted = TURNS
            elif k == 0:
                wanted = ("left", "straight")
            elif k == spec.lanes_per_direction - 1:
                wanted = ("straight", "right")
            else:
                wanted = ("straight",)
            offset_in = (k + 0.5) * w
            start = lateral(branch.angle_deg, offset_in, half + spec.approach_length_m)
            entry = lateral(branch.angle_deg, offset_in, half)
            lane_routes: list[int] = []
            for turn in wanted:
                if turn not in exits_by_turn:
                    if branch.lane_turns:
                        problems.append(
                            f"branches[{b}].lane_turns[{k}]: no arm lies {turn} of {branch.name}"
                        )
                    continue
                x = exits_by_turn[turn]
                exit_angle = spec.branches[x].angle_deg
                # outbound lanes sit left of the arm's centre line, same lane number as the entry
                junction_exit = lateral(exit_angle, -(k + 0.5) * w, half)
                exit_end = lateral(exit_angle, -(k + 0.5) * w, half + spec.exit_length_m)
                try:
                    path = fillet_path(start, entry, junction_exit, exit_end, w)
                except ValueError as error:
                    problems.append(f"branches[{b}] lane {k} {turn}: {error}")
                    continue
                entry_s = spec.approach_length_m
                exit_s = path.length - spec.exit_length_m
                lane_routes.append(len(routes))
                routes.append(Route(len(routes), len(lanes), x, turn, path, entry_s, exit_s))
            if not lane_routes:
                problems.append(f"branches[{b}] ({branch.name}) lane {k}: no route leaves this lane")
            sign_line = (lateral(branch.angle_deg, k * w, half), lateral(branch.angle_deg, (k + 1) * w, half))
            lanes.append(EntryLane(len(lanes), f"{branch.name}_{k}", b, k, tuple(lane_routes), sign_line))
    if problems:
        raise ScenarioError(source, problems)
    extent = half + max(spec.approach_length_m, spec.exit_length_m) + road_half_width
    return Intersection(spec, half, road_half_width, tuple(lanes), tuple(routes), extent)
