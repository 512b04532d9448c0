"""One module per ``crossway`` subcommand: each exposes ``add_parser(subparsers)``."""

import argparse


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's ArgumentDefaultsHelpFormatter ("(default: X)" after an option's help) without the
    noise: nothing for a default of None or "", a required option, an on/off flag, or a help text that
    already says what happens by default."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (action.default is None or action.default == "" or action.required or action.nargs == 0
                or "default" in text.lower()):
            return text
        return super()._get_help_string(action)
