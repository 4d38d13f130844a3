"""A real ``fresco-bridge serve`` process, for the tests and benchmarks that must kill, interrupt
or resume one (an in-process ``RunningBridge`` cannot be ``kill -9``-ed): started from this
checkout's sources, its ready line read within a deadline, its ports. Also the lab most of them
serve, a sim bilinear source with its updatable twin, and the lockstep client that drives both.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from fresco_bridge.integrator.link import GenericClientLink
from protocol import Action
from tests.support.paths import REPO

__all__ = ["READY", "drive_pair", "lockstep", "pair", "source_and_twin", "start_cli", "started",
           "workers_of"]

READY = re.compile(r"fresco-bridge ready: (.*)")
"""The line ``serve`` prints once every site listens: ``site=port, …``."""


def source_and_twin(path: Path, runs: Path, name: str, *, updater: str = "online_ukf",
                    fy: float = 5.0, source: str = "", twin: str = "") -> Path:
    """``path``: a lab with ``damper`` (sim bilinear, k0 = 20 kN/mm, ``fy`` kN, 5 % hardening)
    and ``twin1`` (its ``updater`` twin), recording into ``runs`` as ``name``; ``source`` and
    ``twin`` are more lines of either table."""
    path.write_text(textwrap.dedent(f"""
        [bridge]
        run_dir = "{runs}"
        run_name = "{name}"
        [[sites]]
        name = "damper"
        port = 0
        [sites.controller]
        model = "bilinear"
        params = {{ k0 = 20.0, fy = {fy}, alpha = 0.05 }}
        """) + source + textwrap.dedent(f"""
        [[sites]]
        name = "twin1"
        port = 0
        kind = "updatable"
        learns_from = "damper"
        updater = "{updater}"
        """) + twin)
    return path


def start_cli(cwd: Path, *args: str, stderr: Path | None = None,
              new_session: bool = False) -> subprocess.Popen[str]:
    """``fresco-bridge ARGS`` in ``cwd`` (stdout piped, stderr to ``stderr`` or a fresh
    ``cwd/serve-*.log``); ``new_session``: its own process group, as a shell's job (then
    ``os.killpg`` is the terminal's Ctrl-C)."""
    err = stderr if stderr is not None else cwd / f"serve-{time.monotonic_ns()}.log"
    return subprocess.Popen([sys.executable, "-m", "fresco_bridge.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=err.open("w"), text=True,
                            start_new_session=new_session,
                            env={**os.environ, "PYTHONPATH": str(REPO)})


def started(proc: subprocess.Popen[str], *, deadline: float = 60.0,
            log: Path | None = None) -> tuple[tuple[int, ...], float]:
    """The ports of ``proc``'s ready line, in its order, and the seconds until it came;
    RuntimeError (with ``log``'s end) if it did not come within ``deadline`` s (the process is
    killed then)."""
    assert proc.stdout is not None
    start = time.perf_counter()
    end = time.monotonic() + deadline
    found = None
    while time.monotonic() < end and found is None:
        found = READY.search(proc.stdout.readline())
        if found is None and proc.poll() is not None:
            break
    if found is None:
        proc.kill()
        proc.wait(10)
        tail = "" if log is None else "\n" + "".join(log.read_text().splitlines(True)[-15:])
        raise RuntimeError(f"the bridge did not print its ready line within {deadline:g} s"
                           + tail)
    ports = tuple(int(item.split("=")[1]) for item in found.group(1).split(", "))
    return ports, time.perf_counter() - start


@contextmanager
def pair(ports: tuple[int, ...]) -> Iterator[tuple[GenericClientLink, GenericClientLink]]:
    """Clients of the source (``ports[0]``) and its twin (``ports[1]``), closed after."""
    with GenericClientLink("127.0.0.1", ports[0], 1, data_size=1) as source, \
            GenericClientLink("127.0.0.1", ports[1], 1, data_size=1) as twin:
        yield source, twin


def lockstep(source: GenericClientLink, twin: GenericClientLink, start: int, n: int, *,
             trials: tuple[float, ...] = (1.0,)) -> None:
    """Steps ``start`` … ``start + n - 1`` of the source (d = 1.5 sin(i/4) mm) and its twin
    (0.8 d) in lockstep, each step's ``trials`` (fractions of d, the last one committed:
    Newton's iterations)."""
    for i in range(start, start + n):
        d = 1.5 * math.sin(i / 4.0)
        for fraction in trials:
            trial = fraction * d
            source.set_trial((trial,), time=0.01 * i)
            source.force()
            twin.set_trial((0.8 * trial,), time=0.01 * i)
            twin.force()
        source.commit()
        twin.commit()


def drive_pair(ports: tuple[int, ...], start: int, n: int, *,
               trials: tuple[float, ...] = (1.0,)) -> None:
    """``lockstep`` over fresh clients, then a request the bridge answers after the last
    commit (so the steps are recorded when this returns)."""
    with pair(ports) as (source, twin):
        lockstep(source, twin, start, n, trials=trials)
        twin.request(Action.GET_DISP)


def workers_of(pid: int) -> set[int]:
    """The learner workers among ``pid``'s children (not multiprocessing's resource tracker)."""
    found: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        found |= {int(p) for p in (task / "children").read_text().split()}
    return {p for p in found
            if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()}
