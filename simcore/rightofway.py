"""Right of way: traffic signs, conflict zones between routes, and who has priority over whom.

The one place that ranks vehicles (paper, "Environment"):

1. Only vehicles whose routes conflict are ranked, and only while neither has cleared the
   conflict zone (its rear is past the zone's end).
2. A sign outranks another: none (main road) over yield over stop.
3. Equal signs: priority to the right. Between opposite arms, where neither is on the other's
   right, a left turn yields to the oncoming vehicle (the usual rule; the paper is silent); two
   opposite left turns or two lanes of one arm fall back to a fixed order (lower arm index,
   then the outer lane), so that for every conflicting pair exactly one has priority.
4. Where two routes merge into one exit lane, once either vehicle is through the merge the
   one ahead on the shared lane has priority (the follower must not run into it).

``PriorityTable.higher(...)`` returns, for every ego vehicle, which others have priority over it;
the obstacle view shades them and the crash reward reads them (paper, "Reward Shaping").
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from simcore.dynamics import VEHICLE_LENGTH, VEHICLE_WIDTH
from simcore.scenario import Intersection, classify_turn


class Sign(enum.IntEnum):
    """Traffic sign of an arm. Values are stable: they travel in episode statistics."""

    NONE = 0
    YIELD = 1
    STOP = 2


SIGN_NAMES = {Sign.NONE: "none", Sign.YIELD: "yield", Sign.STOP: "stop"}
# higher rank wins: none over yield over stop (paper, "Environment")
SIGN_RANK = np.array([2, 1, 0], dtype=np.int8)  # indexed by Sign value

# Two vehicles whose centres are closer than this can touch whatever their headings [m]:
# half a length plus half a width.
CONFLICT_DISTANCE = 0.5 * (VEHICLE_LENGTH + VEHICLE_WIDTH)
MERGE_DISTANCE = 0.3  # centre lines closer than this are one lane [m]
SAMPLE_STEP = 0.25  # resolution of the conflict-zone search [m]


def sign_outranks(sign_a: Sign, sign_b: Sign) -> bool:
    """True if a vehicle with ``sign_a`` has priority over one with ``sign_b`` by signs alone."""
    return bool(SIGN_RANK[int(sign_a)] > SIGN_RANK[int(sign_b)])


@dataclass(frozen=True)
class PriorityTable:
    """Per ordered route pair (i, j), precomputed from the geometry; all arrays [P, P]."""

    conflict: np.ndarray  # bool: routes i and j come within CONFLICT_DISTANCE
    zone_end: np.ndarray  # float: arc length on route i where its conflict with j ends [m]
    zone_start: np.ndarray  # float: arc length on route i where its conflict with j begins [m]
    merge_at: np.ndarray  # float: arc length on route i where it joins route j for good, nan if never [m]
    right_wins: np.ndarray  # bool: with equal signs, route j has priority over route i

    def higher(self, routes: np.ndarray, s: np.ndarray, signs: np.ndarray) -> np.ndarray:
        """``out[e, o]`` is True when vehicle ``o`` has priority over ego vehicle ``e``.

        ``routes`` [N] route indices, ``s`` [N] arc lengths of the vehicles' centres [m],
        ``signs`` [N] Sign values of the vehicles' arms.
        """
        re, ro = routes[:, None], routes[None, :]
        se, so = s[:, None], s[None, :]
        conflict = self.conflict[re, ro]
        half = 0.5 * VEHICLE_LENGTH
        cleared_e = se - half > self.zone_end[re, ro]
        cleared_o = so - half > self.zone_end[ro, re]
        rank_e = SIGN_RANK[signs][:, None]
        rank_o = SIGN_RANK[signs][None, :]
        by_rule = (rank_o > rank_e) | ((rank_o == rank_e) & self.right_wins[re, ro])
        ranked = conflict & ~cleared_e & ~cleared_o
        merge_e = self.merge_at[re, ro]
        merging = ~np.isnan(merge_e)
        with np.errstate(invalid="ignore"):
            following = merging & (cleared_e | cleared_o)
            ahead = (so - self.merge_at[ro, re]) > (se - merge_e)
        out = (ranked & ~following & by_rule) | (conflict & following & ahead)
        np.fill_diagonal(out, False)
        return out


def build_priority_table(intersection: Intersection) -> PriorityTable:
    routes = intersection.routes
    count = len(routes)
    samples = [r.path.sample(SAMPLE_STEP)[:, :2] for r in routes]
    s_values = [np.linspace(0.0, r.path.length, len(p)) for r, p in zip(routes, samples)]
    low = [p.min(axis=0) - CONFLICT_DISTANCE for p in samples]
    high = [p.max(axis=0) + CONFLICT_DISTANCE for p in samples]
    conflict = np.zeros((count, count), dtype=bool)
    zone_start = np.full((count, count), np.inf)
    zone_end = np.full((count, count), -np.inf)
    merge_at = np.full((count, count), np.nan)
    right_wins = np.zeros((count, count), dtype=bool)
    lanes = intersection.lanes
    branches = intersection.branches
    for i in range(count):
        for j in range(i + 1, count):
            if routes[i].entry_lane == routes[j].entry_lane:
                continue
            if (low[i] > high[j]).any() or (low[j] > high[i]).any():
                continue  # bounding boxes apart: no conflict possible
            # squared distances as |p|^2 + |q|^2 - 2 p.q: one matrix product instead of a 3-D array
            pi, pj = samples[i], samples[j]
            squared = (pi * pi).sum(1)[:, None] + (pj * pj).sum(1)[None, :] - 2.0 * (pi @ pj.T)
            np.maximum(squared, 0.0, out=squared)
            # each direction: distance from every sample of one route to the nearest of the other
            for a, b, d in ((i, j, np.sqrt(squared.min(axis=1))), (j, i, np.sqrt(squared.min(axis=0)))):
                close = d < CONFLICT_DISTANCE
                if not close.any():
                    continue
                conflict[a, b] = True
                zone_start[a, b] = s_values[a][close].min()
                zone_end[a, b] = s_values[a][close].max()
                joined = d < MERGE_DISTANCE
                if joined[-1]:
                    # first index from which the routes stay joined to the end
                    first = len(joined) - int(np.argmin(joined[::-1])) if not joined.all() else 0
                    merge_at[a, b] = s_values[a][first]
                    # the merge zone ends once the vehicle is a length into the shared lane
                    zone_end[a, b] = merge_at[a, b] + VEHICLE_LENGTH
                lane_a, lane_b = lanes[routes[a].entry_lane], lanes[routes[b].entry_lane]
                right_wins[a, b] = _right_wins(
                    branches[lane_a.branch].angle_deg, branches[lane_b.branch].angle_deg,
                    routes[a].turn, routes[b].turn, lane_a.branch, lane_b.branch, lane_a.lane, lane_b.lane,
                )
    return PriorityTable(conflict, zone_end, zone_start, merge_at, right_wins)


def _right_wins(angle_i: float, angle_j: float, turn_i: str, turn_j: str,
                branch_i: int, branch_j: int, lane_i: int, lane_j: int) -> bool:
    """With equal signs, does the vehicle on route j have priority over the one on route i?"""
    if branch_i == branch_j:
        return lane_j > lane_i  # two lanes of one arm: the outer (right) lane goes first
    side = classify_turn(angle_i, angle_j)
    # an arm at +90 deg from ego's arm is the ego driver's right (right-hand traffic)
    if side == "right":
        return True
    if side == "left":
        return False
    if (turn_i == "left") != (turn_j == "left"):
        return turn_i == "left"  # opposite arms: the left turn yields
    return branch_j < branch_i


def is_right_of(angle_ego_deg: float, angle_other_deg: float) -> bool:
    """Is the arm at ``angle_other_deg`` on the right of a driver entering from ``angle_ego_deg``?"""
    return classify_turn(angle_ego_deg, angle_other_deg) == "right"


def draw_signs(rng: np.random.Generator, branch_count: int) -> np.ndarray:
    """One sign per arm, uniformly at random, never every arm the same (paper, "Environment")."""
    while True:
        signs = rng.integers(0, len(Sign), size=branch_count)
        if not (signs == signs[0]).all():
            return signs.astype(np.int8)


def redraw_one_sign(rng: np.random.Generator, signs: np.ndarray, branch: int) -> int:
    """A new sign for one arm such that the arms' signs are not all equal."""
    others = np.delete(signs, branch)
    choices = [s for s in range(len(Sign)) if not (others == s).all()]
    return int(rng.choice(choices))


__all__ = [
    "CONFLICT_DISTANCE", "PriorityTable", "SIGN_NAMES", "SIGN_RANK", "Sign", "build_priority_table",
    "draw_signs", "is_right_of", "redraw_one_sign", "sign_outranks",
]
