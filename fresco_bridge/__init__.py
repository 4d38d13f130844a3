"""fresco-bridge: the lab daemon between an FE integrator and the actuator controller."""

import sys as _sys

from ._compiled import pure_requested as _pure_requested
from ._compiled import use_pure_sources as _use_pure_sources

WORKER_PROCESS_PREFIX = "fresco-worker-"
"""The name of every worker process the bridge spawns (a twin's learner): Ctrl-C, which a
terminal sends to the whole process group, is the parent's to handle (it ends its workers)."""


def _leave_ctrl_c_to_the_parent() -> None:
    """In a worker process, SIGINT ignored from the first import of this package on: a spawned
    child names itself (``multiprocessing.spawn.prepare``) before it re-imports the parent's
    main module, which imports this package first, seconds before the worker's own code runs;
    a Ctrl-C then must not print the child's traceback."""
    mp = _sys.modules.get("multiprocessing")
    if mp is not None and mp.current_process().name.startswith(WORKER_PROCESS_PREFIX):
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)


_leave_ctrl_c_to_the_parent()

if _pure_requested():  # FRESCO_BRIDGE_PURE=1: run the pure sources of the compiled modules
    _use_pure_sources()

__version__ = "0.1.0"
