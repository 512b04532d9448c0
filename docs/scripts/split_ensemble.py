"""Write each member of an output ensemble as a policy file of its own (session 41).

    python docs/scripts/split_ensemble.py ENSEMBLE.pt OUT_DIR

The reverse of docs/scripts/ensemble.py: OUT_DIR/member-1.pt ... member-K.pt, each the member's
weights and sizes with the ensemble's views record and a note naming where it came from, which
every crossway command takes as ``--checkpoint`` or ``--init-from``. The ensemble's ``caution``
belongs to the members' vote and is not copied; its ``emergency_braking`` is copied to each member
(``crossway evaluate export --no-emergency-braking`` drops it). Joining the files again with
ensemble.py gives the same network.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from algo.policy import load_policy, save_atomically


def split(ensemble: str | Path, out_dir: str | Path) -> list[Path]:
    """The members' files, written into ``out_dir``; ValueError when ``ensemble`` is no ensemble."""
    load_policy(ensemble)  # a clear error for a file that is no policy
    state = torch.load(Path(ensemble), weights_only=False, map_location="cpu")
    if "members" not in state:
        raise ValueError(f"{ensemble} is a single network, not an output ensemble (no members)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, member in enumerate(state["members"], start=1):
        record = {"policy": member["policy"], "policy_config": member["policy_config"], "version": None,
                  "agent_steps": None, "note": f"member {k} of {len(state['members'])} of {ensemble}"}
        for entry in ("views", "emergency_braking"):
            if state.get(entry) is not None:
                record[entry] = state[entry]
        paths.append(save_atomically(record, out_dir / f"member-{k}.pt"))
    return paths


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("ensemble", help="an output ensemble (docs/scripts/ensemble.py)")
    parser.add_argument("out_dir", help="folder for member-1.pt ... member-K.pt")
    args = parser.parse_args()
    try:
        paths = split(args.ensemble, args.out_dir)
    except ValueError as error:
        sys.exit(f"split_ensemble: {error}")
    for path in paths:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
