"""Can the acceleration sub-module see a crash coming? A supervised check, outside RL.

Records every learner step of a policy driving a scenario (views, speeds), labels a step 1 when
its car crashes within ``--horizon`` steps, and trains the acceleration sub-module's network
(``algo.policy.SubModule``, its value output as a logit) to classify the steps, from fresh
weights or from a checkpoint's acceleration head. Prints the held-out ROC AUC per epoch as JSON
lines. If the network learns this quickly while RL's critic does not
(``crossway evaluate reaction`` reports the critic's AUC), the input and the architecture are not
what stops the agents from learning to give way (docs/training.md#giving-way-why-our-agents-have-not-learned-it-yet).

    python tools/crash_risk_capacity.py --checkpoint models/easy.pt --init fresh models/easy.pt
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from algo.policy import PolicyConfig, SubModule, preprocess
from evaluation.policy import PolicyDriver, load_policy
from evaluation.reaction import roc_auc
from simcore.simulator import SimConfig, Simulator


def record(checkpoint: str, scenario: str, steps: int, delay_max_s: float, horizon: int, seed: int):
    """Views [N, 16, 84, 84], speeds [N, 2] and labels [N] of every step of finished episodes."""
    sim = Simulator(scenario, SimConfig(delay_min_s=0.0, delay_max_s=delay_max_s), seed=seed)
    driver = PolicyDriver(sim, load_policy(checkpoint))
    result = sim.reset()
    open_episodes: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    views, speeds, labels = [], [], []
    for _ in range(steps):
        for slot in np.flatnonzero(result.observed).tolist():
            open_episodes.setdefault(slot, []).append((result.views[slot].copy(), result.scalars[slot].copy()))
        result = sim.step(driver.act(result))
        for episode in result.episodes:
            rows = open_episodes.pop(episode.slot, [])
            if episode.end_reason in ("sign_change", "horizon"):
                continue
            for k, (v, s) in enumerate(rows):
                views.append(v)
                speeds.append(s)
                labels.append(episode.end_reason == "crash" and len(rows) - k <= horizon)
    return np.stack(views), np.stack(speeds), np.array(labels, dtype=np.float32)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--checkpoint", required=True, help="policy that drives while steps are recorded")
    parser.add_argument("--scenario", default="easy")
    parser.add_argument("--steps", type=int, default=15000, help="simulator steps to record (0.1 s each)")
    parser.add_argument("--delay-max", type=float, default=10.0, help="longest wait between episodes [s]")
    parser.add_argument("--horizon", type=int, default=20, help="'about to crash': within this many steps")
    parser.add_argument("--epochs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--init", nargs="+", default=["fresh"],
                        help="'fresh' and/or checkpoints whose acceleration head starts the classifier")
    args = parser.parse_args()
    started = time.monotonic()
    views, speeds, labels = record(args.checkpoint, args.scenario, args.steps, args.delay_max, args.horizon,
                                   args.seed)
    split = int(0.8 * len(labels))  # the last fifth of the recording is held out
    print(json.dumps({"samples": len(labels), "positives": int(labels.sum()),
                      "held_out_positives": int(labels[split:].sum()),
                      "record_s": round(time.monotonic() - started, 1)}), flush=True)
    target = torch.from_numpy(labels)
    for init in args.init:
        torch.manual_seed(0)
        network = SubModule(PolicyConfig())
        if init != "fresh":
            state = torch.load(init, weights_only=False, map_location="cpu")["policy"]
            network.load_state_dict({k.removeprefix("acc."): v for k, v in state.items() if k.startswith("acc.")})
        optimiser = torch.optim.Adam(network.parameters(), lr=3e-4)
        for epoch in range(args.epochs):
            for batch in torch.randperm(split).split(64):
                rows = batch.numpy()
                _, logit = network(*preprocess(views[rows], speeds[rows]))
                loss = torch.nn.functional.binary_cross_entropy_with_logits(
                    logit, target[batch], pos_weight=torch.tensor(5.0))
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
            with torch.no_grad():
                scores = np.concatenate([network(*preprocess(views[i:i + 512], speeds[i:i + 512]))[1].numpy()
                                         for i in range(split, len(labels), 512)])
            auc = round(roc_auc(scores, labels[split:]), 4)
            print(json.dumps({"init": init, "epoch": epoch + 1, "held_out_auc": auc}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
