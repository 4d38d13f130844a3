"""Lab configuration (TOML), validated with pydantic; errors name the file, key and reason.

Units at this boundary: displacements mm, forces kN, stiffness kN/mm, mass kN·s²/mm, time s.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Union

from pydantic import (
    Discriminator,
    Field,
    SecretStr,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)

from .config_lines import locate
from .config_model import (
    ClientAddress,
    ConfigError,
    ConfigPath,
    IPv4Address,
    Name,
    StrictConfig,
)
from .controls.registry import CONTROLLER_KINDS, known_kinds
from .site_kinds import DEFAULT_KIND, SITE_KINDS, known_site_kinds
from .sites.kind import LabView
from .sites.site_config import SiteConfigBase

__all__ = ["BridgeConfig", "ConfigError", "LabConfig", "RecordConfig", "SiteConfig",
           "SiteConfigBase", "TelemetryConfig", "load_config", "parse_config"]

_Strict = StrictConfig  # every model of the lab config shares the one strict base


def _site_kind(v: Any) -> str:
    """``kind`` may be omitted for an experimental site."""
    kind = v.get("kind", DEFAULT_KIND) if isinstance(v, dict) else getattr(v, "kind",
                                                                            DEFAULT_KIND)
    return str(kind)


if TYPE_CHECKING:
    SiteConfig = SiteConfigBase
else:  # the discriminated union of every registered site kind's config model
    SiteConfig = Annotated[
        Union[tuple(Annotated[k.config, Tag(k.name)] for k in SITE_KINDS.values())],  # noqa: UP007
        Discriminator(_site_kind),
    ]
"""One ``[[sites]]`` entry: the config model of its ``kind`` (``site_kinds.py``)."""


class BridgeConfig(_Strict):
    host: IPv4Address = "127.0.0.1"
    """Bind address (IPv4: OpenSees clients only speak dotted IPv4)."""
    allowed_clients: list[ClientAddress] = Field(default_factory=lambda: ["127.0.0.1"])
    """Client IPv4 addresses (or CIDR networks) allowed to connect. ``[]`` (anyone) is refused
    unless ``allow_any_client = true``."""
    allow_any_client: bool = False
    """Admit clients from any address where an allowlist is empty (logged loudly at start)."""
    max_data_size: int = Field(default=4096, ge=5, le=1_000_000)
    """Largest dataSize (doubles per vector) a client may announce."""
    session_idle_timeout: float = Field(default=60.0, gt=0, le=86_400)
    """Seconds a session may stay silent while the bridge owes it nothing (no request being
    answered, no operator wait, no controller call) before it is ended; also a client that
    does not read its replies. Frees a site whose client vanished without a word (UDP, a
    half-open TCP connection)."""
    message_deadline: float = Field(default=5.0, gt=0, le=3_600)
    """Seconds a client has to complete a message it has begun (its size ID included), however
    often bytes arrive: a client trickling a byte now and then cannot hold a site."""
    controller_timeout: float = Field(default=5.0, gt=0)
    """Deadline in seconds for every controller call; past it the site goes to HOLD."""
    controller_recovery: float = Field(default=30.0, ge=0)
    """Seconds a site in HOLD for a lost or silent controller keeps probing it inside the
    integrator's waiting request; back in time: the run continues, else the integrator is told
    to stop (NaN answers until its DIE).
    0: no recovery (HOLD answers NaN until the session ends, so the integrator stops)."""
    run_dir: ConfigPath = Path("runs")
    run_name: Name = "run"
    event_loop: Literal["auto", "uvloop", "asyncio"] = "auto"
    """The event loop ``serve`` runs on: ``uvloop`` (libuv; less CPU per step, ``BENCHMARKS.md``,
    "Step cost and scaling"), ``asyncio`` (the standard library's), ``auto``: uvloop when it is
    installed."""
    control_socket: ConfigPath | None = None
    """Operator control socket (``fresco-bridge ctl``); default ``control.sock`` in the run
    directory (no socket when recording is off unless this is set)."""


class RecordConfig(_Strict):
    enabled: bool = True
    fsync: Literal["background", "inline", "off"] = "background"
    """``background``: group commit (fdatasync off the step loop, at most every
    ``sync_interval``); ``inline``: the step waits for fdatasync at every commit; ``off``."""
    sync_interval: float = Field(default=0.05, ge=0.0, le=10.0)
    """Group commit (``fsync = "background"``): seconds between two fdatasyncs at most; a
    power loss can cost the commits of this long plus one fdatasync. Events sync at once.
    50 ms by default: every fdatasync costs the CPU the step loop shares wake-ups and I/O
    completions, a visible share of a fast step when it runs much more often (``BENCHMARKS.md``,
    "Record size and durability")."""
    min_free_mb: float = Field(default=64.0, ge=0.0)
    """Headroom: below this much free space (MiB) on the run directory's filesystem the record
    takes no more commits: the sites HOLD and refuse clients before the disk is full, while the
    HOLD's event and the log still fit. Checked about once a second; 0 turns the check off
    (a full disk still HOLDs)."""


class TelemetryConfig(_Strict):
    """Live telemetry over MQTT (off unless ``mqtt_host`` is set), Prometheus metrics (off unless
    ``metrics_port`` is set) and online error monitors."""

    mqtt_host: str | None = None
    mqtt_port: int = Field(default=1883, ge=1, le=65535)
    prefix: str = "fresco"
    qos: Literal[0, 1] = 0
    compact: bool = False
    queue_size: int = Field(default=10000, ge=10)
    username: str | None = None
    password: SecretStr | None = None
    """Broker password (never written to the run directory's config snapshot)."""
    tls: bool = False
    """Connect to the broker over TLS, verifying its certificate (system CAs unless
    ``tls_ca_file``) and host name."""
    tls_ca_file: ConfigPath | None = None
    """PEM file of the CA(s) that signed the broker's certificate."""
    tls_cert_file: ConfigPath | None = None
    """PEM client certificate (with ``tls_key_file``), for brokers that authenticate clients."""
    tls_key_file: ConfigPath | None = None
    accept_commands: bool = False
    """Accept operator commands (pause/resume/abort) on ``<prefix>/<site>/cmd``; needs
    ``username``/``password`` and ``command_token`` (see SECURITY.md, the threat model)."""
    command_token: SecretStr | None = None
    """Shared secret every command message must carry (at least 16 characters)."""
    monitor_dt: float = Field(default=0.01, gt=0)
    """Integration time step (s) the monitors assume for FEI frequencies and delays."""
    monitor_window: int = Field(default=512, ge=16)
    warn_tracking_error: float | None = Field(default=None, gt=0)
    """|measured − command| (mm) past which a ``monitor-warning`` event is raised."""
    monitors: bool = True
    """Run the online error monitors per committed step: published with MQTT telemetry and
    written to the run record (``monitor`` lines) when recording is on (its cost per step:
    ``BENCHMARKS.md``, "Telemetry")."""
    metrics_port: int | None = Field(default=None, ge=0, le=65535)
    """Serve Prometheus ``/metrics`` on this port (off when unset; 0 picks a free port)."""
    metrics_host: IPv4Address = "127.0.0.1"
    """Bind address of the metrics endpoint (loopback by default: it has no authentication)."""


    @model_validator(mode="after")
    def _tls_files_fit(self) -> TelemetryConfig:
        files = {"tls_ca_file": self.tls_ca_file, "tls_cert_file": self.tls_cert_file,
                 "tls_key_file": self.tls_key_file}
        given = [k for k, v in files.items() if v is not None]
        if given and not self.tls:
            raise ValueError(f"{', '.join(given)} set but tls = false (set tls = true)")
        if (self.tls_cert_file is None) != (self.tls_key_file is None):
            raise ValueError("tls_cert_file and tls_key_file go together")
        for key in given:
            path = files[key]
            assert path is not None
            if not path.is_file():
                raise ValueError(f"{key}: no such file {str(path)!r}")
        return self

    @model_validator(mode="after")
    def _commands_need_credentials(self) -> TelemetryConfig:
        if not self.accept_commands:
            return self
        problems = []
        if self.mqtt_host is None:
            problems.append("mqtt_host is not set")
        if not ((self.username and self.password) or self.tls_cert_file is not None):
            problems.append("broker credentials (username and password, or a TLS client "
                            "certificate) are required")
        token = self.command_token
        if token is None or len(token.get_secret_value()) < 16:
            problems.append("command_token of at least 16 characters is required")
        if problems:
            raise ValueError("accept_commands = true is refused: " + "; ".join(problems)
                             + " (anyone able to publish on the command topic could move an "
                             "actuator)")
        return self


class LabConfig(_Strict):
    bridge: BridgeConfig = Field(default_factory=BridgeConfig)
    record: RecordConfig = Field(default_factory=RecordConfig)
    telemetry: TelemetryConfig = Field(default_factory=TelemetryConfig)
    sites: list[SiteConfig] = Field(min_length=1)

    @field_validator("sites")
    @classmethod
    def _unique(cls, sites: list[SiteConfig]) -> list[SiteConfig]:
        names = [s.name for s in sites]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"site names must be unique; repeated: {', '.join(sorted(dup))}")
        ports = [(s.port, s.transport) for s in sites if s.port != 0]
        dupp = {p for p in ports if ports.count(p) > 1}
        if dupp:
            raise ValueError(f"two sites listen on the same port: {sorted(dupp)}")
        return sites

    @model_validator(mode="after")
    def _allowlists_explicit(self) -> LabConfig:
        """An empty allowlist admits anyone: only when written explicitly."""
        bridge = self.bridge
        empty = [f"sites[{i}].allowed_clients" for i, s in enumerate(self.sites)
                 if s.allowed_clients == []]
        if bridge.allowed_clients == []:
            empty.insert(0, "bridge.allowed_clients")
        if empty and not bridge.allow_any_client:
            raise ValueError(f"{', '.join(empty)} = [] would admit clients from any address; "
                             "list the integrator hosts, or set bridge.allow_any_client = true "
                             "to admit anyone on purpose")
        return self


def _format_errors(source: str, exc: ValidationError, text: str = "",
                   raw: dict[str, Any] | None = None) -> str:
    lines = [f"{source}: invalid configuration ({exc.error_count()} problem(s))"]
    for err in exc.errors():
        at = list(err["loc"])
        parts = [p for i, p in enumerate(at) if not (
            (i and at[i - 1] == "controller" and p in CONTROLLER_KINDS)
            or (i > 1 and at[i - 2] == "sites" and p in SITE_KINDS))]
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in parts)
        loc = loc.replace(".[", "[")
        where = locate(text, raw or {}, parts)  # "line 12, site damper"
        loc = f"{where}: {loc}" if where else loc
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = _unknown_key(at)
        elif err["type"] == "union_tag_invalid":
            tag = err["ctx"]["tag"]
            msg = (f"unknown site kind {tag!r}; expected {known_site_kinds()}"
                   if at[-1] != "controller" and at[:1] == ["sites"] and len(at) == 2
                   else f"unknown controller kind {tag!r}; expected {known_kinds()}")
        got = err.get("input")
        quiet = err["type"] in ("missing", "extra_forbidden") or isinstance(got, dict | list)
        shown = "" if quiet else f" (got {got!r})"
        lines.append(f"  {loc or '<top>'}: {msg}{shown}")
    return "\n".join(lines)


def _unknown_key(loc: list[str | int]) -> str:
    """An unknown key; one that belongs to another site kind says so (a twin's controller
    table, an experimental site's updater)."""
    if len(loc) == 4 and loc[0] == "sites" and loc[2] in SITE_KINDS:
        kind, key = str(loc[2]), str(loc[3])
        owners = [k for k in SITE_KINDS.values() if k.name != kind and key in k.config.model_fields]
        if owners:
            return (f"a key of kind = \"{owners[0].name}\" sites (this site is {kind}: "
                    f"{SITE_KINDS[kind].summary.split(';')[0]})")
    return "unknown key (typo?)"


def parse_config(text: str, source: str = "<config>", *, base: Path | None = None) -> LabConfig:
    """Parse TOML text; raise ConfigError with file, key and reason. Each site kind resolves
    its entries against the whole config (``SiteKind.resolve``: data paths relative to
    ``base``, the config file's folder, default the current directory; cross-site
    references)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    try:
        cfg = LabConfig.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(_format_errors(source, exc, text, raw)) from None
    lab = LabView({s.name: s for s in cfg.sites}, cfg.bridge.controller_timeout,
                  Path.cwd() if base is None else base, lambda k: SITE_KINDS[k].predicted)
    sites: list[SiteConfigBase] = []
    problems: list[str] = []
    for i, site in enumerate(cfg.sites):
        resolve = SITE_KINDS[site.kind].resolve
        if resolve is not None:
            site, found = resolve(site, lab)
            problems += [f"sites[{i}].{p}" for p in found]
        sites.append(site)
    if problems:
        raise ConfigError("\n".join([f"{source}: invalid configuration ({len(problems)} "
                                     "problem(s))", *(f"  {p}" for p in problems)]))
    return cfg.model_copy(update={"sites": sites})


def load_config(path: Path) -> tuple[LabConfig, str]:
    """Read and validate a config file; returns the model and the text (for the snapshot)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the configuration: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(f"{path}: not UTF-8 text (TOML must be UTF-8): byte "
                          f"0x{data[exc.start]:02x} at line {line}, offset {exc.start}") from None
    return parse_config(text, str(path), base=path.parent), text
