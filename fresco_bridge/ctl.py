"""The operator interface: one command handler, served on a local control socket and over MQTT.

``OperatorDesk`` turns ``status | pause | resume | abort`` (optionally for one site) into site
transitions; the control socket (a Unix domain socket, JSON lines, mode 0600) and authenticated
MQTT command messages both call it, so the two paths cannot disagree. ``request`` is the
blocking client behind ``fresco-bridge ctl``.

Wire format, one JSON object per line each way::

    → {"command": "pause", "site": "damper", "id": "optional"}
    ← {"ok": true, "command": "pause", "id": ...,
       "results": [{"site": .., "ok": .., "message": ..}], "sites": [<status of every site>]}
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import math
import os
import socket
import stat
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .jsonline import RequestJsonError, decode
from .logs import printable
from .numbers import fmt
from .record.recovery import socket_answers
from .safety import TransitionRefused
from .sites import Site
from .telemetry import OperatorCommand

log = logging.getLogger("fresco_bridge.ctl")

COMMANDS = ("status", "pause", "resume", "abort")
SOCKET_NAME = "control.sock"
POINTER_NAME = "control.path"
"""Written in the run directory when the socket had to live elsewhere (path too long)."""
READ_TIMEOUT = 10.0
"""Deadline (s) for a control client to send its next request line."""
MAX_LINE = 4096
_SUN_PATH_MAX = 107  # bytes usable in sockaddr_un.sun_path on Linux


class ControlError(Exception):
    """A control request that cannot be served: unknown site or command, socket problems."""


class OperatorDesk:
    """The one handler behind every operator path (control socket, MQTT)."""

    def __init__(self, sites: Mapping[str, Site]) -> None:
        self.sites = sites

    def execute(self, command: str, site: str | None = None, *, source: str) -> dict[str, Any]:
        """Run one command for one site (or all when ``site`` is None); never raises for a
        refused transition: each site's result says ``ok`` and why."""
        if command not in COMMANDS:
            raise ControlError(f"unknown command {command!r}; expected one of {list(COMMANDS)}")
        targets = self._targets(site)
        results: list[dict[str, Any]] = []
        if command != "status":
            for s in targets:
                try:
                    message = getattr(s, f"operator_{command}")(source)
                    results.append({"site": s.name, "ok": True, "message": message})
                except TransitionRefused as exc:
                    log.warning("ctl: %s for site %s refused (%s): %s", command, s.name, source,
                                exc)
                    results.append({"site": s.name, "ok": False, "message": str(exc)})
        return {
            "ok": all(r["ok"] for r in results), "command": command, "results": results,
            "sites": [s.status() for s in targets],
        }

    def _targets(self, site: str | None) -> list[Site]:
        if site is None:
            return list(self.sites.values())
        found = self.sites.get(site)
        if found is None:
            raise ControlError(f"no site {site!r}; sites: {', '.join(self.sites)}")
        return [found]

    def handle_mqtt(self, command: OperatorCommand) -> None:
        """``MqttTelemetry``'s command handler: raise so a refusal is logged and counted."""
        source = f"mqtt{' id ' + command.request_id if command.request_id else ''}"
        result = self.execute(command.command, command.site, source=source)
        if not result["ok"]:
            raise ControlError("; ".join(r["message"] for r in result["results"] if not r["ok"]))


# -- the server ----------------------------------------------------------------------------------
def socket_path_for(run_dir: Path) -> Path:
    """``<run_dir>/control.sock``, or a short path under the temp dir when that is too long
    for AF_UNIX (then ``<run_dir>/control.path`` names it)."""
    path = run_dir / SOCKET_NAME
    if len(os.fsencode(path.absolute())) <= _SUN_PATH_MAX:
        return path
    digest = hashlib.sha256(os.fsencode(run_dir.absolute())).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / _private_dir_name() / f"{digest}.sock"


def _private_dir_name() -> str:
    return f"fresco-bridge-{os.getuid()}"


def _check_private(directory: Path) -> None:
    """The shared-temp fallback directory must be ours and closed to others (no swapped
    sockets from another user)."""
    st = directory.lstat()
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o077:
        raise ControlError(f"{directory} must be a directory owned by uid {os.getuid()} with "
                           f"mode 0700 (found uid {st.st_uid}, mode {stat.S_IMODE(st.st_mode):o}); "
                           "remove it or set [bridge] control_socket")


class ControlServer:
    """The daemon's control socket: JSON lines, a read deadline, one task per client."""

    def __init__(self, desk: OperatorDesk, path: Path, *, pointer_dir: Path | None = None) -> None:
        self.desk = desk
        self.path = path
        self._pointer = None if pointer_dir is None or path.parent == pointer_dir else \
            pointer_dir / POINTER_NAME
        self._server: asyncio.AbstractServer | None = None
        self._clients: set[asyncio.Task[None]] = set()

    async def start(self) -> None:
        path = self.path
        if len(os.fsencode(path.absolute())) > _SUN_PATH_MAX:
            raise ControlError(f"control socket path {path} is longer than the {_SUN_PATH_MAX} "
                               "bytes AF_UNIX allows; set [bridge] control_socket to a shorter one")
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        if path.parent.name == _private_dir_name():
            _check_private(path.parent)
        if path.exists() or path.is_symlink():
            if socket_answers(path):
                raise ControlError(f"control socket {path} is served by another running bridge")
            path.unlink()  # a stale socket from a bridge that did not shut down cleanly
        self._server = await asyncio.start_unix_server(self._client, path=str(path),
                                                       limit=MAX_LINE)
        os.chmod(path, 0o600)  # only this user may move the specimen
        if self._pointer is not None:
            self._pointer.write_text(f"{path}\n", encoding="utf-8")
        log.info("control socket: %s (fresco-bridge ctl status --socket %s)", path, path)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            for task in list(self._clients):
                task.cancel()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(2.0):
                    await self._server.wait_closed()
            self._server = None
        with contextlib.suppress(OSError):
            self.path.unlink()
        if self._pointer is not None:
            with contextlib.suppress(OSError):
                self._pointer.unlink()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._clients.add(task)
        try:
            while True:
                try:
                    async with asyncio.timeout(READ_TIMEOUT):
                        line = await reader.readline()
                except TimeoutError:
                    log.info("ctl: client sent nothing for %g s; closing", READ_TIMEOUT)
                    return
                except ValueError:  # longer than MAX_LINE
                    await _reply(writer, {"ok": False, "error": f"request longer than "
                                                               f"{MAX_LINE} bytes"})
                    return
                if not line:
                    return
                try:
                    body = self.answer(line)
                except Exception as exc:  # a bug of the bridge: logged, and still answered
                    log.exception("ctl: internal error answering a request")
                    body = {"ok": False, "error": f"internal error: {type(exc).__name__}"}
                await _reply(writer, body)
        except (ConnectionError, TimeoutError, asyncio.CancelledError):
            pass  # the client went away, stopped reading its answers, or the bridge stops
        finally:
            self._clients.discard(task)
            writer.close()

    def answer(self, line: bytes) -> dict[str, Any]:
        """One request line → one response object (errors are responses, never exceptions)."""
        try:
            body = decode(line)
        except RequestJsonError as exc:
            log.warning("ctl: request refused: %s", exc)
            return {"ok": False, "error": f"request is not a JSON line: {exc}"}
        if not isinstance(body, dict):
            return {"ok": False, "error": "request must be a JSON object"}
        unknown = sorted(set(body) - {"command", "site", "id"})
        command, site, rid = body.get("command"), body.get("site"), body.get("id")
        if unknown:
            return {"ok": False, "id": rid, "error": f"unknown key(s) {unknown}"}
        if not isinstance(command, str) or not (site is None or isinstance(site, str)):
            return {"ok": False, "id": rid, "error": "command must be a string and site a "
                                                     "string or null"}
        try:
            result = self.desk.execute(command, site, source="control socket")
        except ControlError as exc:
            return {"ok": False, "id": rid, "error": str(exc)}
        return {**result, "id": rid}


async def _reply(writer: asyncio.StreamWriter, body: dict[str, Any]) -> None:
    writer.write(json.dumps(body).encode() + b"\n")
    async with asyncio.timeout(READ_TIMEOUT):
        await writer.drain()


# -- the client ----------------------------------------------------------------------------------
def find_socket(socket_path: Path | None, run_dir: Path | None, runs_root: Path) -> Path:
    """The socket to talk to: explicit, in a run directory, or the newest live one under
    ``runs_root``."""
    if socket_path is not None:
        return socket_path
    if run_dir is not None:
        for path in (run_dir / SOCKET_NAME, _pointed(run_dir / POINTER_NAME)):
            if path is not None and path.exists():
                return path
    else:  # the newest run directory whose bridge answers (skips stale sockets)
        for d in sorted((d for d in runs_root.glob("*") if d.is_dir()), key=_mtime,
                        reverse=True):
            for path in (d / SOCKET_NAME, _pointed(d / POINTER_NAME)):
                if path is not None and path.exists() and socket_answers(path):
                    return path
    where = f"run directory {run_dir}" if run_dir is not None else f"{runs_root}/*"
    raise ControlError(f"no control socket in {where} (is the bridge running? pass --socket "
                       "PATH or --run-dir DIR)")


def _mtime(p: Path) -> float:
    try:
        return p.stat().st_mtime
    except OSError:
        return 0.0


def _pointed(pointer: Path) -> Path | None:
    try:
        return Path(pointer.read_text(encoding="utf-8").strip())
    except OSError:
        return None


def request(path: Path, command: str, site: str | None = None, *,
            timeout: float = 5.0) -> dict[str, Any]:
    """Send one request and wait (with a deadline) for its response line."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        try:
            s.connect(str(path))
            s.sendall(json.dumps({"command": command, "site": site}).encode() + b"\n")
            data = b""
            while not data.endswith(b"\n"):
                chunk = s.recv(65536)
                if not chunk:
                    break
                data += chunk
        except TimeoutError:
            raise ControlError(f"control socket {path}: no answer within {timeout:g} s") from None
        except ConnectionRefusedError:
            raise ControlError(f"control socket {path}: no bridge listens on it (a bridge that "
                               "stopped without removing it?)") from None
        except OSError as exc:
            raise ControlError(f"control socket {path}: {exc.strerror or exc}") from None
    if not data:
        raise ControlError(f"control socket {path} closed without an answer")
    try:
        answer = decode(data, max_depth=64)
    except RequestJsonError as exc:
        raise ControlError(f"control socket {path} answered something that is not a bridge's "
                           f"JSON line: {exc}") from None
    if not isinstance(answer, dict):
        raise ControlError(f"control socket {path} answered a JSON {type(answer).__name__}, "
                           "not a bridge's object")
    return answer


def format_answer(answer: dict[str, Any]) -> str:
    """Human-readable lines for ``fresco-bridge ctl``; whatever the sites' texts quote (a
    client's name, a reason) cannot act on the operator's terminal."""
    return _answer_lines(_printable(answer))


def _printable(value: Any) -> Any:
    """``value`` with every string in it ``printable``."""
    if isinstance(value, str):
        return printable(value)
    if isinstance(value, dict):
        return {k: _printable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_printable(v) for v in value]
    return value


def _answer_lines(answer: dict[str, Any]) -> str:
    if "error" in answer:
        return f"error: {answer['error']}"
    lines = [f"{r['site']}: {'ok' if r['ok'] else 'REFUSED'}: {r['message']}"
             for r in answer.get("results", [])]
    for st in answer.get("sites", []):
        lines.append(
            f"{st['site']}: {st['state']}" + (f" ({st['reason']})" if st["reason"] else "")
            + f"  session {st['session']}" + (f" client {st['peer']}" if st["peer"] else "")
            + f"  step {st['step']}  time {st['time']:g}")
        lines.append(f"    ctrl {_vec(st['ctrl'])} mm (target {_vec(st['target'])})  daq disp "
                     f"{_vec(st['daq_disp'])} mm force {_vec(st['daq_force'])} kN")
        if st.get("kind") == "updatable":
            lines.append(f"    updatable: learns from {st['source']}  updater {st['updater']}  "
                         f"causality {st['causality']}  learner {st['learner']}"
                         + (f" ({st['learner_reason']})" if st["learner_reason"] else "")
                         + f"  trained through source step {st['steps_trained']} "
                         f"(source at {st['source_step']})  not trained {st['not_trained']}  "
                         f"losses {st['learner_losses']}")
        if st.get("record"):
            lines.append(f"    run record not writable: {st['record']} (new clients refused "
                         "until it is)")
        counts = ", ".join(f"{k} {v}" for k, v in sorted(st["limit_events"].items())) or "none"
        lines.append(f"    holds {st['holds']}  limit events: {counts}")
        if st.get("correction"):
            lines.append("    " + _correction_line(st["correction"]))
        for lim in st["limits"]:
            lines.append("    limits " + _limits_line(lim))
        if not st["limits"]:
            lines.append("    no limits configured")
        if st.get("recovering_for") is not None:
            lines.append(f"    command {_vec(st['pending'])} waits for the lost controller to "
                         f"answer again ({st['recovering_for']:.1f} s so far)")
        elif st["pending"] is not None:
            lines.append(f"    command {_vec(st['pending'])} waiting for an operator for "
                         f"{st['paused_for'] or 0.0:.1f} s")
    return "\n".join(lines)


def _correction_line(c: dict[str, Any]) -> str:
    """``correction: last trial 1 correction(s), residual 0.002 mm (converged); …``."""
    last = ("no trial corrected yet" if c["corrections"] is None else
            f"last trial {c['corrections']} correction(s), residual {c['residual']:.4g} mm "
            f"({c['outcome']})")
    return (f"correction: {last}; {c['trials']} trial(s), at most {c['most']} of "
            f"{c['max_iterations']}, {c['warnings']} above half, {c['unconverged']} not "
            "converged")


def _limits_line(lim: dict[str, Any]) -> str:
    """``actuator 1: disp [-40, 40] mm, increment 2 mm, velocity 20 mm/s, ... policy reject``."""
    parts = [f"actuator {lim.get('actuator', 1)}:"]
    if "disp_min" in lim or "disp_max" in lim:
        parts.append(f"disp [{lim.get('disp_min', '-inf')}, {lim.get('disp_max', 'inf')}] mm,")
    for key, label, unit in (("disp_increment", "increment", "mm"),
                             ("velocity", "velocity", "mm/s"), ("step_time", "step_time", "s"),
                             ("max_substeps", "max_substeps", "")):
        if lim.get(key):
            parts.append(f"{label} {lim[key]}{' ' + unit if unit else ''},")
    if "force_min" in lim or "force_max" in lim:
        parts.append(f"force [{lim.get('force_min', '-inf')}, {lim.get('force_max', 'inf')}] "
                     "kN,")
    parts.append(f"policy {lim.get('policy', 'reject')}")
    return " ".join(parts)


def _vec(values: list[float]) -> str:
    return "[" + ", ".join(fmt(v) for v in values) + "]"


# -- the CLI -------------------------------------------------------------------------------------
def add_ctl_parser(sub: Any) -> None:
    """``fresco-bridge ctl status|pause|resume|abort [--site S] [--socket P | --run-dir D]``."""
    p = sub.add_parser("ctl", help="operator control of a running bridge (status, pause, "
                                   "resume, abort)")
    p.add_argument("action", metavar="{" + ",".join(COMMANDS) + "}",
                   help="status (read only), pause, resume or abort")  # checked in ctl_command
    p.add_argument("--site", default=None, help="one site (default: every site)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--socket", type=Path, default=None, help="control socket path")
    where.add_argument("--run-dir", type=Path, default=None,
                       help="run directory of the bridge (its control.sock)")
    p.add_argument("--runs", type=Path, default=Path("runs"),
                   help="run root searched for the newest live bridge (default: runs)")
    p.add_argument("--json", action="store_true", help="print the raw JSON answer")
    p.add_argument("--timeout", default="5", help=f"answer deadline in s (0 < s <= "
                                                  f"{MAX_TIMEOUT:g}; default 5)")


MAX_TIMEOUT = 3600.0
"""The longest answer deadline ``ctl`` accepts (s): the bridge answers in milliseconds."""


def ctl_command(args: Any) -> int:
    """0: done; 1: refused by a site (or an error answer). Raises ControlError (no bridge, a
    bad argument: one line, exit code 2)."""
    if args.action not in COMMANDS:
        raise ControlError(f"ctl {printable(str(args.action))}: not an action; expected one of "
                           f"{', '.join(COMMANDS)}")
    timeout = _timeout(args.timeout)
    _check_site(args.site)
    socket_path = _checked_socket(args.socket)
    run_dir = _checked_dir(args.run_dir, "--run-dir")
    if socket_path is None and run_dir is None:
        _checked_dir(args.runs, "--runs")
    path = find_socket(socket_path, run_dir, args.runs)
    answer = request(path, args.action, args.site, timeout=timeout)
    print(json.dumps(answer, indent=2, ensure_ascii=False) if args.json
          else format_answer(answer))
    return 0 if answer.get("ok") else 1


def _timeout(text: object) -> float:
    """``--timeout``: a finite number of seconds in (0, ``MAX_TIMEOUT``]."""
    try:
        value = float(str(text))
    except ValueError:
        raise ControlError(f"--timeout {printable(str(text))}: not a number of seconds"
                           ) from None
    if not math.isfinite(value) or not 0.0 < value <= MAX_TIMEOUT:
        raise ControlError(f"--timeout {printable(str(text))}: must be a finite number of "
                           "seconds above 0 and "
                           f"at most {MAX_TIMEOUT:g}")
    return value


def _check_site(site: str | None) -> None:
    """``--site``: a name a bridge can have (non-empty, printable)."""
    if site is not None and (not site.strip() or printable(site) != site):
        raise ControlError(f"--site {printable(site)}: not a site name (empty or with control "
                           "characters)")


def _checked_socket(path: Path | None) -> Path | None:
    """``--socket``: an existing Unix socket (a file that is not one is named as such, not
    reported as a refused connection)."""
    if path is None:
        return None
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        raise ControlError(f"--socket {printable(str(path))}: {exc.strerror or exc}") from None
    if not stat.S_ISSOCK(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "a regular file" if \
            stat.S_ISREG(mode) else "a device or a pipe"
        raise ControlError(f"--socket {printable(str(path))}: is {kind}, not a socket (a "
                           f"bridge's control socket is {SOCKET_NAME} in its run directory)")
    return path


def _checked_dir(path: Path | None, option: str) -> Path | None:
    """``--run-dir`` / ``--runs``: an existing directory."""
    if path is not None and not path.is_dir():
        what = "does not exist" if not path.exists() else "is not a directory"
        raise ControlError(f"{option} {printable(str(path))}: {what}")
    return path
