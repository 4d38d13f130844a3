"""``lab up``'s process supervision: start in order, wait until ready, stop in reverse order.

Each service runs under a small guard process (``python -m fresco_bridge.lab --guard``) that
dies with ``lab up`` (``PR_SET_PDEATHSIG``) and takes the service with it, so no process
outlives ``lab up``, even when it is killed.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from ..progress import command_name
from .compose import DEFAULT_COMPOSE, LabError, LabService, Topology, localize_bridge_config

CONSOLE_SCRIPTS = {"fresco-bridge": "fresco_bridge.cli", "sim-actuator": "sim_actuator.cli"}
"""Our console scripts run as ``python -m`` with this interpreter (same venv, no PATH lookup)."""

_PR_SET_PDEATHSIG = 1
try:  # resolved in the parent: between fork and exec the child only calls it
    _PRCTL: Any = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # not Linux: no parent-death signal
    _PRCTL = None


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: the child gets SIGTERM when ``lab up`` dies, even by SIGKILL (no orphans)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM))


def _argv(command: Sequence[str]) -> list[str]:
    """The service command behind the guard; our console scripts run with this interpreter."""
    module = CONSOLE_SCRIPTS.get(command[0])
    argv = [sys.executable, "-m", module, *command[1:]] if module else list(command)
    return [sys.executable, "-m", "fresco_bridge.lab", "--guard", str(os.getpid()), "--", *argv]


def guard_main(argv: Sequence[str]) -> int:
    """``python -m fresco_bridge.lab --guard PARENT -- CMD...``: run CMD, die with ``lab up``.

    The parent-death signal is lost when a program changes its credentials (mosquitto started
    as root drops to its own user), so each service runs under this guard: it keeps the signal,
    forwards SIGTERM/SIGINT to the service, escalates to SIGKILL after 10 s, and exits as the
    service did (same status, or the same signal).
    """
    parent, cmd = int(argv[0]), list(argv[2:])
    _die_with_parent()
    try:
        child = subprocess.Popen(cmd)
    except OSError as exc:
        print(f"lab: cannot start {cmd[0]!r}: {exc.strerror} (is it installed and on PATH?)",
              file=sys.stderr, flush=True)
        return 127

    def terminate(*_: object) -> None:
        with contextlib.suppress(ProcessLookupError):
            child.send_signal(signal.SIGTERM)
        def escalate() -> None:
            if child.poll() is None:
                child.kill()

        timer = threading.Timer(10.0, escalate)
        timer.daemon = True
        timer.start()

    signal.signal(signal.SIGTERM, terminate)
    signal.signal(signal.SIGINT, terminate)
    if os.getppid() != parent:  # lab up died before the parent-death signal was armed
        terminate()
    rc = child.wait()
    if rc < 0:
        signal.signal(-rc, signal.SIG_DFL)
        os.kill(os.getpid(), -rc)
    return rc


def _port_open(address: tuple[str, int], timeout: float = 0.5) -> bool:
    try:
        with socket.create_connection(address, timeout=timeout):
            return True
    except OSError:
        return False


class _Running:
    """A started service: its process, a pump thread prefixing its output, the last lines."""

    def __init__(self, svc: LabService, argv: list[str], env: dict[str, str], out: TextIO,
                 width: int) -> None:
        self.svc = svc
        self.tail: collections.deque[str] = collections.deque(maxlen=40)
        self.ready_seen = threading.Event()
        try:
            self.proc = subprocess.Popen(
                argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, env=env, text=True, bufsize=1,
                process_group=0, preexec_fn=_die_with_parent,
            )
        except OSError as exc:
            raise LabError(f"service {svc.name}: cannot start {argv[0]!r}: {exc.strerror}"
                           ) from None
        self._thread = threading.Thread(target=self._pump, args=(out, width),
                                        name=f"lab.{svc.name}", daemon=True)
        self._thread.start()

    def _pump(self, out: TextIO, width: int) -> None:
        assert self.proc.stdout is not None
        prefix = f"{self.svc.name:<{width}} | "
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.tail.append(line)
            if self.svc.ready_line is not None and line.startswith(self.svc.ready_line):
                self.ready_seen.set()
            with contextlib.suppress(ValueError, OSError):
                out.write(prefix + line + "\n")
                out.flush()

    def describe_exit(self) -> str:
        rc = self.proc.returncode
        how = f"signal {-rc}" if rc is not None and rc < 0 else f"status {rc}"
        tail = "\n  ".join(list(self.tail)[-10:]) or "(no output)"
        return f"service {self.svc.name} exited with {how}; last output:\n  {tail}"

    def stop(self, grace: float) -> str:
        """SIGTERM the service's process group; SIGKILL after ``grace`` seconds. How it ended,
        in words: a service ended by our SIGTERM was stopped on purpose, not a failure."""
        how = None
        if self.proc.poll() is None:
            how = "SIGTERM"
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                how = "SIGKILL"
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5.0)
        with contextlib.suppress(ProcessLookupError):  # stray grandchildren of the group
            os.killpg(self.proc.pid, signal.SIGKILL)
        self._thread.join(2.0)
        return _ended(self.svc.name, self.proc.returncode, how, grace)


@dataclass
class LabOptions:
    compose: Path = DEFAULT_COMPOSE
    profiles: tuple[str, ...] = ()
    env: dict[str, str] = field(default_factory=dict)
    runs: Path = Path("runs")
    ready_timeout: float = 30.0
    stop_grace: float = 10.0
    bridge_service: str = "bridge"


def run_lab(opts: LabOptions, out: TextIO | None = None,
            stop: threading.Event | None = None,
            on_ready: Callable[[dict[str, int]], None] | None = None) -> int:
    """Start the topology, supervise it, stop it; returns the exit status for the CLI.

    0: stopped by ``stop`` (Ctrl-C, SIGTERM) or the one-shot services all succeeded; else the
    first failing one-shot's status, or 1 when a long-running service died.
    """
    out = sys.stdout if out is None else out
    env = {**os.environ, **opts.env}
    topo = Topology.load(opts.compose, profiles=opts.profiles, env=env)
    stop = stop or threading.Event()
    width = max(len(s.name) for s in topo.services)
    running: list[_Running] = []
    pids: dict[str, int] = {}
    runs_before = _run_dirs(opts.runs)
    with tempfile.TemporaryDirectory(prefix="fresco-lab-") as tmp:
        try:
            for svc in topo.services:
                if stop.is_set():
                    return 0
                if svc.reuse and svc.ready is not None and _port_open(svc.ready):
                    _say(out, f"{svc.name}: already served on {svc.ready[0]}:{svc.ready[1]}, "
                         "reusing it")
                    continue
                if (svc.optional and svc.command[0] not in CONSOLE_SCRIPTS
                        and shutil.which(svc.command[0], path=env.get("PATH")) is None):
                    _say(out, f"{svc.name}: {svc.command[0]!r} is not installed; skipped (an "
                         "optional service: its clients retry in the background)")
                    continue
                if svc.ready is not None and _port_open(svc.ready):
                    raise LabError(
                        f"service {svc.name}: {svc.ready[0]}:{svc.ready[1]} is already in use "
                        f"by another process; stop it or choose other ports (the variables at "
                        f"the top of {topo.path})")
                argv = _argv([_placeholders(a, topo, svc, Path(tmp), opts) for a in
                              svc.command])
                child = _Running(svc, argv, {**env, **svc.env}, out, width)
                running.append(child)
                pids[svc.name] = child.proc.pid
                if not svc.oneshot:
                    _wait_ready(child, opts.ready_timeout, stop)
                _say(out, f"{svc.name}: started (pid {child.proc.pid})")
            _say(out, "ready: " + " ".join(f"{n}={p}" for n, p in pids.items()))
            if not any(c.svc.oneshot for c in running):
                _say(out, _while_up(running, opts.bridge_service))
            if on_ready is not None:
                on_ready(pids)
            return _supervise(running, stop, out)
        finally:
            for child in reversed(running):
                _say(out, child.stop(opts.stop_grace))
            _next_steps(out, _run_dirs(opts.runs) - runs_before)


def _while_up(running: list[_Running], bridge: str) -> str:
    """What to do with a lab that waits for an integrator: drive the bridge's first site."""
    ports = ""
    for child in running:
        if child.svc.name == bridge and child.svc.ready_line is not None:
            ports = next((ln[len(child.svc.ready_line):].lstrip(": ") for ln in child.tail
                          if ln.startswith(child.svc.ready_line)), "")
    first = ports.split(",")[0].strip()
    site, _, port = first.partition("=")
    cmd = command_name()
    drive = (f"`{cmd} lab integrate --port {port}` drives site {site}"
             if port.isdigit() else f"`{cmd} lab integrate --port PORT` drives a site")
    return f"next: in another terminal, {drive}; Ctrl-C here stops the lab"


def _ended(name: str, rc: int | None, how: str | None, grace: float) -> str:
    """``bridge: stopped by lab up (SIGTERM), exit status 0`` and the like."""
    if how is None:  # it had ended by itself (a one-shot, or a service that died)
        return (f"{name}: had finished (status 0)" if rc == 0 else
                f"{name}: had exited ({_status(rc)})")
    if how == "SIGKILL":
        return f"{name}: killed (SIGKILL: still running {grace:g} s after our SIGTERM)"
    if rc in (0, -signal.SIGTERM, 128 + signal.SIGTERM):
        return f"{name}: stopped by lab up (SIGTERM), as intended"
    return f"{name}: stopped by lab up (SIGTERM); it exited with {_status(rc)}"


def _status(rc: int | None) -> str:
    return f"signal {-rc}" if rc is not None and rc < 0 else f"status {rc}"


def _run_dirs(runs: Path) -> set[Path]:
    """The run directories under ``runs`` (none if it does not exist yet)."""
    with contextlib.suppress(OSError):
        return {p for p in runs.iterdir() if p.is_dir()}
    return set()


def _next_steps(out: TextIO, new_runs: set[Path]) -> None:
    """Where the lab's run record is and what to do with it."""
    for run in sorted(new_runs):
        _say(out, f"run record: {run}")
    if new_runs:
        run = max(new_runs)
        cmd = command_name()
        _say(out, f"next: {cmd} runs show {run}  (then: {cmd} report {run})")


def _say(out: TextIO, text: str) -> None:
    with contextlib.suppress(ValueError, OSError):
        out.write(f"lab: {text}\n")
        out.flush()


def _placeholders(arg: str, topo: Topology, svc: LabService, tmp: Path,
                  opts: LabOptions) -> str:
    if "{config}" in arg:
        if svc.config is None:
            raise LabError(f"service {svc.name}: x-local.command uses {{config}} but x-local has "
                           "no `config`")
        try:
            text = svc.config.read_text(encoding="utf-8")
        except OSError as exc:
            raise LabError(f"service {svc.name}: cannot read {svc.config}: {exc.strerror}"
                           ) from None
        local = tmp / f"{svc.name}.toml"
        local.write_text(localize_bridge_config(text, str(svc.config), topo, svc.name,
                                                opts.runs.resolve()), encoding="utf-8")
        arg = arg.replace("{config}", str(local))
    return arg.replace("{dir}", str(topo.directory.resolve()))


def _wait_ready(child: _Running, timeout: float, stop: threading.Event) -> None:
    svc = child.svc
    deadline = time.monotonic() + timeout
    while True:
        if child.proc.poll() is not None:
            child._thread.join(2.0)
            raise LabError(f"{child.describe_exit()}\n(before it was ready)")
        line_ok = svc.ready_line is None or child.ready_seen.is_set()
        port_ok = svc.ready is None or (line_ok and _port_open(svc.ready, 0.2))
        if line_ok and port_ok:
            return
        if stop.is_set():
            raise LabError(f"service {svc.name}: stopped while waiting for it to be ready")
        if time.monotonic() > deadline:
            what = " and ".join(
                ([f"port {svc.ready[0]}:{svc.ready[1]}"] if svc.ready else [])
                + ([f"the line {svc.ready_line!r}"] if svc.ready_line else []))
            raise LabError(f"service {svc.name}: not ready within {timeout:g} s (waiting for "
                           f"{what}); last output:\n  " + "\n  ".join(list(child.tail)[-10:]))
        stop.wait(0.05)


def _supervise(running: list[_Running], stop: threading.Event, out: TextIO) -> int:
    oneshots = [c for c in running if c.svc.oneshot]
    while not stop.wait(0.1):
        for child in running:
            rc = child.proc.poll()
            if rc is None:
                continue
            if child.svc.oneshot:
                if rc != 0:
                    _say(out, child.describe_exit())
                    return rc if rc > 0 else 1
                if all(c.proc.poll() is not None for c in oneshots):
                    _say(out, "one-shot services finished; stopping the lab")
                    return 0
                continue
            child._thread.join(2.0)
            _say(out, child.describe_exit() + "\nstopping the lab")
            return 1
    return 0


@contextlib.contextmanager
def signals_set(stop: threading.Event) -> Iterator[None]:
    """SIGINT/SIGTERM set ``stop`` (the lab then shuts down in order) while inside."""
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT,
                                                                      signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
