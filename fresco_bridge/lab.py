"""``fresco-bridge lab``: the docker compose lab topology as local processes, and its integrator.

``docker/compose.yaml`` is the one description of the lab: each service carries an ``x-local``
block (the command to run it on this machine, how to tell it is ready). ``lab up`` reads it,
starts the selected services in ``depends_on`` order, waits for each with a deadline, forwards
their output prefixed with the service name, and stops them in reverse order (SIGTERM, then
SIGKILL after a grace period) on Ctrl-C, SIGTERM, when a one-shot service (the integrator)
finishes, or when a service dies. Children die with this process (``PR_SET_PDEATHSIG``), so
even a killed ``lab up`` leaves no orphans.

The bridge config a compose service mounts names compose hostnames and container ports; for a
local run it is rewritten to 127.0.0.1 and the host ports compose publishes (``localize``).
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import graphlib
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import yaml

__all__ = [
    "LabError",
    "LabService",
    "Topology",
    "dump_toml",
    "interpolate",
    "localize_bridge_config",
    "run_integrator",
    "run_lab",
]

DEFAULT_COMPOSE = Path("docker/compose.yaml")
LOOPBACK = "127.0.0.1"
CONSOLE_SCRIPTS = {"fresco-bridge": "fresco_bridge.cli", "sim-actuator": "sim_actuator.cli"}
"""Our console scripts run as ``python -m`` with this interpreter (same venv, no PATH lookup)."""


class LabError(Exception):
    """The topology cannot be read or started; the message names the service and the reason."""


# -- compose file --------------------------------------------------------------------------------

_VAR = re.compile(r"\$\$|\$\{([A-Za-z_][A-Za-z0-9_]*)(?:(:?[-?])([^}]*))?\}|\$([A-Za-z_]\w*)")


def interpolate(text: str, env: Mapping[str, str], where: str = "") -> str:
    """Compose variable interpolation: ``$VAR``, ``${VAR}``, ``${VAR:-default}``,
    ``${VAR-default}``, ``${VAR:?error}``, ``${VAR?error}`` and ``$$`` (a literal ``$``)."""

    def one(m: re.Match[str]) -> str:
        if m.group(0) == "$$":
            return "$"
        name = m.group(1) or m.group(4)
        op, arg = m.group(2), m.group(3) or ""
        value = env.get(name)
        unset = value is None or (op is not None and op.startswith(":") and value == "")
        if op in (":-", "-") and unset:
            return arg
        if op in (":?", "?") and unset:
            raise LabError(f"{where}: required variable {name} is not set: {arg}")
        return value or ""

    return _VAR.sub(one, text)


def _interpolate_tree(node: Any, env: Mapping[str, str], where: str) -> Any:
    if isinstance(node, str):
        return interpolate(node, env, where)
    if isinstance(node, list):
        return [_interpolate_tree(v, env, where) for v in node]
    if isinstance(node, dict):
        return {k: _interpolate_tree(v, env, f"{where}.{k}") for k, v in node.items()}
    return node


def _address(text: str, where: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise LabError(f"{where}: {text!r} is not host:port")
    return host, int(port)


def _published(spec: Any, where: str) -> tuple[int, int] | None:
    """(container port, host port) of one compose ``ports`` entry; None if not published."""
    if isinstance(spec, dict):
        target, published = spec.get("target"), spec.get("published")
        if target is None or published in (None, ""):
            return None
        return int(target), int(str(published).split("-")[0])
    text = str(spec).split("/")[0]
    parts = text.rsplit(":", 2) if text.count(":") <= 2 else [text]
    if len(parts) < 2 or not all(p.isdigit() for p in parts[-2:]):
        if len(parts) == 1 and parts[0].isdigit():
            return None  # container port only: published on a random host port
        raise LabError(f"{where}: cannot read the port mapping {spec!r}")
    return int(parts[-1]), int(parts[-2])


@dataclass(frozen=True)
class LabService:
    """One compose service as ``lab up`` runs it."""

    name: str
    command: tuple[str, ...]
    depends_on: tuple[str, ...] = ()
    ready: tuple[str, int] | None = None
    ready_line: str | None = None
    oneshot: bool = False
    reuse: bool = False
    config: Path | None = None
    env: Mapping[str, str] = field(default_factory=dict)
    ports: Mapping[int, int] = field(default_factory=dict)
    """Container port -> host port, from compose ``ports``."""
    profiles: tuple[str, ...] = ()


@dataclass(frozen=True)
class Topology:
    """The services of a compose file that have an ``x-local`` block, in start order."""

    path: Path
    services: tuple[LabService, ...]

    @property
    def directory(self) -> Path:
        return self.path.parent

    def service(self, name: str) -> LabService:
        for s in self.services:
            if s.name == name:
                return s
        raise LabError(f"{self.path}: no service {name!r}")

    @classmethod
    def load(cls, path: Path, *, profiles: Sequence[str] = (),
             env: Mapping[str, str] | None = None) -> Topology:
        """Read ``path``; keep the services without profiles and those of ``profiles``."""
        env = dict(os.environ if env is None else env)
        try:
            raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise LabError(f"{path}: cannot read the compose file: {exc.strerror}") from None
        except yaml.YAMLError as exc:
            raise LabError(f"{path}: not valid YAML: {exc}") from None
        services = raw.get("services") if isinstance(raw, dict) else None
        if not isinstance(services, dict) or not services:
            raise LabError(f"{path}: no `services` mapping")
        chosen: dict[str, LabService] = {}
        for name, spec in services.items():
            where = f"{path}: services.{name}"
            if not isinstance(spec, dict):
                raise LabError(f"{where}: not a mapping")
            svc_profiles = tuple(spec.get("profiles") or ())
            if svc_profiles and not set(svc_profiles) & set(profiles):
                continue
            chosen[name] = _service(name, _interpolate_tree(spec, env, where), path, where,
                                    svc_profiles)
        for svc in chosen.values():
            for dep in svc.depends_on:
                if dep not in chosen:
                    raise LabError(f"{path}: service {svc.name} depends on {dep!r}, which is not "
                                   "defined or not in the selected profiles")
        try:
            order = list(graphlib.TopologicalSorter(
                {s.name: s.depends_on for s in chosen.values()}).static_order())
        except graphlib.CycleError as exc:
            raise LabError(f"{path}: depends_on has a cycle: {exc.args[1]}") from None
        return cls(path, tuple(chosen[n] for n in order))


def _service(name: str, spec: dict[str, Any], path: Path, where: str,
             profiles: tuple[str, ...]) -> LabService:
    local = spec.get("x-local")
    if not isinstance(local, dict):
        raise LabError(f"{where}: no `x-local` block: `lab up` does not know how to run it "
                       "locally")
    known = {"command", "ready", "ready_line", "oneshot", "reuse", "config", "env"}
    unknown = set(local) - known
    if unknown:
        raise LabError(f"{where}.x-local: unknown key(s) {sorted(unknown)} (known: "
                       f"{sorted(known)})")
    command = local.get("command")
    if not (isinstance(command, list) and command and all(isinstance(a, str | int | float)
                                                          for a in command)):
        raise LabError(f"{where}.x-local.command: must be a non-empty list of arguments")
    deps = spec.get("depends_on") or ()
    ports: dict[int, int] = {}
    for entry in spec.get("ports") or ():
        mapping = _published(entry, f"{where}.ports")
        if mapping is not None:
            ports[mapping[0]] = mapping[1]
    ready = local.get("ready")
    config = local.get("config")
    return LabService(
        name=name,
        command=tuple(str(a) for a in command),
        depends_on=tuple(deps),
        ready=_address(str(ready), f"{where}.x-local.ready") if ready else None,
        ready_line=str(local["ready_line"]) if local.get("ready_line") else None,
        oneshot=bool(local.get("oneshot", False)),
        reuse=bool(local.get("reuse", False)),
        config=(path.parent / str(config)) if config else None,
        env={str(k): str(v) for k, v in (local.get("env") or {}).items()},
        ports=ports,
        profiles=profiles,
    )


# -- the bridge config, localized ------------------------------------------------------------


def localize_bridge_config(text: str, source: str, topology: Topology, bridge: str,
                           runs: Path) -> str:
    """The bridge config with compose hostnames and container ports made local.

    Controller and MQTT hosts that name a compose service become 127.0.0.1 and the host port
    compose publishes for their container port; every site listens on the host port the bridge
    service publishes; the bridge binds and admits loopback only; runs go below ``runs``.
    """
    try:
        cfg = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LabError(f"{source}: not valid TOML: {exc}") from None
    names = {s.name: s for s in topology.services}
    own = topology.service(bridge)

    def published(svc: LabService, port: int, what: str) -> int:
        if port not in svc.ports:
            raise LabError(f"{source}: {what} uses port {port} of service {svc.name}, which "
                           f"{topology.path} does not publish (ports: {dict(svc.ports)})")
        return svc.ports[port]

    section = cfg.setdefault("bridge", {})
    section["host"] = LOOPBACK
    section["allowed_clients"] = [LOOPBACK]
    section["run_dir"] = str(runs)
    for i, site in enumerate(cfg.get("sites", [])):
        what = f"sites[{i}] ({site.get('name', '?')})"
        if int(site.get("port", 0)) != 0:
            site["port"] = published(own, int(site["port"]), what)
        ctrl = site.get("controller", {})
        host = ctrl.get("host")
        if host in names:
            default = {"modbus": 5020, "mts": 5021}.get(str(ctrl.get("kind")), 0)
            ctrl["port"] = published(names[host], int(ctrl.get("port", default)),
                                     f"{what} controller")
            ctrl["host"] = LOOPBACK
        elif host is not None and host != LOOPBACK:
            raise LabError(f"{source}: {what} controller host {host!r} is neither a service of "
                           f"{topology.path} ({', '.join(names)}) nor {LOOPBACK}")
    tel = cfg.get("telemetry", {})
    mqtt = tel.get("mqtt_host")
    if mqtt in names:
        tel["mqtt_port"] = published(names[mqtt], int(tel.get("mqtt_port", 1883)), "telemetry")
        tel["mqtt_host"] = LOOPBACK
    elif mqtt is not None and mqtt != LOOPBACK:
        raise LabError(f"{source}: telemetry.mqtt_host {mqtt!r} is not a service of "
                       f"{topology.path} ({', '.join(names)})")
    header = (f"# {source}, localized by `fresco-bridge lab up` for {topology.path}: compose "
              "hostnames and container ports -> 127.0.0.1 and published host ports\n")
    return header + dump_toml(cfg)


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else json.dumps(k, ensure_ascii=False)


def _value(v: Any, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON escapes are valid TOML basic-string ones
    if isinstance(v, list):
        return "[" + ", ".join(_value(x, where) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x, where)}" for k, x in v.items()) + " }"
    raise LabError(f"{where}: cannot write a {type(v).__name__} as TOML")


def dump_toml(data: Mapping[str, Any]) -> str:
    """TOML for what :mod:`tomllib` produces from a config (no dates): ``loads(dump(d)) == d``."""
    out: list[str] = []

    def table(d: Mapping[str, Any], path: list[str]) -> None:
        subtables = []
        for k, v in d.items():
            if isinstance(v, dict) or (isinstance(v, list) and v
                                       and all(isinstance(x, dict) for x in v)):
                subtables.append((k, v))
            else:
                out.append(f"{_key(k)} = {_value(v, '.'.join([*path, k]))}")
        for k, v in subtables:
            sub = [*path, k]
            name = ".".join(_key(p) for p in sub)
            if isinstance(v, dict):
                out.append(f"\n[{name}]")
                table(v, sub)
            else:
                for item in v:
                    out.append(f"\n[[{name}]]")
                    table(item, sub)

    table(data, [])
    return "\n".join(out).lstrip("\n") + "\n"


# -- processes -----------------------------------------------------------------------------

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

    def stop(self, grace: float) -> int | None:
        """SIGTERM the service's process group; SIGKILL after ``grace`` seconds."""
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5.0)
        with contextlib.suppress(ProcessLookupError):  # stray grandchildren of the group
            os.killpg(self.proc.pid, signal.SIGKILL)
        self._thread.join(2.0)
        return self.proc.returncode


@dataclass
class LabOptions:
    compose: Path = DEFAULT_COMPOSE
    profiles: tuple[str, ...] = ()
    env: dict[str, str] = field(default_factory=dict)
    runs: Path = Path("runs")
    ready_timeout: float = 30.0
    stop_grace: float = 10.0
    bridge_service: str = "bridge"


def run_lab(opts: LabOptions, out: TextIO = sys.stdout,
            stop: threading.Event | None = None,
            on_ready: Callable[[dict[str, int]], None] | None = None) -> int:
    """Start the topology, supervise it, stop it; returns the exit status for the CLI.

    0: stopped by ``stop`` (Ctrl-C, SIGTERM) or the one-shot services all succeeded; else the
    first failing one-shot's status, or 1 when a long-running service died.
    """
    env = {**os.environ, **opts.env}
    topo = Topology.load(opts.compose, profiles=opts.profiles, env=env)
    stop = stop or threading.Event()
    width = max(len(s.name) for s in topo.services)
    running: list[_Running] = []
    pids: dict[str, int] = {}
    with tempfile.TemporaryDirectory(prefix="fresco-lab-") as tmp:
        try:
            for svc in topo.services:
                if stop.is_set():
                    return 0
                if svc.reuse and svc.ready is not None and _port_open(svc.ready):
                    _say(out, f"{svc.name}: already served on {svc.ready[0]}:{svc.ready[1]}, "
                         "reusing it")
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
            if on_ready is not None:
                on_ready(pids)
            return _supervise(running, stop, out)
        finally:
            for child in reversed(running):
                rc = child.stop(opts.stop_grace)
                _say(out, f"{child.svc.name}: stopped (status {rc})")


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


# -- the integrator service -----------------------------------------------------------------------


def run_integrator(host: str, port: int, *, duration: float, pga: float, seed: int,
                   connect_timeout: float = 30.0, out: TextIO = sys.stdout) -> dict[str, float]:
    """The demo's two-story frame (explicit Newmark) driving the damper site of a running bridge.

    Retries the connection until ``connect_timeout`` (the bridge may still be starting); every
    step then has the link's own receive deadline.
    """
    import numpy as np

    from .integrator import DEMO_DT, demo_integrator, kanai_tajimi
    from .integrator.link import GenericClientLink

    motion = kanai_tajimi(pga, duration=duration, dt=DEMO_DT, seed=seed)
    link = GenericClientLink(host, port, 2, timeout=10.0)
    deadline = time.monotonic() + connect_timeout
    while True:
        try:
            link.connect()
            break
        except OSError as exc:
            if time.monotonic() > deadline:
                raise LabError(f"integrator: bridge {host}:{port} not reachable within "
                               f"{connect_timeout:g} s: {exc}") from None
            time.sleep(0.2)
    forces: list[float] = []

    def damper_force(step: int, t: float, drift: Any) -> list[float]:
        link.set_trial((0.0, float(drift[0])), time=t)
        q = link.force()
        forces.append(q[1])
        return [q[1]]

    integ = demo_integrator(damper_force, motion)
    t0 = time.perf_counter()
    try:
        while not integ.done:
            integ.step()
            link.commit()
    finally:
        link.close()
    wall = time.perf_counter() - t0
    drift = integ.response().drift
    summary = {
        "steps": float(integ.n_steps),
        "ms_per_step": 1000.0 * wall / max(integ.n_steps, 1),
        "peak_story1_drift_mm": float(np.max(np.abs(drift[:, 0]))),
        "peak_damper_force_kN": float(np.max(np.abs(forces))) if forces else 0.0,
    }
    out.write("integrator: " + json.dumps(summary) + "\n")
    out.flush()
    return summary


# -- the CLI subcommand ---------------------------------------------------------------------------


def add_lab_parser(sub: Any) -> None:
    """``fresco-bridge lab up|integrate`` (called by the CLI to register the subcommand)."""
    p_lab = sub.add_parser("lab", help="the docker compose lab topology as local processes")
    lab_sub = p_lab.add_subparsers(dest="lab_command", required=True)
    p_up = lab_sub.add_parser("up", help="start mosquitto, sim-actuator and the bridge (and the "
                              "integrator) from docker/compose.yaml; Ctrl-C stops them")
    p_up.add_argument("--compose", type=Path, default=DEFAULT_COMPOSE,
                      help="compose file (default %(default)s)")
    p_up.add_argument("--with-integrator", action="store_true",
                      help="also run the demo integrator (profile `integrator`); the lab stops "
                      "when it finishes")
    p_up.add_argument("--profile", action="append", default=[], help="extra compose profile")
    p_up.add_argument("--controller", choices=("modbus", "mts"), default=None,
                      help="protocol of the simulated controller (sets LAB_CONTROLLER and "
                      "LAB_BRIDGE_CONFIG; default: the compose defaults, modbus)")
    p_up.add_argument("--runs", type=Path, default=Path("runs"), help="run directory root")
    p_up.add_argument("--ready-timeout", type=float, default=30.0,
                      help="seconds each service may take to be ready (default %(default)s)")
    p_int = lab_sub.add_parser("integrate", help="drive a running bridge's damper site with the "
                               "demo's two-story frame (the compose `integrator` service)")
    p_int.add_argument("--host", default=LOOPBACK)
    p_int.add_argument("--port", type=int, default=8090)
    p_int.add_argument("--duration", type=float, default=10.0, help="record length, s")
    p_int.add_argument("--pga", type=float, default=3.0, help="PGA in m/s² (default 3.0)")
    p_int.add_argument("--seed", type=int, default=1, help="synthetic record seed")
    p_int.add_argument("--connect-timeout", type=float, default=30.0)


def lab_command(args: Any) -> int:
    """Run ``fresco-bridge lab ...``; LabError propagates to the CLI boundary."""
    if args.lab_command == "integrate":
        run_integrator(args.host, args.port, duration=args.duration, pga=args.pga,
                       seed=args.seed, connect_timeout=args.connect_timeout)
        return 0
    env: dict[str, str] = {}
    if args.controller is not None:
        env["LAB_CONTROLLER"] = args.controller
        env["LAB_BRIDGE_CONFIG"] = "lab.toml" if args.controller == "modbus" else "lab-mts.toml"
    profiles = tuple(args.profile) + (("integrator",) if args.with_integrator else ())
    opts = LabOptions(compose=args.compose, profiles=profiles, env=env, runs=args.runs,
                      ready_timeout=args.ready_timeout)
    stop = threading.Event()
    with signals_set(stop):
        return run_lab(opts, stop=stop)


if __name__ == "__main__" and sys.argv[1:2] == ["--guard"]:
    raise SystemExit(guard_main(sys.argv[2:]))
