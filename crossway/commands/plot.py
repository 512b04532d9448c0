"""``crossway plot``: learning curves from the progress.csv files of ``crossway train`` and
``crossway pretrain``, as PNG."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from crossway.commands import HelpFormatter


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "plot", help="draw learning curves from progress.csv files (PNG)",
        description="Draw one curve per progress.csv (written by 'crossway train' into its run directory, or by "
                    "'crossway pretrain' into its --out), e.g. the rolling reach rate against agent-steps, or "
                    "--x samples --y student_reach_rate for a pretrain run.",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("progress", nargs="+", type=Path,
                        help="progress.csv files (or other CSVs, such as Table I's table1-S-tests.csv); "
                             "NAME=PATH sets a legend name")
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    parser.add_argument("--x", default="agent_steps", help="column on the x axis")
    parser.add_argument("--y", default="reach_rate", help="column on the y axis")
    parser.add_argument("--title", default="Reach rate (rolling, last 200 episodes)", help="plot title")
    parser.add_argument("--y-range", type=y_range_arg, metavar="LOW,HIGH", default=argparse.SUPPRESS,
                        help="y axis limits, e.g. 0.9,1 to tell rates near 1 apart (default: 0,1 for a column "
                             "whose name ends in 'rate', the data's range otherwise)")
    parser.add_argument("--where", action="append", type=where_arg, metavar="COLUMN=VALUE", default=[],
                        help="keep only the rows whose COLUMN holds VALUE (repeatable), e.g. for Table I's "
                             "table1-S-tests.csv: --x delay_max_s --y goal --where sign=stop")
    parser.add_argument("--markers", action="store_true", help="also draw a dot at every point")
    parser.add_argument("--x-label", default=None, help="x axis label (default: the --x column's name)")
    parser.add_argument("--y-label", default=None, help="y axis label (default: the --y column's name)")
    parser.set_defaults(func=run)


def where_arg(text: str) -> tuple[str, str]:
    column, equals, value = text.partition("=")
    if not equals or not column:
        raise argparse.ArgumentTypeError(f"expected COLUMN=VALUE, got {text!r}")
    return column, value


def y_range_arg(text: str) -> tuple[float, float]:
    try:
        low, high = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None
    if not (math.isfinite(low) and math.isfinite(high)):
        raise argparse.ArgumentTypeError(f"LOW and HIGH must be finite, got {text!r}")
    if not low < high:
        raise argparse.ArgumentTypeError(f"LOW must be under HIGH, got {text!r}")
    return low, high


def run(args) -> int:
    from crossway.plot import plot_curves, read_progress

    if args.out.suffix.lower() != ".png":
        raise ValueError(f"--out must end in .png, got {args.out.name!r}")
    if not args.out.parent.is_dir():
        raise ValueError(f"--out: directory {str(args.out.parent)!r} does not exist")
    series = []
    for item in args.progress:
        text = str(item)
        name, path = text.split("=", 1) if "=" in text else (Path(text).parent.name, text)
        if not Path(path).is_file():
            raise ValueError(f"no such file: {path}")
        xs, ys = read_progress(Path(path), args.x, args.y, dict(args.where))
        series.append((name, xs, ys))
    y_range = getattr(args, "y_range", None) or ((0.0, 1.0) if args.y.endswith("rate") else None)
    x_label = args.x_label or args.x.replace("_", " ")
    y_label = args.y_label or args.y.replace("_", " ")
    plot_curves(series, args.out, args.title, x_label, y_label, y_range,
                markers=args.markers)
    print(f"wrote {args.out}")
    return 0
