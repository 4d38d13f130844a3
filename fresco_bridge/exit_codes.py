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
           "exit_code", "reader_gone"]

BAD_INPUT_EXIT = 2
"""The command line, the config or a file named on it is wrong: the user can fix it."""
FAILURE_EXIT = 1
INTERRUPTED_EXIT = 130
"""128 + SIGINT: Ctrl-C."""
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
    except KeyboardInterrupt:
        return INTERRUPTED_EXIT
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


def _debug_traceback() -> None:
    """The traceback of the error being handled, at debug level (``-v``); ``logging`` is
    imported only here, on the way out, to keep the light entry light."""
    import logging

    logging.getLogger("fresco_bridge").debug("fatal", exc_info=True)
