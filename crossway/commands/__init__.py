"""One module per ``crossway`` subcommand: each exposes ``add_parser(subparsers)``."""
