"""The lab topology as ``docker/compose.yaml`` describes it, read for ``fresco-bridge lab up``.

Compose-style variable interpolation, the services that carry an ``x-local`` block in
``depends_on`` order, and the bridge config rewritten for loopback (``localize_bridge_config``:
compose hostnames and container ports become 127.0.0.1 and the host ports compose publishes).
"""

from __future__ import annotations

import graphlib
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

DEFAULT_COMPOSE = Path("docker/compose.yaml")
LOOPBACK = "127.0.0.1"


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
    optional: bool = False
    """Skipped with a warning when its program is not installed (e.g. the telemetry broker)."""
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
    known = {"command", "ready", "ready_line", "oneshot", "reuse", "optional", "config", "env"}
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
        optional=bool(local.get("optional", False)),
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
