"""Join several policies into one that drives by the mean of their outputs (session 22).

    python docs/scripts/ensemble.py OUT.pt CKPT CKPT [CKPT ...] [--caution C [--caution-fade-standing S]
        [--caution-full-from-speed V] [--caution-full-below-speed V] [--caution-signs none,yield]]
    python docs/scripts/ensemble.py OUT.pt ENSEMBLE.pt --caution C   (the same members, another rule)

Writes one checkpoint that holds every member's weights and sizes; every crossway command loads
it as one network (``algo.policy.load_policy``, ``algo.policy.ensemble``) whose acceleration and
steering means are tanh of the members' mean pre-activation and whose values are the members'
mean. Unlike a weight average (docs/scripts/weight_soup.py) the members need not share a start
or a size; they must have learnt from the same view square. An ensemble among the checkpoints
joins in as its members (so two ensembles of 3 make one of 6, each member counting once). OUT
keeps the first one's views record and names the checkpoints in its note. Evaluate it as any
checkpoint (``crossway evaluate table1 --checkpoint OUT.pt``); ``evaluation.policy.PolicyDriver``
runs the members side by side, at less than the cost of all of them one after the other.

``--caution C`` (session 24, ``algo.policy.Caution``) makes the ensemble brake where its members
disagree: its acceleration is tanh of the members' mean pre-activation minus C of their standard
deviations; ``--caution-fade-standing S`` lets C fall to 0 over S seconds of standing still,
``--caution-full-from-speed V`` scales C with the car's speed (0 at standstill, all of it from V m/s),
``--caution-full-below-speed V`` the other way (all of it at standstill, 0 from V m/s),
``--caution-signs`` limits it to cars whose view shows one of those signs (``algo.policy.sign_in_view``).
A negative C (session 34) is boldness: the members' mean plus |C| standard deviations, the eager
side of their vote (``--caution -1 --caution-full-below-speed 4 --caution-signs none,yield``: the
cars with priority that dawdle near their line go on it).
Without it the rule of an ensemble among the checkpoints is dropped (the plain mean)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

import torch

from algo.policy import Caution, load_policy, policy_views, save_atomically


def joined_checkpoint(checkpoints: list[str], caution: Caution | None = None) -> dict:
    """The ensemble's checkpoint: each member's weights and sizes (``algo.policy.load_policy`` joins
    them into one network), the first one's views record, the ``caution`` rule and a note;
    ValueError when a file is not a policy, the members learnt from different view squares or
    fewer than two members result."""
    policies = [load_policy(path) for path in checkpoints]
    views = {policy_views(path) for path in checkpoints}
    if len(views) != 1:
        raise ValueError(f"the checkpoints learnt from different view squares: {sorted(map(str, views))}")
    states = [torch.load(Path(path), weights_only=False, map_location="cpu") for path in checkpoints]
    members = []
    for state, policy in zip(states, policies):  # an ensemble among the checkpoints joins in as its members
        members.extend(state["members"] if "members" in state
                       else [{"policy": policy.state_dict(), "policy_config": asdict(policy.config)}])
    if len(members) < 2:
        raise ValueError(f"an ensemble needs at least two members, the checkpoints hold {len(members)}")
    rule = "mean before the tanh" + ("" if caution is None else f", {caution.describe()}")
    out = {"members": members, "version": None, "agent_steps": None,
           "caution": None if caution is None else caution.record(),
           "note": f"output ensemble ({rule}) of " + ", ".join(checkpoints)}
    if "views" in states[0]:
        out["views"] = states[0]["views"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="where to write the joined checkpoint")
    parser.add_argument("checkpoints", nargs="+",
                        help="policies to join (checkpoints or models/*.pt): two or more, or one ensemble")
    parser.add_argument("--caution", type=float, default=None, metavar="C",
                        help="brake where the members disagree: acceleration = tanh(mean - C x standard deviation "
                             "of the members' pre-activations); a negative C is boldness (mean plus |C| standard "
                             "deviations); default: the plain mean")
    parser.add_argument("--caution-fade-standing", type=float, default=None, metavar="S",
                        help="C falls linearly to 0 over S seconds of standing still (under 0.5 m/s) [s]")
    parser.add_argument("--caution-full-from-speed", type=float, default=None, metavar="V",
                        help="C grows linearly with the car's speed, from 0 at standstill to all of it at V m/s")
    parser.add_argument("--caution-full-below-speed", type=float, default=None, metavar="V",
                        help="C falls linearly with the car's speed, from all of it at standstill to 0 at V m/s "
                             "(only slow cars are touched)")
    parser.add_argument("--caution-signs", default=None, metavar="SIGNS",
                        help="brake only cars whose view shows one of these signs, comma-separated from "
                             "none, yield, stop (e.g. none,yield); default: every car")
    args = parser.parse_args()
    if (args.caution_fade_standing is not None or args.caution_full_from_speed is not None
            or args.caution_full_below_speed is not None or args.caution_signs is not None) and args.caution is None:
        parser.error("--caution-fade-standing, --caution-full-from-speed, --caution-full-below-speed and "
                     "--caution-signs need --caution")
    try:
        signs = None if args.caution_signs is None else tuple(s.strip() for s in args.caution_signs.split(","))
        caution = (None if args.caution is None else
                   Caution(args.caution, args.caution_fade_standing, args.caution_full_from_speed, signs,
                           args.caution_full_below_speed))
        joined = joined_checkpoint(args.checkpoints, caution)
    except ValueError as error:
        sys.exit(f"ensemble: {error}")
    save_atomically(joined, args.out)
    sizes = load_policy(args.out).config
    print(f"wrote {args.out}: the output ensemble of {len(joined['members'])} policies, one network "
          f"{sizes.conv1_channels},{sizes.conv2_channels},{sizes.hidden}"
          + (" with the standing-time input" if sizes.standing_input else "")
          + ("" if caution is None else f"; caution: {caution.describe()}"))


if __name__ == "__main__":
    main()
