"""The ``fresco-bridge`` console entry: ``diagnose`` and ``diagnose-bench`` start light.

The diagnosis needs nothing of the daemon, yet ``fresco_bridge.cli`` imports every command's
module (config models, sites, controllers, pydantic): measured, that was 1.3-2.9 s of a
cold ``fresco-bridge diagnose`` on the loaded machine (BENCHMARKS.md, "cold start"). Those two
commands are parsed here with the same ``add_diagnosis_parsers``; every other command line,
``--help`` included, goes to ``cli.main`` unchanged.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

from .diagnosis.cli import COMMANDS, add_diagnosis_parsers, diagnosis_command

__all__ = ["BROKEN_PIPE_EXIT", "main", "reader_gone"]

BROKEN_PIPE_EXIT = 141
"""128 + SIGPIPE: what a coreutils command returns when its reader went away (``| head``)."""


def reader_gone() -> int:
    """The reader of stdout went away (``| head``): the user's choice, not a failure, so no
    error line (the command stops at the line it could not print, as coreutils do); stdout goes
    to /dev/null so the interpreter's final flush stays quiet too. The exit code."""
    # no real descriptor (an in-process caller): nothing to redirect
    with contextlib.suppress(AttributeError, OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return BROKEN_PIPE_EXIT


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
    except BrokenPipeError:
        return reader_gone()
    except Exception as exc:  # the CLI boundary, as cli.main: one clear line, no traceback
        what = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        where = f" ({exc.filename})" if isinstance(exc, OSError) and exc.filename else ""
        print(f"error: {type(exc).__name__}: {what}{where}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
