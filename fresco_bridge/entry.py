"""The ``fresco-bridge`` console entry: ``diagnose`` and ``diagnose-bench`` start light.

The diagnosis needs nothing of the daemon, yet ``fresco_bridge.cli`` imports every command's
module (config models, sites, controllers, pydantic): measured, that was 1.3-2.9 s of a
cold ``fresco-bridge diagnose`` on the loaded machine (BENCHMARKS.md, "cold start"). Those two
commands are parsed here with the same ``add_diagnosis_parsers``; every other command line,
``--help`` included, goes to ``cli.main`` unchanged.
"""

from __future__ import annotations

import argparse
import sys

from .diagnosis.cli import COMMANDS, add_diagnosis_parsers, diagnosis_command

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Run one command line (``sys.argv[1:]`` by default); the exit code."""
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in COMMANDS:
        from .cli import main as full_main

        return full_main(args)
    parser = argparse.ArgumentParser(prog="fresco-bridge")
    add_diagnosis_parsers(parser.add_subparsers(dest="command", required=True))
    parsed = parser.parse_args(args)
    try:
        return diagnosis_command(parsed)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # the CLI boundary, as cli.main: one clear line, no traceback
        what = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        where = f" ({exc.filename})" if isinstance(exc, OSError) and exc.filename else ""
        print(f"error: {type(exc).__name__}: {what}{where}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
