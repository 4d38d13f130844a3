"""MQTT telemetry: a side tap that can never slow the step loop down.

The step loop only appends to bounded in-memory queues (``publish_*`` are plain functions:
no await, no I/O, no exception). A background task, ``run()``, owns the broker connection:
it connects, drains the queues in order (status first, then events, then steps), and on any
MQTT or socket error reconnects with jittered exponential backoff, because aiomqtt 2.x has
no automatic reconnect. Every wait on the broker has a deadline (``timeout``). When the
broker is slow or gone the queues fill and new messages are dropped and counted (oldest
kept, so what arrives is an in-order prefix); retained site status is coalesced per site
and republished after each reconnect, so it is never lost, only superseded.

Operator commands are off unless ``accept_commands=True``, which also requires broker
credentials (user/password or a TLS context) and a shared ``command_token``; see README.md
for the threat model.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import math
import ssl
import time
from collections import deque
from collections.abc import AsyncIterator
from typing import Any, cast

import aiomqtt

from fresco_bridge.backoff import Backoff
from fresco_bridge.jsonline import RequestJsonError, decode
from fresco_bridge.telemetry.base import (
    COMMANDS,
    CommandHandler,
    CommandName,
    NullTelemetry,
    OperatorCommand,
    Telemetry,
    TelemetryConfigError,
    TelemetryStats,
)
from fresco_bridge.telemetry.schema import (
    SCHEMA_VERSION,
    SiteEvent,
    SiteStatus,
    StepSample,
    TelemetrySchemaError,
    check_site_name,
)

__all__ = [  # the shared types are re-exported: importers of this module keep working
    "COMMANDS",
    "CommandHandler",
    "CommandName",
    "MqttTelemetry",
    "NullTelemetry",
    "OperatorCommand",
    "Telemetry",
    "TelemetryConfigError",
    "TelemetryStats",
]

log = logging.getLogger("fresco_bridge.telemetry")
_paho_log = logging.getLogger("paho.fresco_bridge")  # a library's: WARNING up, one line (logs.py)

MAX_COMMAND_BYTES = 1024
MIN_TOKEN_LENGTH = 16
BRIDGE_TOPIC = "_bridge/status"
_LINGER = 0.02  # s the drain waits after waking, so a fast run's steps go out in bursts
_BURST = 10  # publishes started together at most (aiomqtt warns past 10 pending)


def _reraise_lost_cancel() -> None:
    """Raise the cancel that Python 3.11's ``asyncio.wait_for`` swallowed, if any.

    aiomqtt waits with ``wait_for``; on 3.11, when the awaited reply and a ``cancel()`` land in
    the same loop turn, it returns the reply and drops the cancellation (fixed in 3.12). The
    request stays counted in ``Task.cancelling()``, so the loop can still honour it here instead
    of running on forever (a CI run once hung 300 s on exactly this).
    """
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError


def _utf8(value: object) -> bytes | None:
    """``value``'s UTF-8 bytes, or None if it is not a string UTF-8 can encode.

    JSON's ``\\ud800`` escapes decode to lone surrogates, which ``str.encode`` refuses.
    """
    if not isinstance(value, str):
        return None
    try:
        return value.encode()
    except UnicodeEncodeError:
        return None


class _RateLimitedLog:
    """At most ``burst`` lines per ``period`` seconds; the rest are counted and summarised."""

    def __init__(self, burst: int = 10, period: float = 10.0) -> None:
        self._burst, self._period = burst, period
        self._window_start = -period
        self._lines = 0
        self._suppressed = 0

    def warning(self, msg: str, *args: object) -> None:
        now = time.monotonic()
        if now - self._window_start >= self._period:
            if self._suppressed:
                log.warning("telemetry: %d similar log line(s) suppressed", self._suppressed)
            self._window_start, self._lines, self._suppressed = now, 0, 0
        if self._lines < self._burst:
            self._lines += 1
            log.warning(msg, *args)
        else:
            self._suppressed += 1


class MqttTelemetry:
    """Publishes per-step samples, retained site status and events to an MQTT broker.

    Topics (``prefix`` default ``fresco``): ``<prefix>/<site>/step``, ``<prefix>/<site>/status``
    (retained), ``<prefix>/<site>/event``, ``<prefix>/<site>/cmd`` (inbound, opt-in) and
    ``<prefix>/_bridge/status`` (retained, with a last will saying the bridge went offline).
    """

    def __init__(
        self,
        *,
        host: str,
        port: int,
        prefix: str = "fresco",
        qos: int = 0,
        queue_size: int = 10000,
        compact: bool = False,
        username: str | None = None,
        password: str | None = None,
        tls: ssl.SSLContext | None = None,
        client_id: str | None = None,
        accept_commands: bool = False,
        command_handler: CommandHandler | None = None,
        command_token: str | None = None,
        timeout: float = 5.0,
        keepalive: int = 10,
        reconnect_min: float = 0.5,
        reconnect_max: float = 30.0,
    ) -> None:
        self._check_config(host, port, prefix, qos, queue_size, timeout, keepalive,
                           reconnect_min, reconnect_max)
        if accept_commands:
            self._check_command_config(username, password, tls, command_handler, command_token)
        elif command_handler is not None or command_token is not None:
            log.info("telemetry: command_handler/token given but accept_commands is False: "
                     "operator commands over MQTT stay disabled")
        self.host, self.port, self.prefix, self.qos = host, port, prefix, qos
        self.compact = compact
        self.accept_commands = accept_commands
        self._username, self._password, self._tls, self._client_id = (
            username, password, tls, client_id)
        self._handler = command_handler
        self._token = (command_token or "").encode()
        self._timeout, self._keepalive = timeout, keepalive
        self._backoff = Backoff(reconnect_min, reconnect_max)
        self._capacity = queue_size
        self._event_capacity = min(queue_size, 1024)
        self._steps: deque[StepSample] = deque()
        self._sending = 0  # messages of the burst being published
        self._events: deque[SiteEvent] = deque()
        self._pending_status: dict[str, SiteStatus] = {}
        self._last_status: dict[str, SiteStatus] = {}
        self._topics: dict[str, str | None] = {}
        self._wake = asyncio.Event()
        self._stopping = False
        self._running = False
        self._stop_requested = asyncio.Event()
        self._published = 0
        self._dropped = 0
        self._reconnects = 0
        self._failures = 0
        self._connections = 0
        self._connected = False
        self._accepted = 0
        self._rejected = 0
        self._drops_reported = 0
        self._drops_reported_at = 0.0
        self._reject_log = _RateLimitedLog()

    # -- configuration checks -------------------------------------------------------------

    @staticmethod
    def _check_config(host: str, port: int, prefix: str, qos: int, queue_size: int,
                      timeout: float, keepalive: int, rmin: float, rmax: float) -> None:
        problems = []
        if not host:
            problems.append("host is empty")
        if not 0 < port < 65536:
            problems.append(f"port {port} is not in 1..65535")
        levels = prefix.split("/")
        if not prefix or any(not lv or set(lv) & set("+#") for lv in levels) or prefix[0] == "$":
            problems.append(f"prefix {prefix!r} must be non-empty topic levels without '+', '#', "
                            "empty levels or a leading '$'")
        if qos not in (0, 1, 2):
            problems.append(f"qos {qos} is not 0, 1 or 2")
        if queue_size < 1:
            problems.append(f"queue_size {queue_size} must be >= 1")
        if not timeout > 0:
            problems.append(f"timeout {timeout} must be > 0 s")
        if keepalive < 1:
            problems.append(f"keepalive {keepalive} must be >= 1 s")
        if not 0 < rmin <= rmax:
            problems.append(f"reconnect backoff needs 0 < reconnect_min <= reconnect_max, "
                            f"got {rmin} and {rmax}")
        if problems:
            raise TelemetryConfigError("MQTT telemetry: " + "; ".join(problems))

    @staticmethod
    def _check_command_config(username: str | None, password: str | None,
                              tls: ssl.SSLContext | None, handler: CommandHandler | None,
                              token: str | None) -> None:
        problems = []
        if not ((username and password) or tls is not None):
            problems.append("broker credentials are required (username and password, or a TLS "
                            "context with a client certificate)")
        if handler is None:
            problems.append("command_handler is required")
        if token is None or len(token) < MIN_TOKEN_LENGTH:
            problems.append(f"command_token of at least {MIN_TOKEN_LENGTH} characters is required")
        if problems:
            raise TelemetryConfigError(
                "accept_commands=True is refused: " + "; ".join(problems)
                + " (anyone able to publish on the command topic could move an actuator)")
        if tls is None:
            log.warning("telemetry: operator commands accepted without TLS: the command token "
                        "and broker password travel in clear text")

    # -- producer side: called from the step loop, never blocks, never raises -------------

    def publish_step(self, sample: StepSample) -> None:
        """Queue a step sample; if the queue is full the sample is dropped and counted."""
        try:
            if len(self._steps) >= self._capacity:
                self._dropped += 1
                return
            self._steps.append(sample)
            self._wake.set()
        except Exception:  # pragma: no cover - a side tap must not hurt the step loop
            self._dropped += 1

    def publish_status(self, status: SiteStatus) -> None:
        """Queue a retained status; a newer status for the same site supersedes a pending one."""
        try:
            self._pending_status[status.site] = status
            self._last_status[status.site] = status
            self._wake.set()
        except Exception:  # pragma: no cover
            self._dropped += 1

    def publish_event(self, event: SiteEvent) -> None:
        """Queue an event (own bounded queue, drained before steps so a backlog cannot hide it)."""
        try:
            if len(self._events) >= self._event_capacity:
                self._dropped += 1
                return
            self._events.append(event)
            self._wake.set()
        except Exception:  # pragma: no cover
            self._dropped += 1

    def stop(self) -> None:
        """Ask ``run`` to publish what is queued, mark the bridge offline and return."""
        self._stopping = True
        self._stop_requested.set()
        self._wake.set()

    @property
    def stats(self) -> TelemetryStats:
        return TelemetryStats(
            published=self._published, dropped=self._dropped, reconnects=self._reconnects,
            connected=self._connected,
            queued=len(self._steps) + len(self._events) + len(self._pending_status)
            + self._sending,
            failures=self._failures,
            commands_accepted=self._accepted, commands_rejected=self._rejected,
        )

    # -- the background task ----------------------------------------------------------------

    async def run(self) -> None:
        """Connect, publish, reconnect on failure; returns after ``stop()`` once drained.

        Cancel it to stop at once (the bridge is still marked offline, within 1 s). MQTT and
        socket errors never escape: they trigger a reconnect after a jittered backoff,
        min(reconnect_max, reconnect_min·2^n)·U(0.5, 1). One ``run`` per instance.
        """
        if self._running:
            raise RuntimeError("MqttTelemetry.run() is already running (one task per instance)")
        self._running = True
        attempt = 0
        while True:
            if self._stopping and attempt > 0:
                self._drop_backlog("bridge stopping while the broker is unreachable")
                return
            try:
                async with self._connection() as client:
                    self._on_connected()
                    attempt = 0
                    try:
                        await self._session(client)
                    except asyncio.CancelledError:
                        with contextlib.suppress(Exception):
                            await self._publish_bridge_online(client, online=False, timeout=1.0)
                        raise
                    await self._publish_bridge_online(client, online=False)
                    return
            except (aiomqtt.MqttError, OSError) as exc:
                reason = f"{type(exc).__name__}: {exc}"
            except Exception as exc:  # a bug here must not take the daemon down
                log.exception("telemetry: unexpected error, reconnecting")
                reason = f"{type(exc).__name__}: {exc}"
            finally:
                self._connected = False
            self._failures += 1
            attempt += 1
            delay = self._backoff.failed()
            log.warning("telemetry: MQTT %s:%d unavailable (%s); retry %d in %.2f s",
                        self.host, self.port, reason, attempt, delay)
            self._report_drops(force=True)
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):  # stop() cuts the backoff short
                    await self._stop_requested.wait()

    @contextlib.asynccontextmanager
    async def _connection(self) -> AsyncIterator[aiomqtt.Client]:
        """``async with aiomqtt.Client`` whose exit has a deadline of its own.

        A disconnect that never completes once hung ``run()`` (seen in CI after a cancel), so
        the exit is bounded here whatever aiomqtt does. Past the deadline the connection is
        left to paho, which closes a socket silent for ``keepalive`` seconds: aiomqtt has no
        public abort, and reaching into either library's internals breaks silently on upgrade.
        """
        client = self._client()
        await client.__aenter__()
        exc_info: tuple[type[BaseException] | None, BaseException | None, Any] = (None, None, None)
        try:
            yield client
        except BaseException as exc:
            exc_info = (type(exc), exc, exc.__traceback__)
            raise
        finally:
            try:
                async with asyncio.timeout(self._timeout):
                    await client.__aexit__(*exc_info)
            except TimeoutError:
                log.warning("telemetry: MQTT disconnect not completed in %.1f s; the socket "
                            "closes at paho's keepalive (%d s)", self._timeout, self._keepalive)
            except (aiomqtt.MqttError, OSError):
                pass  # the connection was already lost; the error that lost it is raised above

    def _client(self) -> aiomqtt.Client:
        will = aiomqtt.Will(topic=f"{self.prefix}/{BRIDGE_TOPIC}",
                            payload=self._bridge_payload(online=False), qos=1, retain=True)
        return aiomqtt.Client(
            self.host, self.port, username=self._username, password=self._password,
            identifier=self._client_id, tls_context=self._tls, will=will,
            timeout=self._timeout, keepalive=self._keepalive, logger=_paho_log,
        )

    def _on_connected(self) -> None:
        self._backoff.succeeded()
        self._connected = True
        self._connections += 1
        if self._connections > 1:
            self._reconnects += 1
        for site, status in self._last_status.items():  # the broker may have lost retained
            self._pending_status.setdefault(site, status)
        log.info("telemetry: connected to MQTT %s:%d (connection %d)", self.host, self.port,
                 self._connections)
        self._report_drops(force=True)

    async def _session(self, client: aiomqtt.Client) -> None:
        """Drain and listen until the connection fails (raises) or ``stop()`` (returns)."""
        _reraise_lost_cancel()
        await self._publish_bridge_online(client, online=True)
        _reraise_lost_cancel()
        if self.accept_commands:
            await client.subscribe(f"{self.prefix}/+/cmd", qos=1, timeout=self._timeout)
            _reraise_lost_cancel()
        drain = asyncio.create_task(self._drain(client), name="fresco-telemetry.drain")
        listen = asyncio.create_task(self._listen(client), name="fresco-telemetry.listen")
        try:
            done, _ = await asyncio.wait({drain, listen}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in (drain, listen):
                task.cancel()
            await asyncio.gather(drain, listen, return_exceptions=True)
        for task in done:
            task.result()  # re-raise the MQTT error that ended the session

    async def _publish_bridge_online(self, client: aiomqtt.Client, *, online: bool,
                                     timeout: float | None = None) -> None:
        await client.publish(f"{self.prefix}/{BRIDGE_TOPIC}", self._bridge_payload(online=online),
                             qos=1, retain=True, timeout=timeout or self._timeout)

    @staticmethod
    def _bridge_payload(*, online: bool) -> bytes:
        return json.dumps({"v": SCHEMA_VERSION, "online": online}, separators=(",", ":")).encode()

    async def _drain(self, client: aiomqtt.Client) -> None:
        """Publish what is queued, in priority order, a burst of publishes at a time.

        aiomqtt's one way to publish is an awaited ``publish`` per message (paho then writes
        each with its own ``send``; nothing public writes several at once). Awaited one by
        one, each message also costs its own loop turns and writer registration; a burst's
        publishes run together instead, started in queue order, so paho writes them in that
        order. The cost per step: BENCHMARKS.md, "Telemetry".
        """
        while True:
            burst = self._next_burst()
            if not burst:
                if self._stopping:
                    return
                self._report_drops()
                self._wake.clear()
                await self._wake.wait()  # idle: nothing to publish, no peer involved
                await asyncio.sleep(_LINGER)
                continue
            self._sending = len(burst)
            try:
                async with asyncio.timeout(self._timeout):  # one deadline for the burst
                    results = await asyncio.gather(
                        *(client.publish(topic, payload, qos=self.qos, retain=retain,
                                         timeout=math.inf) for topic, payload, retain in burst),
                        return_exceptions=True)
            except BaseException:
                self._dropped += len(burst)  # taken off the queue but not confirmed sent
                raise
            finally:
                self._sending = 0
            failed = [r for r in results if isinstance(r, BaseException)]
            self._published += len(burst) - len(failed)
            self._dropped += len(failed)
            if failed:
                raise failed[0]

    def _next_burst(self) -> list[tuple[str, bytes, bool]]:
        """Up to ``_BURST`` messages off the queues, in priority order."""
        burst: list[tuple[str, bytes, bool]] = []
        while len(burst) < _BURST and (item := self._next_message()) is not None:
            burst.append(item)
        return burst

    def _next_message(self) -> tuple[str, bytes, bool] | None:
        """The next (topic, payload, retain) in priority order; bad records are logged, dropped."""
        while True:
            record: SiteStatus | SiteEvent | StepSample
            if self._pending_status:
                site = next(iter(self._pending_status))
                record, kind, retain = self._pending_status.pop(site), "status", True
            elif self._events:
                record, kind, retain = self._events.popleft(), "event", False
            elif self._steps:
                record, kind, retain = self._steps.popleft(), "step", False
            else:
                return None
            base = self._topic_base(record.site)
            try:
                if base is None:
                    raise TelemetrySchemaError(f"invalid site name {record.site!r}")
                return f"{base}/{kind}", record.to_json(self.compact), retain
            except (TelemetrySchemaError, TypeError, ValueError) as exc:
                self._dropped += 1
                self._reject_log.warning("telemetry: %s message not publishable, dropped: %s",
                                         kind, exc)

    def _topic_base(self, site: str) -> str | None:
        base = self._topics.get(site, "")
        if base == "":
            try:
                base = f"{self.prefix}/{check_site_name(site)}"
            except TelemetrySchemaError:
                base = None
            self._topics[site] = base
        return base

    def _drop_backlog(self, why: str) -> None:
        n = len(self._steps) + len(self._events) + len(self._pending_status)
        self._steps.clear()
        self._events.clear()
        self._pending_status.clear()
        self._dropped += n
        if n:
            log.warning("telemetry: %d queued message(s) dropped: %s", n, why)

    def _report_drops(self, *, force: bool = False) -> None:
        new = self._dropped - self._drops_reported
        now = time.monotonic()
        if new and (force or now - self._drops_reported_at >= 5.0):
            log.warning("telemetry: %d message(s) dropped since last report (%d in total): "
                        "queue full or broker unreachable", new, self._dropped)
            self._drops_reported, self._drops_reported_at = self._dropped, now

    # -- operator commands ------------------------------------------------------------------

    async def _listen(self, client: aiomqtt.Client) -> None:
        """Consume inbound messages; also how a dropped connection is noticed promptly."""
        async for message in client.messages:
            self.handle_command_message(str(message.topic), message.payload,
                                        retain=bool(message.retain))

    def handle_command_message(self, topic: str, payload: object, *, retain: bool = False) -> None:
        """Validate one inbound command message and hand it to the handler, or log why not.

        Accepted: topic ``<prefix>/<site>/cmd``, not retained, at most 1 KiB of UTF-8 JSON
        ``{"command": "pause"|"resume"|"abort", "token": "<command_token>", "id": "..."}``
        (``id`` optional, no other keys). Anything else is ignored with a warning that never
        includes the token. Never raises: a message's content must not end the MQTT session
        (its listener), which carries the telemetry and the remote abort.
        """
        try:
            reason = self._command_problem(topic, payload, retain)
        except Exception as exc:  # a payload this check did not foresee is still only ignored
            reason = f"unreadable payload ({type(exc).__name__})"
        if isinstance(reason, OperatorCommand):
            command = reason
            assert self._handler is not None  # guaranteed by accept_commands' config check
            try:
                self._handler(command)
            except Exception as exc:
                self._rejected += 1
                self._reject_log.warning("telemetry: command %s for site %s refused by the "
                                         "daemon: %s", command.command, command.site, exc)
                return
            self._accepted += 1
            log.warning("telemetry: operator command %s accepted for site %s (id %s)",
                        command.command, command.site, command.request_id)
            return
        self._rejected += 1
        self._reject_log.warning("telemetry: command message on %r ignored: %s", topic, reason)

    def _command_problem(self, topic: str, payload: object,
                         retain: bool) -> OperatorCommand | str:
        """The parsed command, or why the message must be ignored."""
        if not self.accept_commands:
            return "operator commands are disabled (accept_commands=False)"
        head, tail = f"{self.prefix}/", "/cmd"
        matches = topic.startswith(head) and topic.endswith(tail)
        site = topic[len(head) : -len(tail)] if matches else ""
        try:
            check_site_name(site)
        except TelemetrySchemaError:
            return "topic is not <prefix>/<site>/cmd with a valid site name"
        if retain:
            return "retained command (a stale command must never move an actuator)"
        if not isinstance(payload, bytes | bytearray):
            return f"payload is {type(payload).__name__}, expected bytes"
        # paho has read the whole message by now (no public API caps it sooner): the broker's
        # ``message_size_limit`` is what keeps a huge one away (README.md, "Operator commands")
        if len(payload) > MAX_COMMAND_BYTES:
            return f"payload of {len(payload)} bytes exceeds {MAX_COMMAND_BYTES}"
        try:
            body = decode(bytes(payload))
        except RequestJsonError as exc:
            return f"malformed payload ({len(payload)} bytes): {exc}"
        if not isinstance(body, dict):
            return f"payload is a JSON {type(body).__name__}, expected an object"
        unknown = sorted(set(body) - {"command", "token", "id"})
        if unknown:
            return f"unknown key(s) {unknown}"
        token = _utf8(body.get("token"))
        if token is None or not hmac.compare_digest(token, self._token):
            return "missing or wrong token (unauthorised)"
        command = body.get("command")
        if not isinstance(command, str) or command not in COMMANDS:
            return f"unknown command {command!r}; expected one of {sorted(COMMANDS)}"
        request_id = body.get("id")
        if request_id is not None and not (isinstance(request_id, str) and len(request_id) <= 64
                                           and _utf8(request_id) is not None):
            return "id must be a string of at most 64 characters (UTF-8)"
        return OperatorCommand(site=site, command=cast(CommandName, command),
                               request_id=request_id)

