"""The ``crossway`` command: one entry point, one subcommand per job.

Each subcommand lives in ``crossway.commands.<name>`` and registers itself with
``add_parser(subparsers)``, setting ``func`` to the callable that runs it.
"""

from __future__ import annotations

import argparse
import sys

from crossway import __version__
from crossway.commands import bench, distributed, evaluate, plot, pretrain, render

COMMANDS = (distributed, pretrain, evaluate, render, bench, plot)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="crossway",
        description=(
            "Train cars to cross unsignalled intersections with multi-agent deep reinforcement "
            "learning (after Capasso et al., 'End-to-End Intersection Handling using Multi-Agent "
            "Deep Reinforcement Learning')."
        ),
        epilog="Run 'crossway COMMAND --help' for the options of each command.",
    )
    parser.add_argument("--version", action="version", version=f"crossway {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except (ValueError, FileNotFoundError) as error:
        # bad input: say what is wrong, no traceback
        print(f"crossway {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
