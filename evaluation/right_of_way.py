"""The right-of-way test's infraction check (paper, "Testing the Right of Way Rule", Table II).

An agent commits an infraction when it enters a conflict area before an agent that has
priority over it there and that will also cross it. Precisely, for every ordered pair (a, b) of
agents of one episode whose routes conflict (``PriorityTable.conflict``):

- b has priority over a by the rule alone (``PriorityTable`` with both still short of the
  zone): b's sign outranks a's, or the signs are equal and b comes from a's right (or the
  opposite-arm and tie-break rules of ``simcore.rightofway``);
- a *enters* the area at the first step its front reaches the zone's start on its route,
  ``s + length/2 >= zone_start``; b likewise on its own route;
- a's infraction: b has priority, b enters at some step of the episode, and a entered strictly
  earlier. If b never enters (it ended before), nobody was wronged: no infraction.

An episode is "no infraction" when no ordered pair has one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simcore.dynamics import VEHICLE_LENGTH
from simcore.rightofway import PriorityTable


@dataclass(frozen=True)
class Infraction:
    offender: int  # agent index
    wronged: int  # the agent with priority that entered later
    offender_entry_step: int
    wronged_entry_step: int


def entry_step(s_track: np.ndarray, zone_start: float) -> int | None:
    """First step at which a car's front reaches ``zone_start``; ``s_track`` [T] is NaN when absent."""
    reached = np.flatnonzero(s_track + 0.5 * VEHICLE_LENGTH >= zone_start)
    return int(reached[0]) if len(reached) else None


def find_infractions(table: PriorityTable, routes: np.ndarray, signs: np.ndarray,
                     s_tracks: np.ndarray) -> list[Infraction]:
    """Infractions of one episode: ``routes`` [N], ``signs`` [N] and ``s_tracks`` [N, T] (arc
    length of each agent's centre per step, NaN when it is not on the road)."""
    n = len(routes)
    start = np.full(n, -1e9)  # priority by the rule: evaluated with every car far from the zones
    higher = table.higher(np.asarray(routes), start, np.asarray(signs))
    found = []
    for a in range(n):
        for b in range(n):
            if a == b or not higher[a, b]:
                continue
            a_entry = entry_step(s_tracks[a], table.zone_start[routes[a], routes[b]])
            b_entry = entry_step(s_tracks[b], table.zone_start[routes[b], routes[a]])
            if a_entry is not None and b_entry is not None and a_entry < b_entry:
                found.append(Infraction(a, b, a_entry, b_entry))
    return found
