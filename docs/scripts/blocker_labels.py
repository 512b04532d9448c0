"""How a student copies its teacher's braking for blockers, and how often that braking comes before its crashes.

    python docs/scripts/blocker_labels.py CHECKPOINT [--scenario hard] [--steps 20000] [--delay-max 30]
        [--seed 7] [--teacher-patience 4]

The student (the policy's Gaussian means) drives every car; at every step the hard students' teacher
(view-limited, approaching at 2 m/s by its own sign, braking for blockers, waiting outside zones,
breaking wait cycles: ``crossway pretrain --teacher-*`` as in docs/imitation.md) says what it would
do in the same state, and whether that is its braking for a car standing in its way
(``ScriptedDriver.blocker_bound``, the labels ``crossway pretrain --blocker-weight`` counts more).
Prints one JSON object:

- ``labels``: per kind of step (teacher brakes for a blocker; teacher brakes hard, -1.5 m/s^2 or
  more, for another reason; every other step), how many car-steps, the teacher's and the student's
  mean acceleration [m/s^2] and the student's mean squared error in normalised units (the
  imitation loss's);
- ``crashes``: for every car that crashed, over its last ``LAST_STEPS`` steps (3 s), how many
  steps the teacher braked hard in, how many it braked for a blocker in, and both drivers' mean
  acceleration [m/s^2].
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from algo.imitation import BRAKE_LABEL
from algo.policy import ACTION_SCALE

HARD_BRAKE_MPS2 = BRAKE_LABEL * float(ACTION_SCALE[0])  # the imitation loss's hard-braking label [m/s^2]
LAST_STEPS = 30  # the crashed car's last steps looked at (0.1 s each)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint")
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--steps", type=int, default=20_000, help="simulator steps (0.1 s each)")
    parser.add_argument("--delay-max", type=float, default=30.0, help="longest wait between a lane's episodes [s]")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--teacher-patience", type=float, default=4.0,
                        help="the teacher's patience [s] ('inf': never); for blockers twice that")
    args = parser.parse_args()

    import torch

    from algo.policy import load_policy
    from evaluation.policy import PolicyDriver, check_checkpoint
    from simcore.controller import DriverOptions, scripted_driver
    from simcore.simulator import SimConfig, Simulator

    torch.set_num_threads(1)
    sim = Simulator(args.scenario, SimConfig(delay_max_s=args.delay_max), seed=args.seed)
    check_checkpoint(args.checkpoint, sim.spec)
    options = DriverOptions(sight="view", approach_speed_mps=2.0, approach_signs="own", brake_for_blockers=True,
                            wait_outside_zones=True, break_wait_cycles=True, patience_s=args.teacher_patience,
                            blocker_patience_s=2.0 * args.teacher_patience)
    teacher = scripted_driver(sim, options)
    student = PolicyDriver(sim, load_policy(args.checkpoint))

    kinds = ("teacher brakes for a blocker", "teacher brakes hard for another reason", "other steps")
    sums = {k: np.zeros(4) for k in kinds}  # count, teacher acc, student acc, squared error
    last = collections.defaultdict(lambda: collections.deque(maxlen=LAST_STEPS))
    crashes, end_reasons = [], collections.Counter()
    result = sim.reset()
    for _ in range(args.steps):
        labels = teacher.act()
        actions = student.act(result)
        for slot in np.flatnonzero(sim.learners_present).tolist():
            label = float(np.clip(labels[slot, 0], -ACTION_SCALE[0], ACTION_SCALE[0]))
            acc = float(actions[slot, 0])
            blocker = bool(teacher.blocker_bound[slot])
            kind = kinds[0] if blocker else kinds[1] if label <= HARD_BRAKE_MPS2 else kinds[2]
            sums[kind] += (1.0, label, acc, ((acc - label) / ACTION_SCALE[0]) ** 2)
            last[slot].append((label, acc, blocker))
        result = sim.step(actions)
        for summary in result.episodes:
            end_reasons[summary.end_reason] += 1
            if summary.end_reason == "crash" and last[summary.slot]:
                steps = np.array(last[summary.slot], dtype=float)
                crashes.append({"teacher_hard_brake_steps": int((steps[:, 0] <= HARD_BRAKE_MPS2).sum()),
                                "teacher_blocker_steps": int(steps[:, 2].sum()),
                                "teacher_mean_mps2": round(float(steps[:, 0].mean()), 2),
                                "student_mean_mps2": round(float(steps[:, 1].mean()), 2)})
            last[summary.slot].clear()
    total = sum(s[0] for s in sums.values())
    report = {
        "checkpoint": args.checkpoint, "scenario": args.scenario, "steps": args.steps, "seed": args.seed,
        "delay_max_s": args.delay_max, "teacher": options.record(), "end_reasons": dict(end_reasons),
        "labels": {k: {"car_steps": int(s[0]), "share": round(float(s[0] / max(total, 1)), 4),
                       "teacher_mean_mps2": round(float(s[1] / max(s[0], 1)), 3),
                       "student_mean_mps2": round(float(s[2] / max(s[0], 1)), 3),
                       "squared_error": round(float(s[3] / max(s[0], 1)), 4)} for k, s in sums.items()},
        "crashes": crashes,
        "crashes_after_blocker_braking": sum(c["teacher_blocker_steps"] > 0 for c in crashes),
    }
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
