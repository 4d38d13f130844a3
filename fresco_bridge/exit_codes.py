"""The command line's one error boundary: what a command raised becomes one line on stderr and
an exit code, never a traceback.

Below both ways into the ``fresco-bridge`` commands, the light console entry (``entry.py``:
``diagnose``, ``diagnose-bench``) and the full parser (``cli.py``), so each command line ends
the same way whichever parsed it. Standard library only (and ``progress``, which imports
``rich`` only when it draws): the light entry stays light.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable

from .progress import close_all

__all__ = ["BAD_INPUT_EXIT", "BROKEN_PIPE_EXIT", "FAILURE_EXIT", "INTERRUPTED_EXIT",
           "Interrupted", "exit_code", "reader_gone"]

BAD_INPUT_EXIT = 2
"""The command line, the config or a file named on it is wrong: the user can fix it."""
FAILURE_EXIT = 1
INTERRUPTED_EXIT = 130
"""128 + SIGINT: Ctrl-C."""
BROKEN_PIPE_EXIT = 141
"""128 + SIGPIPE: what a coreutils command returns when its reader went away (``| head``)."""

class Interrupted(KeyboardInterrupt):
    """Ctrl-C (or a stop signal) that a command caught to say what it left behind: its text is
    the one line the user reads after ``interrupted:`` (what stopped, where the run is, what
    to do next); ``code`` the exit code (128 + the signal). A ``KeyboardInterrupt``, so every
    ``finally`` and cleanup on the way out still runs."""

    def __init__(self, text: str, code: int = 130) -> None:
        super().__init__(text)
        self.code = code


def reader_gone() -> int:
    """The reader of stdout went away (``| head``): the user's choice, not a failure, so no
    error line (the command stops at the line it could not print, as coreutils do); stdout goes
    to /dev/null so the interpreter's final flush stays quiet too. The exit code."""
    # no real descriptor (an in-process caller): nothing to redirect
    with contextlib.suppress(AttributeError, OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return BROKEN_PIPE_EXIT


def exit_code(command: Callable[[], int],
              bad_input: tuple[type[Exception], ...] = ()) -> int:
    """Run ``command``; its exit code, or the one of what it raised: ``bad_input`` (the
    caller's errors that mean the user gave something wrong) 2, Ctrl-C 130, a gone reader 141,
    anything else 1 (the traceback at debug level, for ``-v``)."""
    try:
        try:
            return command()
        finally:
            close_all()  # a progress bar still drawing ends its line before any error line
    except bad_input as exc:
        print(f"error: {exc}", file=sys.stderr)
        return BAD_INPUT_EXIT
    except KeyboardInterrupt as exc:
        text = str(exc) or f"{_command()} stopped by Ctrl-C before it finished"
        # on a terminal, after the ^C it echoed: the line starts on a line of its own
        fresh = "\n" if getattr(sys.stderr, "isatty", lambda: False)() else ""
        print(f"{fresh}interrupted: {text}", file=sys.stderr)
        return exc.code if isinstance(exc, Interrupted) else INTERRUPTED_EXIT
    except BrokenPipeError:
        return reader_gone()
    except OSError as exc:  # a port in use, a run directory that cannot be written, …
        _debug_traceback()
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"error: {exc.strerror or exc}{where}", file=sys.stderr)
        return FAILURE_EXIT
    except Exception as exc:
        _debug_traceback()
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return FAILURE_EXIT


def _command() -> str:
    """``fresco-bridge study paper``: the command line's first words, for the generic line."""
    words = [a for a in sys.argv[1:3] if not a.startswith("-")]
    return " ".join(["fresco-bridge", *words])


def _debug_traceback() -> None:
    """The traceback of the error being handled, at debug level (``-v``); ``logging`` is
    imported only here, on the way out, to keep the light entry light."""
    import logging

    logging.getLogger("fresco_bridge").debug("fatal", exc_info=True)
