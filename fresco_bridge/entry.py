"""The ``fresco-bridge`` console entry: ``diagnose`` and ``diagnose-bench`` start light.

The diagnosis needs nothing of the daemon, yet ``fresco_bridge.cli`` imports every command's
module (config models, sites, controllers, pydantic), seconds of a cold start on a loaded
machine (BENCHMARKS.md, "Diagnosis"). Those two commands are parsed here with the same
``add_diagnosis_parsers``; every other command line, ``--help`` included, goes to ``cli.main``
unchanged. Both end through the same error boundary (``exit_codes.exit_code``).
"""

from __future__ import annotations

import argparse
import sys

from .diagnosis.cli import COMMANDS, add_diagnosis_parsers, diagnosis_command
from .exit_codes import BROKEN_PIPE_EXIT, exit_code

__all__ = ["BROKEN_PIPE_EXIT", "main"]


def main(argv: list[str] | None = None) -> int:
    """Run one command line (``sys.argv[1:]`` by default); the exit code."""
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in COMMANDS:
        from .cli import main as full_main

        return full_main(args)
    parser = argparse.ArgumentParser(prog="fresco-bridge")
    add_diagnosis_parsers(parser.add_subparsers(dest="command", required=True))
    parsed = parser.parse_args(args)
    return exit_code(lambda: diagnosis_command(parsed))


if __name__ == "__main__":
    sys.exit(main())
