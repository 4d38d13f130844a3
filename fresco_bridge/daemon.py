"""The bridge: one listener per configured site, all in one event loop, never exiting on a session.

``Bridge`` owns the run record, the sites and their listeners. A failed session (bad input,
client killed, controller fault) ends only that session; the listener keeps accepting.
"""

from __future__ import annotations

import asyncio
import logging
import shutil
import ssl
import threading
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TypeVar

from pydantic import SecretStr

from . import __version__, loops
from .config import ConfigError, LabConfig, SiteConfigBase, TelemetryConfig
from .config_model import redact_config_text, secret_values
from .ctl import ControlError, ControlServer, OperatorDesk, socket_path_for
from .indicators import OnlineMonitor
from .loops import LoopKind
from .record import RunRecord
from .record.recovery import LastCommit, flag_interrupted
from .record.scan import ResumeScan
from .server.connection import SiteListener
from .server.tcp import TcpConnection
from .server.tls import TlsConfigError, server_context
from .server.udp import UdpSiteEndpoint
from .site_kinds import SITE_KINDS
from .sites import Site
from .sites.access import Allowlist
from .sites.kind import SiteContext, SiteGroup
from .telemetry import MqttTelemetry
from .telemetry.metrics import Metrics, MetricsServer
from .telemetry.taps import MonitorBatch, SiteTaps

log = logging.getLogger("fresco_bridge")
T = TypeVar("T")


def _tls_context(tcfg: TelemetryConfig) -> ssl.SSLContext | None:
    """The broker connection's TLS context: certificate and host name verified, always."""
    if not tcfg.tls:
        return None
    try:
        context = ssl.create_default_context(
            cafile=str(tcfg.tls_ca_file) if tcfg.tls_ca_file else None)
        if tcfg.tls_cert_file is not None and tcfg.tls_key_file is not None:
            context.load_cert_chain(str(tcfg.tls_cert_file), str(tcfg.tls_key_file))
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"telemetry TLS: cannot load the certificates: {exc}") from exc
    return context


def _site_tls(scfg: SiteConfigBase) -> ssl.SSLContext | None:
    """The site's mutual-TLS server context (OpenFresco's SSL channel), if ``tls = true``."""
    if not scfg.tls:
        return None
    assert scfg.cert_file and scfg.key_file and scfg.client_ca_file
    return server_context(scfg.cert_file, scfg.key_file, scfg.client_ca_file)


def _secret(value: SecretStr | None) -> str | None:
    return None if value is None else value.get_secret_value()


class Bridge:
    def __init__(self, config: LabConfig, config_text: str, *, run_dir: Path | None = None,
                 resume: Path | None = None) -> None:
        self.config = config
        self.config_text = config_text
        self.run_dir_override = run_dir
        self.resume = resume
        """An interrupted run directory to continue instead of starting a new one."""
        self.record: RunRecord | None = None
        self.sites: dict[str, Site] = {}
        self._servers: list[asyncio.Server | asyncio.DatagramTransport] = []
        self.ports: dict[str, int] = {}
        self.telemetry: MqttTelemetry | None = None
        self._telemetry_task: asyncio.Task[None] | None = None
        self.metrics: Metrics | None = None
        self.metrics_server: MetricsServer | None = None
        self.desk = OperatorDesk(self.sites)
        self.control: ControlServer | None = None
        self._monitor_batches: list[MonitorBatch] = []
        self.groups: list[SiteGroup] = []
        """Each site kind's group (``site_kinds.py``): its sites and what they share."""

    async def start(self) -> None:
        cfg = self.config
        run_root = self.run_dir_override or cfg.bridge.run_dir
        resumed: dict[str, LastCommit] = {}
        scan: ResumeScan | None = None
        if self.resume is not None:
            if not cfg.record.enabled:
                raise ConfigError("resuming a run needs [record] enabled = true")
            self.record = RunRecord.resume(self.resume, fsync=cfg.record.fsync,
                                           sync_interval=cfg.record.sync_interval,
                                           min_free_mb=cfg.record.min_free_mb,
                                           read_position=False)
            scan = ResumeScan(self.resume)  # read once, below, for every kind's readers
        elif cfg.record.enabled:
            self.record = RunRecord.create(
                run_root, cfg.bridge.run_name,
                redact_config_text(self.config_text, (v for _, v in secret_values(cfg))),
                {"fresco_bridge": __version__, "sites": [s.name for s in cfg.sites]},
                fsync=cfg.record.fsync, sync_interval=cfg.record.sync_interval,
                min_free_mb=cfg.record.min_free_mb,
            )
            log.info("run record: %s", self.record.directory)
        if self.record is not None and self.record.failure is not None:
            log.error("%s: every site refuses clients until the run record can be written",
                      self.record.failure)
        flag_interrupted(run_root, exclude=None if self.record is None
                         else self.record.directory)
        loop = asyncio.get_running_loop()
        context = SiteContext(self.record, cfg.bridge.controller_timeout,
                              cfg.bridge.controller_recovery, scan)
        try:
            built: dict[str, Site] = {}
            for kind in SITE_KINDS.values():
                configs = [s for s in cfg.sites if s.kind == kind.name]
                if configs:
                    group = kind.build(configs, context)
                    self.groups.append(group)
                    built.update(group.sites)
            if scan is not None and self.record is not None:
                resumed = self._read_resumed(scan, self.record)
            for group in self.groups:  # before any site listens: controllers, learners
                await group.start()
            for scfg in cfg.sites:
                site = self.sites[scfg.name] = built[scfg.name]
                if scfg.name in resumed:
                    last = resumed[scfg.name]
                    site.resume_from(last.session, last.step, last.time)
                listener = self._listener(site)
                try:
                    server: asyncio.Server | asyncio.DatagramTransport
                    if scfg.transport == "tcp":
                        server = await loop.create_server(
                            partial(TcpConnection, listener, _site_tls(scfg)),
                            cfg.bridge.host, scfg.port, reuse_address=True,
                        )
                        port = server.sockets[0].getsockname()[1]
                    else:
                        server, _ = await loop.create_datagram_endpoint(
                            partial(UdpSiteEndpoint, listener),
                            local_addr=(cfg.bridge.host, scfg.port),
                        )
                        port = server.get_extra_info("sockname")[1]
                except OSError as exc:
                    raise OSError(exc.errno, f"site {scfg.name}: cannot listen on "
                                  f"{scfg.transport.upper()} {cfg.bridge.host}:{scfg.port}: "
                                  f"{exc.strerror or exc}") from exc
                self._servers.append(server)
                self.ports[scfg.name] = port
                log.info("site %s: listening on %s %s:%d (%s protocol, %d DOF, setup %s)",
                         scfg.name, scfg.transport.upper(), cfg.bridge.host, port,
                         scfg.protocol, scfg.dofs, scfg.setup)
            for group in self.groups:
                group.wire(self.sites)
        except (OSError, TlsConfigError, ConfigError):
            await self._abandon_start()
            raise
        await self._start_control()
        tcfg = cfg.telemetry
        if tcfg.mqtt_host is not None:
            self.telemetry = MqttTelemetry(
                host=tcfg.mqtt_host, port=tcfg.mqtt_port, prefix=tcfg.prefix, qos=tcfg.qos,
                queue_size=tcfg.queue_size, compact=tcfg.compact, username=tcfg.username,
                password=_secret(tcfg.password), tls=_tls_context(tcfg),
                accept_commands=tcfg.accept_commands,
                command_handler=self.desk.handle_mqtt if tcfg.accept_commands else None,
                command_token=_secret(tcfg.command_token),
            )
            self._telemetry_task = loop.create_task(self.telemetry.run(), name="telemetry.mqtt")
            log.info("telemetry: MQTT %s:%d prefix %s", tcfg.mqtt_host, tcfg.mqtt_port,
                     tcfg.prefix)
        if tcfg.metrics_port is not None:
            try:
                self._start_metrics(tcfg.metrics_host, tcfg.metrics_port)
            except OSError:
                await self._abandon_start()
                raise
        self._attach_taps()

    @staticmethod
    def _read_resumed(scan: ResumeScan, record: RunRecord) -> dict[str, LastCommit]:
        """The resumed run's record, read once for every reader the kinds added (specimens,
        learners) and for where it stops: each site's last committed step."""
        scan.read()
        record.continue_at(scan.point.seq, scan.point.t)
        resumed = scan.last_commits()
        log.warning("run record: %s RESUMED (continues after the last committed step of "
                    "each site: %s)", record.directory,
                    ", ".join(f"{c.site} step {c.step}" for c in resumed.values()) or "none")
        return resumed

    def _listener(self, site: Site) -> SiteListener:
        """What the site's connections share; an open allowlist is said loudly."""
        bcfg = self.config.bridge
        entries = site.cfg.allowed_clients
        allowlist = Allowlist(bcfg.allowed_clients if entries is None else entries)
        if allowlist.any:
            log.warning("site %s ADMITS CLIENTS FROM ANY ADDRESS (allow_any_client = true; "
                        "bound to %s): anyone who can reach the port can drive the actuator",
                        site.name, bcfg.host)
        return SiteListener(site, allowlist, bcfg.max_data_size, bcfg.session_idle_timeout,
                            bcfg.message_deadline)

    async def _abandon_start(self) -> None:
        """A start that failed closes what it opened; a run directory that recorded nothing
        is removed, so a failed start does not show up as an empty run."""
        await self.close()
        record = self.record
        if record is not None and record.lines == 0 and self.resume is None:
            shutil.rmtree(record.directory, ignore_errors=True)
            log.info("run record %s removed: the bridge never started", record.directory)

    def _start_metrics(self, host: str, port: int) -> None:
        """The /metrics endpoint (its own thread); a port in use fails start() cleanly."""
        self.metrics = Metrics()
        telemetry = self.telemetry
        if telemetry is not None:
            self.metrics.track_telemetry(lambda: telemetry.stats)
        try:
            self.metrics_server = self.metrics.start_http_server(host, port)
        except OSError as exc:
            raise OSError(exc.errno, f"metrics endpoint {host}:{port}: {exc.strerror}") from exc
        for site in self.sites.values():
            site.metrics = self.metrics.for_site(site.name)
        for group in self.groups:
            group.attach_metrics(self.metrics)
        log.info("metrics: http://%s:%d/metrics", host, self.metrics_server.port)

    def _attach_taps(self) -> None:
        """Give each site its taps: MQTT, metrics and/or monitor lines in the run record."""
        tcfg = self.config.telemetry
        recording = self.record is not None and tcfg.monitors
        if self.telemetry is None and self.metrics is None and not recording:
            return  # nothing to feed: the sites' only listener is the record's writer
        for site in self.sites.values():
            monitor = OnlineMonitor(
                tcfg.monitor_dt, tcfg.monitor_window, warn_tracking_error=tcfg.warn_tracking_error,
            ) if tcfg.monitors else None
            if self.telemetry is None and site.metrics is None and monitor is not None \
                    and site.recorder is not None:
                # the record is the monitors' only consumer: batched (the same samples)
                batch = MonitorBatch(monitor, site.recorder, site.monitor_warning)
                self._monitor_batches.append(batch)
                site.add_listener(batch)
                continue
            taps = SiteTaps(self.telemetry, site.metrics,
                            site.recorder if tcfg.monitors else None, monitor, site.monitor_warning,
                            predicted=SITE_KINDS[site.cfg.kind].predicted,
                            correction=site.correction_sample)
            site.add_listener(taps)
            taps.publish_status(site.status_now())

    async def _start_control(self) -> None:
        """The operator control socket (``fresco-bridge ctl``); a failure stops start()."""
        path = self.config.bridge.control_socket
        run_dir = self.record.directory if self.record is not None else None
        if path is None and run_dir is not None:
            path = socket_path_for(run_dir)
        if path is None:
            log.warning("no operator control socket: recording is off and [bridge] "
                        "control_socket is not set")
            return
        self.control = ControlServer(self.desk, path, pointer_dir=run_dir)
        try:
            await self.control.start()
        except (ControlError, OSError):
            self.control = None
            await self.close()
            raise

    async def close(self) -> None:
        if self.control is not None:
            await self.control.close()
            self.control = None
        for server in self._servers:
            server.close()
        for server in self._servers:
            if isinstance(server, asyncio.AbstractServer):
                await server.wait_closed()
        self._servers.clear()
        for site in self.sites.values():
            site.close_session("bridge shutting down")
        for group in self.groups:
            await group.close()
        if self.metrics_server is not None:
            self.metrics_server.close()
            self.metrics_server = None
        if self.telemetry is not None and self._telemetry_task is not None:
            self.telemetry.stop()
            try:
                await asyncio.wait_for(self._telemetry_task, 5.0)
            except (TimeoutError, asyncio.CancelledError):
                log.warning("telemetry: not drained within 5 s; %s", self.telemetry.stats)
        for batch in self._monitor_batches:  # after the sessions' ends (they flush too)
            batch.flush()
        if self.record is not None:
            self.record.close()

    async def serve_forever(self, stop: asyncio.Event | None = None) -> None:
        await self.start()
        try:
            await (stop or asyncio.Event()).wait()
        finally:
            await self.close()


DRAIN_SECONDS = 10.0
"""How long ``BridgeThread.drain`` waits for the sessions' DIE by default."""
THREAD_START_DEADLINE = 180.0
"""How long ``BridgeThread`` waits for ``Bridge.start``: above every part's own start deadline
(a learner worker's is 120 s: import, offline fit, compiling its kernels), so the part that is
late reports its own error first."""


class BridgeThread:
    """A bridge on its own event loop in a background thread (demo, benchmarks, tests).

    ``with BridgeThread(cfg, text) as b: b.ports[...]`` — the integrator side can then use
    plain blocking sockets in the calling thread, as a separate FE process would.
    """

    def __init__(self, config: LabConfig, config_text: str, *, run_dir: Path | None = None,
                 resume: Path | None = None, event_loop: LoopKind = "asyncio") -> None:
        self.bridge = Bridge(config, config_text, run_dir=run_dir, resume=resume)
        self.event_loop = event_loop
        """The loop the thread runs (asyncio's unless asked: ``serve`` follows the config)."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="fresco-bridge", daemon=True)

    def _main(self) -> None:
        async def run() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            try:
                await self.bridge.start()
            except BaseException as exc:
                self._error = exc
                self._ready.set()
                return
            self._ready.set()
            try:
                await self._stop.wait()
            finally:
                await self.bridge.close()

        try:
            loops.run(run(), self.event_loop)
        except BaseException as exc:  # reported to the owner by __enter__/stop
            self._error = self._error or exc
            self._ready.set()

    def __enter__(self) -> BridgeThread:
        self._thread.start()
        if not self._ready.wait(THREAD_START_DEADLINE):
            raise RuntimeError(f"the bridge did not start within {THREAD_START_DEADLINE:.0f} s")
        if self._error is not None:
            raise self._error
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def drain(self, timeout: float = DRAIN_SECONDS) -> bool:
        """Wait until no site serves a session, at most ``timeout`` s; True if none does.

        Why: a client's last commit and DIE need no reply, so they may still be in flight when
        its owner is done; a twin's last step may still be with its learner. Stopping then
        would end those sessions as if the client had vanished (the demo drains before it
        stops)."""
        if self._loop is None or not self._thread.is_alive():
            return True
        end = time.monotonic() + timeout
        while self.call(lambda: any(site.busy for site in self.bridge.sites.values())):
            if time.monotonic() >= end:
                return False
            time.sleep(0.01)
        return True

    def stop(self) -> None:
        if self._loop is not None and self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(30)

    @property
    def ports(self) -> dict[str, int]:
        return self.bridge.ports

    @property
    def run_dir(self) -> Path:
        assert self.bridge.record is not None, "recording is off"
        return self.bridge.record.directory

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn()`` on the bridge's loop (to inspect site state safely from tests)."""
        assert self._loop is not None

        async def wrapper() -> T:
            return fn()

        return asyncio.run_coroutine_threadsafe(wrapper(), self._loop).result(10)
