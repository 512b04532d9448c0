"""Join several policies into one network that drives by the mean of their outputs (session 22).

    python docs/scripts/ensemble.py OUT.pt CKPT CKPT [CKPT ...]

Writes one checkpoint whose network holds every member side by side (``algo.policy.ensemble``):
its acceleration and steering means are tanh of the members' mean pre-activation, its values the
members' mean. Unlike a weight average (docs/scripts/weight_soup.py) the members need not share a
start or a size; they must have learnt from the same view square. OUT keeps the first one's views
record and names its members in its note. Evaluate it as any checkpoint (``crossway evaluate table1
--checkpoint OUT.pt``); it costs about as much as its members together.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

import torch

from algo.policy import ensemble, load_policy, policy_views


def joined_checkpoint(checkpoints: list[str]) -> dict:
    """The ensemble's checkpoint (a dict as ``crossway evaluate export`` writes); ValueError when a
    file is not a policy or the members learnt from different view squares."""
    policies = [load_policy(path) for path in checkpoints]
    views = {policy_views(path) for path in checkpoints}
    if len(views) != 1:
        raise ValueError(f"the checkpoints learnt from different view squares: {sorted(map(str, views))}")
    joined = ensemble(policies)
    first = torch.load(Path(checkpoints[0]), weights_only=False, map_location="cpu")
    out = {"policy": joined.state_dict(), "policy_config": asdict(joined.config), "version": None,
           "agent_steps": None, "note": "output ensemble (mean before the tanh) of " + ", ".join(checkpoints)}
    if "views" in first:
        out["views"] = first["views"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="where to write the joined checkpoint")
    parser.add_argument("checkpoints", nargs="+", help="two or more policies (checkpoints or models/*.pt)")
    args = parser.parse_args()
    if len(args.checkpoints) < 2:
        parser.error("give at least two checkpoints to join")
    try:
        joined = joined_checkpoint(args.checkpoints)
    except ValueError as error:
        sys.exit(f"ensemble: {error}")
    torch.save(joined, args.out)
    sizes = joined["policy_config"]
    print(f"wrote {args.out}: the output ensemble of {len(args.checkpoints)} policies, network "
          f"{sizes['conv1_channels']},{sizes['conv2_channels']},{sizes['hidden']}"
          + (" with the standing-time input" if sizes["standing_input"] else ""))


if __name__ == "__main__":
    main()
