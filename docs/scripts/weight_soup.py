"""Average the weights of several students into one policy, a "model soup" (docs/imitation.md, session 20).

    python docs/scripts/weight_soup.py OUT.pt CKPT CKPT [CKPT ...]

Writes the uniform average of the checkpoints' weights (Wortsman et al. 2022, "Model soups"), which
only means something for networks fine-tuned from one start: here students pretrained from the
same exported policy. Every checkpoint must hold the same network (``PolicyConfig``) and have
learnt from the same view square; OUT keeps the first one's views record and names its parts in
its note. Evaluate it as any checkpoint (``crossway evaluate table1 --checkpoint OUT.pt``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from algo.policy import load_policy, policy_views, save_atomically


def soup(checkpoints: list[str]) -> dict:
    """The averaged checkpoint (a dict as ``crossway evaluate export`` writes); ValueError when the
    networks or their views differ."""
    policies = [load_policy(path) for path in checkpoints]
    configs = {policy.config for policy in policies}
    if len(configs) != 1:
        raise ValueError(f"the checkpoints hold different networks: {sorted(map(str, configs))}")
    views = {policy_views(path) for path in checkpoints}
    if len(views) != 1:
        raise ValueError(f"the checkpoints learnt from different view squares: {sorted(map(str, views))}")
    states = [policy.state_dict() for policy in policies]
    averaged = {name: torch.stack([state[name].double() for state in states]).mean(0).to(tensor.dtype)
                for name, tensor in states[0].items()}
    first = torch.load(Path(checkpoints[0]), weights_only=False, map_location="cpu")
    out = {"policy": averaged, "policy_config": vars(policies[0].config), "version": None, "agent_steps": None,
           "note": "uniform weight average of " + ", ".join(checkpoints)}
    if "views" in first:
        out["views"] = first["views"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="where to write the averaged checkpoint")
    parser.add_argument("checkpoints", nargs="+", help="two or more checkpoints with one start")
    args = parser.parse_args()
    if len(args.checkpoints) < 2:
        parser.error("give at least two checkpoints to average")
    try:
        averaged = soup(args.checkpoints)
    except ValueError as error:
        sys.exit(f"weight_soup: {error}")
    save_atomically(averaged, args.out)
    print(f"wrote {args.out}: the average of {len(args.checkpoints)} checkpoints")


if __name__ == "__main__":
    main()
