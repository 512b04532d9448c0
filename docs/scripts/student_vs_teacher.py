"""How well a pretrained student copies its teacher where it matters (docs/imitation.md).

    python docs/scripts/student_vs_teacher.py CHECKPOINT [--scenario hard] [--teacher-sight full|view]
        [--steps 6000] [--delay-max 30] [--seed 11]

The student (the policy's Gaussian means) drives every car; at every step the scripted teacher
(``ScriptedDriver``, as ``crossway pretrain`` labels) says what it would do in the same state. The
steps are split by the teacher's acceleration: "teacher brakes hard" (<= -1.5 m/s^2), "teacher
eases off" (-1.5 to 0) and "teacher holds or speeds up" (>= 0). For each: how many car-steps,
the student's mean acceleration, and how often the student brakes hard (<= -1.5 m/s^2) too.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

HARD_BRAKE_MPS2 = -1.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint")
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--teacher-sight", choices=("full", "view"), default="full")
    parser.add_argument("--steps", type=int, default=6000, help="simulator steps")
    parser.add_argument("--delay-max", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()

    import torch

    from evaluation.policy import PolicyDriver, load_policy
    from simcore.controller import ScriptedDriver, view_sight
    from simcore.simulator import SimConfig, Simulator

    torch.set_num_threads(1)
    sim = Simulator(args.scenario, SimConfig(delay_min_s=0.0, delay_max_s=args.delay_max), seed=args.seed)
    result = sim.reset()
    student = PolicyDriver(sim, load_policy(args.checkpoint))
    teacher = ScriptedDriver(sim, **(view_sight(sim) if args.teacher_sight == "view" else {}))
    pairs = []
    for _ in range(args.steps):
        on_road = np.flatnonzero(sim.learners_present)
        labels = teacher.act()  # first: the teacher's state (time at a stand) follows the road
        actions = student.act(result)
        pairs.append(np.stack([labels[on_road, 0], actions[on_road, 0]], axis=1))
        result = sim.step(actions)
    both = np.concatenate(pairs)
    teacher_acc, student_acc = both[:, 0], both[:, 1]
    groups = {"teacher brakes hard": teacher_acc <= HARD_BRAKE_MPS2,
              "teacher eases off": (teacher_acc > HARD_BRAKE_MPS2) & (teacher_acc < 0.0),
              "teacher holds or speeds up": teacher_acc >= 0.0}
    report = {"checkpoint": args.checkpoint, "scenario": args.scenario, "teacher_sight": args.teacher_sight,
              "car_steps": len(both)}
    for name, mask in groups.items():
        report[name] = {
            "car_steps": int(mask.sum()),
            "teacher_mean_mps2": round(float(teacher_acc[mask].mean()), 3) if mask.any() else None,
            "student_mean_mps2": round(float(student_acc[mask].mean()), 3) if mask.any() else None,
            "student_brakes_hard": (round(float((student_acc[mask] <= HARD_BRAKE_MPS2).mean()), 3)
                                    if mask.any() else None),
        }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
