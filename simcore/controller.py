"""A scripted driver: pure-pursuit path following, speed keeping and a simple right-of-way rule.

It reads the simulator's state directly (privileged information a learner never gets) and
exists so that anyone can watch the simulator, benchmark it and test it without a trained
model. It is not the paper's TTC baseline.

Right of way: before a conflict zone it stops while a car with priority (``rightofway``) is in
that zone or is closer to it than ``YIELD_HORIZON_S`` at that car's target speed (or its current
speed, if faster). Judging by the target speed rather than the current one matters: a car with
priority that waits at its own line for a third car is near, not far, and going ahead of it is
an infraction in the paper's right-of-way test (Table II; ``evaluation.right_of_way``). After
waiting ``PATIENCE_S`` at a stand it goes anyway, which breaks the rare priority cycles (three
arms with equal signs); after each ``act()``, ``patience_released`` says which cars go so although
a car with priority is near (``crossway pretrain --patience-weight`` counts those labels more).

With ``sight_m`` set it only yields to cars with priority that may show in the square of that
half-side around it, aligned with its heading (their centre within half a car length of it;
before session 12 the centre had to be inside, so it ignored cars a learner sees part of):
``view_sight(sim)`` limits it to what a learner's views show (``crossway pretrain
--teacher-sight view``). ``sight_shift_m`` moves that
square's centre ahead of the car (a what-if for views placed further forward).

With ``approach_speed_mps`` set it also drives as if a car with priority could appear at any
moment: before each conflict zone it shares with a route that would have priority over its own
(by the signs now on the arms and priority to the right), it slows so that it reaches the zone's
stop point at no more than that speed, braking at ``APPROACH_DECELERATION``. A driver limited to
its views needs this (the paper's hard agents average 5.9 m/s at stop signs, Table I).
``approach_signs`` says which zones: ``"all"`` judges priority by the signs now on every arm
(privileged: a learner's sign channel shows only its own lane's line), ``"own"`` by its own sign
alone, taking every other arm as unsigned, the worst case (so it slows before a zone with a route
from the right when it has no sign, and before every crossing route when it has a yield or stop
sign): a choice a learner can make from its views.

With ``brake_for_blockers`` it also stops before a conflict zone that a car in sight occupies now,
whatever the priority: a car standing in the junction is an obstacle, even for a car with the
right of way (docs/scripts/crash_kinds.py: most crashes of the view-limited driver on easy were a
car with priority running into one that had entered their conflict zone first). After standing
``BLOCKER_PATIENCE_S`` it goes anyway: three cars can each stand in the zone of the next. After
each ``act()``, ``blocker_bound`` says which cars' acceleration is that braking (``crossway
pretrain --blocker-weight`` counts those labels more).

With ``wait_outside_zones`` it never plans to stand inside a conflict zone: when the point where it
would stop (for a car with priority, or for a blocker) leaves its body inside the zone of another
crossing route, it stops before that zone instead (and so on, back to the first zone of a chain of
overlapping ones). On hard the stop lines lie 21 m from the centre and the zones overlap, so a
driver that stops right before each zone stands in others, and with ``brake_for_blockers`` the
cars lock each other (docs/imitation.md, session 15). A car already inside such a zone stops where
it had planned. The approach slowing then applies only at those stop points: a car that has
entered a chain of zones crosses it at its cruising speed.

With ``break_wait_cycles`` it draws, each step, who waits for whom (a car with priority it yields
to within the yield horizon, a car it follows on a shared lane, a car in sight occupying a zone
ahead of it), and a car stops yielding to a car with priority that waits, through that graph, for
the car itself: otherwise the cycle waits for ever, or until a patience runs out. Every car of a
cycle is freed so; their braking for blockers still keeps them apart. The graph reads every car's
state (privileged, like the priorities themselves).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from simcore.dynamics import DT, MAX_ACCELERATION, MAX_STEERING, STANDING_MPS, VEHICLE_LENGTH, WHEELBASE
from simcore.rightofway import SIGN_RANK, Sign
from simcore.simulator import Simulator
from simcore.views import VIEW_EXTENT_M, may_show

STOP_MARGIN_M = 2.0  # stop this far before a conflict zone [m]
YIELD_HORIZON_S = 5.0  # yield to a car with priority closer to the conflict than this at its target speed [s]
PATIENCE_S = 4.0  # after standing this long, go [s]
FOLLOW_GAP_M = 4.0  # bumper-to-bumper gap kept behind a car on a shared lane [m]
SPEED_GAIN = 1.5  # proportional speed control [1/s]
VIEW_SIGHT_M = 0.5 * VIEW_EXTENT_M  # half-side of the square the paper's views show [m]
APPROACH_DECELERATION = 2.0  # comfortable braking towards a conflict zone's approach speed [m/s^2]
APPROACH_SIGNS = ("all", "own")  # which signs decide the zones to approach slowly (ScriptedDriver)
SIGHTS = ("full", "view")  # what the scripted driver sees (DriverOptions.sight)
BLOCKER_PATIENCE_S = 8.0  # after standing this long, ignore the cars in its way (brake_for_blockers) [s]


def _reachable(edges: dict[int, set[int]], start: int) -> set[int]:
    """The nodes reachable from ``start`` along ``edges`` in one step or more (depth-first)."""
    seen: set[int] = set()
    stack = [start]
    while stack:
        for nxt in edges.get(stack.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                stack.append(nxt)
    return seen


def view_sight(sim: Simulator) -> dict[str, float]:
    """``ScriptedDriver`` keyword arguments that limit it to what ``sim``'s learners see (the
    scenario's ``[views]``: ``VIEW_SIGHT_M`` centred unless the scenario changes it)."""
    return {"sight_m": 0.5 * sim.spec.views.extent_m, "sight_shift_m": sim.spec.views.shift_m}


@dataclass(frozen=True)
class DriverOptions:
    """The scripted driver as the commands configure it (``crossway evaluate --scripted-*``,
    ``crossway pretrain --teacher-*``); ``scripted_driver`` builds it for a simulator."""

    sight: str = "full"  # "full": it sees every car; "view": only those sim's learners' views may show
    approach_speed_mps: float | None = None  # slow to this speed before zones of routes that may have priority
    approach_signs: str = "all"  # which signs decide those zones (ScriptedDriver.approach_signs)
    brake_for_blockers: bool = False  # stop before a zone a car in sight occupies, whatever the priority
    wait_outside_zones: bool = False  # never plan a stop that leaves the car inside another conflict zone
    break_wait_cycles: bool = False  # go ahead of a car with priority that waits, through others, for this one
    # after standing this long it stops yielding to cars with priority [s]; inf: never (no clock the views show)
    patience_s: float = PATIENCE_S
    # after standing this long it stops braking for cars in its way (brake_for_blockers) [s]; inf: never
    blocker_patience_s: float = BLOCKER_PATIENCE_S

    def __post_init__(self):
        if self.sight not in SIGHTS:
            raise ValueError(f"sight must be one of {SIGHTS}, got {self.sight!r}")
        if self.approach_speed_mps is not None and not 0.0 <= self.approach_speed_mps < math.inf:
            raise ValueError(f"approach_speed_mps must be >= 0 m/s or None, got {self.approach_speed_mps}")
        if self.approach_signs not in APPROACH_SIGNS:
            raise ValueError(f"approach_signs must be one of {APPROACH_SIGNS}, got {self.approach_signs!r}")
        _check_patience(self.patience_s, self.blocker_patience_s)

    def record(self) -> dict:
        """The options as an evaluation's JSON records them (approach_signs only with a speed)."""
        return {"scripted_sight": self.sight if self.sight == "view" else None,
                "scripted_approach_mps": self.approach_speed_mps,
                "scripted_approach_signs": self.approach_signs if self.approach_speed_mps is not None else None,
                "scripted_brake_for_blockers": self.brake_for_blockers,
                "scripted_wait_outside_zones": self.wait_outside_zones,
                "scripted_break_wait_cycles": self.break_wait_cycles,
                "scripted_patience_s": _seconds_or_never(self.patience_s),
                "scripted_blocker_patience_s": _seconds_or_never(self.blocker_patience_s)}


def _check_patience(patience_s: float, blocker_patience_s: float) -> None:
    for name, value in (("patience_s", patience_s), ("blocker_patience_s", blocker_patience_s)):
        if not value > 0:  # nan fails too; inf is allowed
            raise ValueError(f"{name} must be > 0 s (inf: never), got {value}")


def _seconds_or_never(value: float) -> float | str:
    """A patience for JSON, which has no infinity."""
    return "never" if math.isinf(value) else value


def scripted_driver(sim: Simulator, options: DriverOptions | None = None) -> "ScriptedDriver":
    """The scripted driver as the commands name it (``DriverOptions``; None: the defaults, every
    car in sight); sight "view" limits it to what ``sim``'s learners see (``view_sight``)."""
    options = options or DriverOptions()
    return ScriptedDriver(sim, approach_speed_mps=options.approach_speed_mps, approach_signs=options.approach_signs,
                          brake_for_blockers=options.brake_for_blockers, wait_outside_zones=options.wait_outside_zones,
                          break_wait_cycles=options.break_wait_cycles, patience_s=options.patience_s,
                          blocker_patience_s=options.blocker_patience_s,
                          **(view_sight(sim) if options.sight == "view" else {}))


class ScriptedDriver:
    """Acts for every slot of a ``Simulator``; ``act()`` returns a ``[slots, 2]`` action array."""

    def __init__(self, sim: Simulator, speed_fraction: float = 0.9, yield_to_priority: bool = True,
                 sight_m: float | None = None, approach_speed_mps: float | None = None,
                 sight_shift_m: float = 0.0, approach_signs: str = "all", brake_for_blockers: bool = False,
                 wait_outside_zones: bool = False, break_wait_cycles: bool = False,
                 patience_s: float = PATIENCE_S, blocker_patience_s: float = BLOCKER_PATIENCE_S):
        if sight_m is not None and not sight_m > 0:
            raise ValueError(f"sight_m must be > 0 m or None, got {sight_m}")
        if not math.isfinite(sight_shift_m):
            raise ValueError(f"sight_shift_m must be a finite number of metres, got {sight_shift_m}")
        if approach_speed_mps is not None and not approach_speed_mps >= 0:
            raise ValueError(f"approach_speed_mps must be >= 0 m/s or None, got {approach_speed_mps}")
        if approach_signs not in APPROACH_SIGNS:
            raise ValueError(f"approach_signs must be one of {APPROACH_SIGNS}, got {approach_signs!r}")
        _check_patience(patience_s, blocker_patience_s)
        self.patience_s = patience_s  # after standing this long, stop yielding to cars with priority [s]
        self.blocker_patience_s = blocker_patience_s  # after standing this long, stop braking for blockers [s]
        self.approach_signs = approach_signs
        self.brake_for_blockers = brake_for_blockers
        self.wait_outside_zones = wait_outside_zones
        self.break_wait_cycles = break_wait_cycles
        # speed at the stop point of a conflict zone with a route that may have priority [m/s]
        self.approach_speed_mps = approach_speed_mps
        self.sim = sim
        self.sight_m = sight_m  # half-side of the square around the car it looks into [m]; None: everywhere
        self.sight_shift_m = sight_shift_m  # that square's centre lies this far ahead of the car's [m]
        self.speed_fraction = speed_fraction  # cruise at this fraction of the target speed
        self.yield_to_priority = yield_to_priority
        self._standing_s = np.zeros(sim.num_slots)
        # per slot, after each act(): its acceleration is the braking for a car in its way
        # (brake_for_blockers), the label ``crossway pretrain --blocker-weight`` counts more
        self.blocker_bound = np.zeros(sim.num_slots, dtype=bool)
        # per slot, after each act(): it goes although a car with priority in sight is near, because
        # it has stood ``patience_s`` (the label ``crossway pretrain --patience-weight`` counts more)
        self.patience_released = np.zeros(sim.num_slots, dtype=bool)
        lanes = sim.intersection.lanes
        self._entry_lane = np.array([r.entry_lane for r in sim.intersection.routes])  # per route
        self._entry_branch = np.array([lanes[e].branch for e in self._entry_lane])  # per route
        # per route: (starts, ends) [m] of its conflict zones with crossing routes from other lanes
        table = sim.priority
        crossing = (table.conflict & np.isnan(table.merge_at)
                    & (self._entry_lane[:, None] != self._entry_lane[None, :]))
        self._crossing_zones = [(table.zone_start[r][crossing[r]], table.zone_end[r][crossing[r]])
                                for r in range(len(self._entry_lane))]

    def act(self) -> np.ndarray:
        sim = self.sim
        actions = np.zeros((sim.num_slots, 2))
        self.blocker_bound[:] = False
        self.patience_released[:] = False
        released = np.zeros(sim.num_slots, dtype=bool)  # it would yield to a car with priority, had it patience
        blocker_braking = np.full(sim.num_slots, math.inf)  # [m/s^2]; inf: nothing in its way
        idx = np.flatnonzero(sim.present)  # every car, traffic included, is someone to yield to
        learners = sim.learners_present
        self._standing_s[~learners] = 0.0
        if not learners.any():
            return actions
        higher = sim.priorities(idx) if self.yield_to_priority else np.zeros((len(idx),) * 2, bool)
        sight = self._in_sight(idx) if self.sight_m is not None else np.ones((len(idx),) * 2, bool)
        higher &= sight
        zone_start = sim.priority.zone_start
        if self.approach_speed_mps is not None:
            route_rank = self._route_ranks()
        merge_at = sim.priority.merge_at
        half = 0.5 * VEHICLE_LENGTH
        waits_for: dict[int, set[int]] = collections.defaultdict(set)  # car -> cars it stops or follows for
        yields: dict[int, list[tuple[int, float]]] = collections.defaultdict(list)  # car -> (car, braking)
        for a, slot in enumerate(idx.tolist()):
            if slot >= sim.num_slots:
                continue  # traffic drives itself
            path = sim.intersection.routes[sim.route[slot]].path
            speed = sim.speed[slot]
            s_front = sim.s[slot] + half
            # pure pursuit towards a point on the centre line ahead
            lookahead = max(6.0, 1.2 * speed)
            tx, ty = path.position(sim.s[slot] + lookahead, 0.0)
            alpha = math.atan2(ty - sim.y[slot], tx - sim.x[slot]) - sim.heading[slot]
            steering = math.atan2(2.0 * WHEELBASE * math.sin(alpha), lookahead)
            desired = self.speed_fraction * sim.target_speed[slot]
            if self.approach_speed_mps is not None:
                zones = self._yield_zones(slot, route_rank)
                if self.wait_outside_zones:  # it slows for where it would stop: a chain's first zone
                    zones = np.array([self._stop_before(sim.route[slot], z, -math.inf) for z in zones])
                upcoming = zones[zones >= s_front]
                if len(upcoming):
                    room = max(float(upcoming.min()) - STOP_MARGIN_M - s_front, 0.0)
                    desired = min(desired, math.sqrt(self.approach_speed_mps ** 2 + 2.0 * APPROACH_DECELERATION * room))
            acceleration = SPEED_GAIN * (desired - speed)
            patient = self._standing_s[slot] < self.patience_s
            for b, other in enumerate(idx.tolist()):
                if not higher[a, b]:
                    continue
                merge_ego = merge_at[sim.route[slot], sim.route[other]]
                if not math.isnan(merge_ego) and sim.s[other] >= merge_at[sim.route[other], sim.route[slot]]:
                    if not patient:
                        continue
                    # the other car is already on the lane both routes share: follow it, do not stop
                    ahead = (sim.s[other] - merge_at[sim.route[other], sim.route[slot]]) - (sim.s[slot] - merge_ego)
                    gap = ahead - VEHICLE_LENGTH - FOLLOW_GAP_M
                    if gap < 2.0 * speed:
                        acceleration = min(acceleration, SPEED_GAIN * (sim.speed[other] - speed) + 0.5 * gap)
                        waits_for[slot].add(other)
                    continue
                if s_front > zone_start[sim.route[slot], sim.route[other]]:
                    continue  # already in the zone: clear it
                gap = self._stop_before(sim.route[slot], zone_start[sim.route[slot], sim.route[other]], s_front) \
                    - STOP_MARGIN_M - s_front
                other_gap = zone_start[sim.route[other], sim.route[slot]] - (sim.s[other] + half)
                # far away, even at its target speed: a car waiting at its line for a third one is near
                if other_gap > YIELD_HORIZON_S * max(sim.speed[other], sim.target_speed[other]):
                    continue
                if not patient:  # it has stood too long: it no longer yields
                    released[slot] |= gap < 3.0 * speed + 5.0
                    continue
                if gap < 3.0 * speed + 5.0:
                    braking = -speed * speed / (2.0 * gap) if gap > 0.5 else -MAX_ACCELERATION
                    if self.break_wait_cycles:
                        yields[slot].append((other, braking))  # applied below, unless it closes a cycle
                        waits_for[slot].add(other)
                    else:
                        acceleration = min(acceleration, braking)
                elif self.break_wait_cycles:
                    waits_for[slot].add(other)  # not braking yet, but it will
            if self.brake_for_blockers and self._standing_s[slot] < self.blocker_patience_s:
                braking, occupants = self._blocker_braking(slot, idx, sight[a], speed, s_front)
                blocker_braking[slot] = braking
                acceleration = min(acceleration, braking)
                waits_for[slot].update(occupants)
            actions[slot] = (acceleration, steering)
        if self.break_wait_cycles:
            for slot, brakings in yields.items():
                # a car with priority that waits, through a chain of cars, for this one would wait
                # for ever: every car of such a cycle stops yielding to the others in it (its braking
                # for blockers and for cars ahead on a shared lane stays and keeps them apart;
                # freeing only one car per cycle measured worse on hard: docs/imitation.md)
                for other, braking in brakings:
                    if slot not in _reachable(waits_for, other):
                        actions[slot, 0] = min(actions[slot, 0], braking)
        # the blocker's braking decides the action (ties with another reason to brake count too)
        self.blocker_bound[:] = np.isfinite(blocker_braking) & (blocker_braking <= actions[:, 0])
        standing = learners & (sim.speed[: sim.num_slots] < STANDING_MPS)
        self._standing_s[standing] += DT
        self._standing_s[~standing] = 0.0
        np.clip(actions[:, 0], -MAX_ACCELERATION, MAX_ACCELERATION, out=actions[:, 0])
        np.clip(actions[:, 1], -MAX_STEERING, MAX_STEERING, out=actions[:, 1])
        self.patience_released[:] = released & (actions[:, 0] > 0.0)
        return actions

    def _blocker_braking(self, slot: int, idx: np.ndarray, in_sight: np.ndarray, speed: float,
                         s_front: float) -> tuple[float, list[int]]:
        """Braking [m/s^2] to stop before a conflict zone that a car in sight occupies now, whatever
        the priority (a car standing in the junction is an obstacle), +inf when none; and the cars
        in sight that occupy a zone ahead of it, near or far."""
        sim, table = self.sim, self.sim.priority
        half = 0.5 * VEHICLE_LENGTH
        route = sim.route[slot]
        best = math.inf
        occupants: list[int] = []
        for b, other in enumerate(idx.tolist()):
            if other == slot or not in_sight[b]:
                continue
            ro = sim.route[other]
            # crossing routes only: a shared lane (same entry, or after a merge) is car following
            if (not table.conflict[route, ro] or not math.isnan(table.merge_at[route, ro])
                    or self._entry_lane[route] == self._entry_lane[ro]):
                continue
            start = table.zone_start[route, ro]
            if s_front > start:
                continue
            occupied = (sim.s[other] + half >= table.zone_start[ro, route]
                        and sim.s[other] - half <= table.zone_end[ro, route])
            if not occupied:
                continue
            gap = self._stop_before(route, start, s_front) - STOP_MARGIN_M - s_front
            if gap < 3.0 * speed + 5.0:
                best = min(best, -speed * speed / (2.0 * gap) if gap > 0.5 else -MAX_ACCELERATION)
            occupants.append(other)
        return best, occupants

    def _stop_before(self, route: int, zone_start_m: float, s_front: float) -> float:
        """Arc length [m] of the zone start to stop before, on ``route``, for a zone beginning at
        ``zone_start_m``: itself, or with ``wait_outside_zones`` the start of an earlier zone the
        car would otherwise stand in (repeated along a chain of overlapping zones) unless the car's
        front ``s_front`` is already past that start."""
        if not self.wait_outside_zones:
            return zone_start_m
        starts, ends = self._crossing_zones[route]
        stop = zone_start_m
        while True:
            front = stop - STOP_MARGIN_M  # the car's body when standing there: [front - length, front]
            inside = (starts < front) & (ends > front - VEHICLE_LENGTH) & (starts < stop)
            if not inside.any():
                break
            stop = float(starts[inside].min())
        return stop if s_front <= stop else zone_start_m

    def _route_ranks(self) -> np.ndarray:
        """Each route's sign rank as the approach rule judges it (``approach_signs``): the sign now
        on its arm, or with "own" that of an unsigned arm, the highest any arm can have."""
        if self.approach_signs == "all":
            return SIGN_RANK[self.sim.branch_signs[self._entry_branch]]
        return np.full(len(self._entry_branch), SIGN_RANK[Sign.NONE])

    def _yield_zones(self, slot: int, route_rank: np.ndarray) -> np.ndarray:
        """Arc lengths [m] on ``slot``'s route where its conflict zones begin with the routes that
        would have priority over it (``route_rank``: each route's sign rank now), car or no car."""
        sim, table = self.sim, self.sim.priority
        route = sim.route[slot]
        rank = SIGN_RANK[sim.sign[slot]]
        by_rule = (route_rank > rank) | ((route_rank == rank) & table.right_wins[route])
        may_yield = table.conflict[route] & by_rule & (self._entry_lane != self._entry_lane[route])
        return table.zone_start[route][may_yield]

    def _in_sight(self, idx: np.ndarray) -> np.ndarray:
        """``out[a, b]``: car ``idx[b]`` may show in the square of half-side ``sight_m`` centred
        ``sight_shift_m`` ahead of car ``idx[a]`` and aligned with its heading: some of its body
        can be inside (``simcore.views.may_show``), as a learner's view shows part of a car."""
        sim = self.sim
        ego = idx[:, None]
        return may_show(sim.x[ego], sim.y[ego], sim.heading[ego], sim.x[idx][None, :], sim.y[idx][None, :],
                        2.0 * self.sight_m, self.sight_shift_m)
