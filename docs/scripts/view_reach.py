"""Draw docs/pictures/hard-view-reach.png: what the centred 50 x 50 m view shows from the stop line.

    python docs/scripts/view_reach.py [OUT.png]

The hard junction, empty but for three cars placed by hand: the ego (south_1, straight, its front
at the stop line), a car coming from its right (east_1, straight) and one from its left (west_1,
straight), both 8 m before their own stop lines at 8 m/s, one second from them. The panel shows the ego's four views.
"""

from __future__ import annotations

import sys

import numpy as np

from simcore.dynamics import VEHICLE_LENGTH
from simcore.render import render_frame
from simcore.simulator import SimConfig, Simulator


def place(sim: Simulator, lane: str, before_line_m: float, speed_mps: float, target_speed_mps: float = 8.0) -> int:
    """Put a car on ``lane``'s straight route, its centre ``before_line_m`` before the stop line."""
    slot = sim.slot_names.index(lane)
    entry = next(l for l in sim.intersection.lanes if l.name == lane)
    route = next(r for r in entry.routes if sim.intersection.routes[r].turn == "straight")
    path = sim.intersection.routes[route].path
    s = sim.intersection.routes[route].junction_entry_s - before_line_m
    sim.route[slot], sim.s[slot], sim.r[slot] = route, s, 0.0
    sim.x[slot], sim.y[slot] = path.position(s, 0.0)
    sim.heading[slot] = path.heading_at(s)
    sim.speed[slot], sim.target_speed[slot] = speed_mps, target_speed_mps
    sim.sign[slot], sim.steps[slot], sim.present[slot] = 0, 0, True
    return slot


def scene() -> tuple[Simulator, object, int]:
    """The simulator after one step of the scene, its StepResult and the ego's slot."""
    sim = Simulator("hard", SimConfig(start_all_at_reset=False, delay_min_s=1e6, delay_max_s=1e6), seed=0)
    sim.reset()
    sim.branch_signs[:] = 0  # no signs: priority to the right
    ego = place(sim, "south_1", 0.5 * VEHICLE_LENGTH, 0.0)
    place(sim, "east_1", 8.0, 8.0)
    place(sim, "west_1", 8.0, 8.0)
    return sim, sim.step(np.zeros((sim.num_slots, 2))), ego


def main(out: str = "docs/pictures/hard-view-reach.png") -> None:
    sim, result, ego = scene()
    frame = render_frame(sim, result, focus_slot=ego, pixels_per_m=4.0,
                         caption="hard: the ego at its stop line; cars 8 m before theirs")
    _png(frame, out)


def _png(frame: np.ndarray, out: str) -> None:
    import cairo

    h, w, _ = frame.shape
    rgba = np.zeros((h, w, 4), np.uint8)
    rgba[..., 0], rgba[..., 1], rgba[..., 2], rgba[..., 3] = frame[..., 2], frame[..., 1], frame[..., 0], 255
    cairo.ImageSurface.create_for_data(memoryview(rgba), cairo.FORMAT_RGB24, w, h).write_to_png(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
