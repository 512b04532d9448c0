"""Can the network learn the teacher's hard braking from its views at all? (docs/imitation.md)

    python docs/scripts/brake_learnability.py [--init-from models/hard.pt] [--scenario hard]
        [--teacher-sight view] [--train-samples 60000] [--held-out-samples 15000] [--epochs 8]
        [--brake-weight 1] [--delay-max 30] [--threads 2]

The scripted teacher (``ScriptedDriver``, as ``crossway pretrain`` labels) drives every car and
labels every car-step, on two separate sets of episodes (simulator seeds 0 and 1): a training
set and a held-out set. The network (from ``--init-from``) then trains on the training set
alone, epoch after epoch, with ``crossway pretrain``'s loss, and after each epoch both sets are
scored where it matters: the car-steps whose label is a hard braking decision (<= -1.5 m/s^2).
"brake recall" is the share of those where the network brakes that hard too; "false brakes" the
share of the other car-steps where it does. If the network fits the training set's braking but
not the held-out set's, the views hold the decision and the students lack data; if it cannot
fit even the training set, the decision is not in its input (or beyond the network).

Progress on stderr; one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np


def score(policy, buffer, indices: np.ndarray, brake_label: float) -> dict:
    """Squared errors and braking agreement of the network's acceleration means on ``indices``."""
    import torch

    from algo.policy import preprocess

    means = []
    with torch.no_grad():
        for start in range(0, len(indices), 256):
            batch = indices[start:start + 256]
            views, scalars = buffer.observations(batch)
            mu_acc, _, _, _ = policy(*preprocess(views, scalars))
            means.append(mu_acc.numpy())
    mu = np.concatenate(means)
    label = buffer.targets[indices % buffer.capacity, 0]
    braking = label <= brake_label
    return {
        "samples": int(len(indices)),
        "braking_share": round(float(braking.mean()), 4),
        "mse_acc": round(float(((mu - label) ** 2).mean()), 5),
        "mse_acc_braking": round(float(((mu - label)[braking] ** 2).mean()), 5) if braking.any() else None,
        "brake_recall": round(float((mu[braking] <= brake_label).mean()), 4) if braking.any() else None,
        "false_brakes": round(float((mu[~braking] <= brake_label).mean()), 4) if (~braking).any() else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--init-from", default="models/hard.pt")
    parser.add_argument("--scenario", default="hard")
    parser.add_argument("--teacher-sight", choices=("full", "view"), default="view")
    parser.add_argument("--train-samples", type=int, default=60_000)
    parser.add_argument("--held-out-samples", type=int, default=15_000)
    parser.add_argument("--epochs", type=int, default=8)
    parser.add_argument("--brake-weight", type=float, default=1.0)
    parser.add_argument("--delay-max", type=float, default=30.0)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    if min(args.train_samples, args.held_out_samples, args.epochs) < 1:
        parser.error("--train-samples, --held-out-samples and --epochs must be >= 1")

    from pathlib import Path

    from algo.imitation import BRAKE_LABEL
    from learner.pretrain import Pretrainer, PretrainConfig

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    started = time.monotonic()
    sets = {}
    for name, samples, seed in (("train", args.train_samples, 0), ("held_out", args.held_out_samples, 1)):
        config = PretrainConfig(scenario=args.scenario, teacher_sight=args.teacher_sight,
                                teacher_half_life=float("inf"), buffer_samples=samples, delay_max_s=args.delay_max,
                                brake_weight=args.brake_weight, seed=seed, init_from=Path(args.init_from),
                                torch_threads=args.threads)
        collector = Pretrainer(config)
        while collector.buffer.added < samples:
            collector.collect(500)
            log(f"{name}: {min(collector.buffer.added, samples):,}/{samples:,} samples "
                f"({time.monotonic() - started:.0f} s)")
        sets[name] = collector
    trainer = sets["train"]  # its network learns; the held-out collector's is never used
    rng = np.random.default_rng(2)

    def valid(buffer) -> np.ndarray:
        low = buffer.added - len(buffer) + (3 if buffer.added > buffer.capacity else 0)
        return np.arange(low, buffer.added)

    train_all = valid(trainer.buffer)
    train_probe = rng.choice(train_all, size=min(10_000, len(train_all)), replace=False)
    held_out = valid(sets["held_out"].buffer)
    epochs = []

    def record(epoch: int) -> None:
        trainer.policy.eval()
        row = {"epoch": epoch, "updates": trainer.updates, "wall_s": round(time.monotonic() - started, 1),
               "train": score(trainer.policy, trainer.buffer, train_probe, BRAKE_LABEL),
               "held_out": score(trainer.policy, sets["held_out"].buffer, held_out, BRAKE_LABEL)}
        trainer.policy.train()
        epochs.append(row)
        log(f"epoch {epoch}: brake recall train {row['train']['brake_recall']} held-out "
            f"{row['held_out']['brake_recall']}, mse on braking train {row['train']['mse_acc_braking']} held-out "
            f"{row['held_out']['mse_acc_braking']} ({row['wall_s']:.0f} s)")

    record(0)
    updates_per_epoch = max(1, len(trainer.buffer) // trainer.config.batch_size)
    for epoch in range(1, args.epochs + 1):
        trainer.train(updates_per_epoch)
        record(epoch)
    print(json.dumps({"command": " ".join(["python", "docs/scripts/brake_learnability.py", *sys.argv[1:]]),
                      "scenario": args.scenario, "teacher_sight": args.teacher_sight, "init_from": args.init_from,
                      "brake_weight": args.brake_weight, "delay_max_s": args.delay_max,
                      "train_samples": len(trainer.buffer), "held_out_samples": len(held_out), "epochs": epochs}))


if __name__ == "__main__":
    main()
