"""The ``fresco-bridge`` console entry: ``diagnose`` and ``diagnose-bench`` start light.

The diagnosis needs nothing of the daemon, yet ``fresco_bridge.cli`` imports every command's
module (config models, sites, controllers, pydantic), seconds of a cold start on a loaded
machine (BENCHMARKS.md, "Diagnosis"). Those two commands are parsed here with the same
``add_diagnosis_parsers``; every other command line, ``--help`` included, goes to ``cli.main``
unchanged. Both end through the same error boundary (``exit_codes.exit_code``).

The long commands on the full parser (``demo``, ``study``, ``updater``, ``lab integrate``) say
they are starting before that import, on a terminal: a person sees the command alive within a
second even on a cold start (the first run after an install compiles every module).
"""

from __future__ import annotations

import argparse
import sys

from .diagnosis.cli import COMMANDS, add_diagnosis_parsers, diagnosis_command
from .exit_codes import BROKEN_PIPE_EXIT, exit_code
from .progress import status

__all__ = ["BROKEN_PIPE_EXIT", "main"]

LONG_COMMANDS = {"demo": 1, "study": 2, "updater": 2, "lab": 2}
"""Commands that take seconds before their own first line: how many words name them."""


def _starting(args: list[str]) -> None:
    """``fresco-bridge study paper: starting...`` on stderr, when it is a terminal."""
    words = LONG_COMMANDS.get(args[0]) if args else None
    if (words is None or len(args) < words or args[words - 1].startswith("-")
            or args[:2] == ["lab", "up"] or "-h" in args or "--help" in args):
        return  # not a long command, or a usage error / help: argparse answers at once
    status(f"fresco-bridge {' '.join(args[:words])}: starting...")


def main(argv: list[str] | None = None) -> int:
    """Run one command line (``sys.argv[1:]`` by default); the exit code."""
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in COMMANDS:
        _starting(args)
        from .cli import main as full_main

        return full_main(args)
    parser = argparse.ArgumentParser(prog="fresco-bridge")
    add_diagnosis_parsers(parser.add_subparsers(dest="command", required=True))
    parsed = parser.parse_args(args)
    return exit_code(lambda: diagnosis_command(parsed))


if __name__ == "__main__":
    sys.exit(main())
