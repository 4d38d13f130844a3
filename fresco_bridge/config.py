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
from .config_model import ClientAddress, ConfigPath, IPv4Address, StrictConfig
from .controls.kind import ControllerConfigBase
from .controls.registry import CONTROLLER_KINDS, controller_kind, known_kinds
from .controls.sim import SimControllerConfig
from .safety import ControlPointLimitsConfig
from .setups import SetupError, SetupSpec, make_setup
from .tangent import TangentMethod

Name = Annotated[str, Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]


class ConfigError(ValueError):
    """A configuration problem, already phrased for the user (file, key, reason)."""


_Strict = StrictConfig  # every model of the lab config shares the one strict base


def _controller_kind(v: Any) -> str:
    """``kind`` may be omitted for the default in-process simulated controller."""
    kind = v.get("kind", "sim") if isinstance(v, dict) else getattr(v, "kind", "sim")
    return str(kind)


if TYPE_CHECKING:
    ControllerConfig = ControllerConfigBase
else:  # the discriminated union of every registered kind's config model
    ControllerConfig = Annotated[
        Union[tuple(Annotated[k.config, Tag(k.name)] for k in CONTROLLER_KINDS.values())],  # noqa: UP007
        Discriminator(_controller_kind),
    ]


class SiteConfig(_Strict):
    """One site: a listener the integrator connects to, and its controller (``experimental``)
    or the twin of an experimental site's element (``updatable``, ``twins/``)."""

    name: Name
    kind: Literal["experimental", "updatable"] = "experimental"
    """``updatable``: the force comes from an updater learning online from ``learns_from``."""
    port: int = Field(ge=0, le=65535)
    """0 picks a free port (tests, demo); the chosen port is logged and printed."""
    transport: Literal["tcp", "udp"] = "tcp"
    protocol: Literal["element", "site"] = "element"
    """``element``: OpenSees genericClient / OpenFresco EE* clients; ``site``: ShadowExpSite."""
    dofs: int = Field(default=1, ge=1, le=64)
    """Number of basic DOFs of the element served (the -dof entries of genericClient)."""
    setup: SetupSpec = "NoTransformation"
    """A name (``NoTransformation``, ``OneActuator``) or a ``[sites.setup]`` table: OpenFresco's
    setup as ``kind`` with its parameters (docs/openfresco-setups.md)."""
    tangent: TangentMethod = "controller"
    """The tangent answered to action 13: the controller's (``controller``), its first answer
    kept (``initial``), or estimated from the committed steps (``broyden``, ``bfgs``,
    ``transpose``; docs/openfresco-setups.md)."""
    controller: ControllerConfig = Field(default_factory=SimControllerConfig)
    """A kind of ``controls/registry.py``: ``sim`` (in-process specimen, the default), ``rig``,
    ``modbus``, ``mts``."""
    damping: list[list[float]] | None = None
    """n×n damping matrix in basic DOFs, row by row (answers action 14); default zero."""
    mass: list[list[float]] | None = None
    """n×n mass matrix in basic DOFs, row by row (answers action 15); default zero."""
    allowed_clients: list[ClientAddress] | None = None
    """Client IPv4 addresses (or CIDR networks) allowed to connect; default: the bridge-wide
    list. ``[]`` admits anyone and needs ``bridge.allow_any_client = true``."""
    actor_tag: int = 1
    """Tag this site reports to a ShadowExpSite (site protocol only)."""
    limits: list[ControlPointLimitsConfig] = Field(default_factory=list)
    """``[[sites.limits]]``, one per control point (actuator after the setup); default none."""
    tls: bool = False
    """Mutual TLS as OpenFresco's ``TCP_SocketSSL``: the site presents ``cert_file`` /
    ``key_file`` and admits only clients whose certificate ``client_ca_file`` issued directly
    (verify depth 1). TCP only."""
    cert_file: ConfigPath | None = None
    """PEM certificate the site presents (OpenFresco's ``server.crt``)."""
    key_file: ConfigPath | None = None
    """PEM private key of ``cert_file`` (OpenFresco's ``server.key``)."""
    client_ca_file: ConfigPath | None = None
    """PEM CA certificate(s) that issue the clients' certificates (OpenFresco's
    ``server_ca.crt``)."""
    learns_from: Name | None = None
    """Updatable site: the experimental site (one actuator) whose committed steps it learns
    from."""
    updater: str | None = None
    """Updatable site: a name of ``updating/registry.py`` (``none``, ``offline_ann``,
    ``online_ann``, ``online_ukf``, ``online_improved``)."""
    offline: ConfigPath | None = None
    """Updatable site: the offline database (CSV ``time,disp,force``, the bridge's export CSV
    or a run directory), relative to the config file's folder."""
    model: ConfigPath | None = None
    """Updatable site: an ANN model file (``updater pretrain``), relative to the config file's
    folder."""
    causality: Literal["previous-step", "same-step"] = "previous-step"
    """Updatable site: ``previous-step``: the twin's step i answers from what was learned
    through the source's step i-1; ``same-step``: also from the source's measurement of step
    i (the paper's order; one trial per step: explicit schemes; in-process sources)."""
    on_learner_loss: Literal["hold", "freeze"] = "hold"
    """Updatable site: when the learner dies or misses its deadline, ``hold`` (the site's HOLD:
    NaN answers, the integrator stops) or ``freeze`` (answer from the learner's last snapshot,
    parameters frozen, until a new worker has caught up)."""
    updater_options: dict[str, Any] = Field(default_factory=dict)
    """Updatable site: the updater's options (as ``updater replay --option KEY=VALUE``)."""
    learner_deadline: float = Field(default=2.0, gt=0, le=600)
    """Updatable site: seconds the twin waits for its learner's answer; past it the learner
    counts as lost (``on_learner_loss``). Shorter than ``bridge.controller_timeout``."""

    @field_validator("limits", mode="before")
    @classmethod
    def _single_limits_table(cls, v: Any) -> Any:
        """``[sites.limits]`` (one table, not an array) is the one control point's limits."""
        return [v] if isinstance(v, dict) else v

    @model_validator(mode="after")
    def _matrices_fit(self) -> SiteConfig:
        for key in ("damping", "mass"):
            m = getattr(self, key)
            if m is not None and (len(m) != self.dofs or any(len(r) != self.dofs for r in m)):
                n = self.dofs
                raise ValueError(f"{key} must be a {n}×{n} matrix (dofs = {n})")
        if self.setup == "OneActuator" and self.dofs > 2:
            raise ValueError("setup OneActuator serves dofs = 1 or 2 (two nodes, -dof 1 -dof 1)")
        try:
            setup = make_setup(self.setup, self.dofs)  # setups/ owns the count and geometry
        except SetupError as exc:
            raise ValueError(str(exc)) from None
        n_act = setup.n_actuators
        problem = controller_kind(self.controller.kind).actuators_problem(
            self.controller, n_act, setup.specimen_geometry())
        if problem is not None:
            raise ValueError(f"{problem} (setup {self.setup} with {self.dofs} DOF(s))")
        self._kind_keys_fit(n_act)
        actuators = [lim.actuator for lim in self.limits]
        if any(a > n_act for a in actuators):
            raise ValueError(f"limits: actuator {max(actuators)} does not exist (setup "
                             f"{self.setup} with {self.dofs} DOF(s) drives {n_act} actuator(s))")
        if len(set(actuators)) != len(actuators):
            raise ValueError(f"limits: one [[sites.limits]] table per actuator; repeated: "
                             f"{sorted({a for a in actuators if actuators.count(a) > 1})}")
        self._tls_fits()
        return self

    def _kind_keys_fit(self, n_act: int) -> None:
        twin_keys = [k for k in _TWIN_KEYS if k in self.model_fields_set]
        if self.kind == "experimental":
            if twin_keys:
                raise ValueError(f"{', '.join(twin_keys)}: keys of kind = \"updatable\" sites "
                                 "(this site is experimental)")
            return
        if "controller" in self.model_fields_set:
            raise ValueError("an updatable site has no [sites.controller] table (its force is "
                             "the twin's, learned from learns_from)")
        missing = [k for k in ("learns_from", "updater") if getattr(self, k) is None]
        if missing:
            raise ValueError(f"kind = \"updatable\" needs {' and '.join(missing)}")
        if n_act != 1:
            raise ValueError(f"an updatable site drives one actuator (its twin is uniaxial); "
                             f"setup {self.setup} with {self.dofs} DOF(s) drives {n_act}")
        if self.offline is not None and self.model is not None:
            raise ValueError("give offline or model, not both")

    def _tls_fits(self) -> None:
        files = {"cert_file": self.cert_file, "key_file": self.key_file,
                 "client_ca_file": self.client_ca_file}
        if not self.tls:
            given = [k for k, v in files.items() if v is not None]
            if given:
                raise ValueError(f"{', '.join(given)} set but tls = false (set tls = true)")
            return
        if self.transport != "tcp":
            raise ValueError("tls = true needs transport = \"tcp\" (OpenFresco's SSL channel is "
                             "TCP; there is no TLS over UDP here)")
        missing = [k for k, v in files.items() if v is None]
        if missing:
            raise ValueError(f"tls = true needs {', '.join(missing)} (OpenFresco's server.crt, "
                             "server.key and server_ca.crt)")
        for key, path in files.items():
            assert path is not None
            if not path.is_file():
                raise ValueError(f"{key}: no such file {str(path)!r}")


_TWIN_KEYS = ("learns_from", "updater", "offline", "model", "causality", "on_learner_loss",
              "updater_options", "learner_deadline")
"""The keys only an updatable site takes."""


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
        parts = list(err["loc"])
        parts = [p for i, p in enumerate(parts) if not (i and parts[i - 1] == "controller"
                                                         and p in CONTROLLER_KINDS)]
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in parts)
        loc = loc.replace(".[", "[")
        where = locate(text, raw or {}, parts)  # "line 12, site damper"
        loc = f"{where}: {loc}" if where else loc
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown key (typo?)"
        elif err["type"] == "union_tag_invalid":
            msg = f"unknown controller kind {err['ctx']['tag']!r}; expected {known_kinds()}"
        got = err.get("input")
        quiet = err["type"] in ("missing", "extra_forbidden") or isinstance(got, dict | list)
        shown = "" if quiet else f" (got {got!r})"
        lines.append(f"  {loc or '<top>'}: {msg}{shown}")
    return "\n".join(lines)


def parse_config(text: str, source: str = "<config>", *, base: Path | None = None) -> LabConfig:
    """Parse TOML text; raise ConfigError with file, key and reason. Relative data paths of
    updatable sites resolve against ``base`` (the config file's folder; default: the current
    directory)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    try:
        cfg = LabConfig.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(_format_errors(source, exc, text, raw)) from None
    if not any(s.kind == "updatable" for s in cfg.sites):
        return cfg
    cfg, problems = _updatable_sites(cfg, Path.cwd() if base is None else base)
    if problems:
        raise ConfigError("\n".join([f"{source}: invalid configuration ({len(problems)} "
                                     "problem(s))", *(f"  {p}" for p in problems)]))
    return cfg


def _updatable_sites(cfg: LabConfig, base: Path) -> tuple[LabConfig, list[str]]:
    """``cfg`` with the updatable sites' data paths resolved against ``base``, and what is
    wrong with those sites (``sites[i].key: reason``): their source, updater and data. The
    updater registry and the data readers load only for a config with updatable sites."""
    from .updating.base import UpdaterError
    from .updating.histories import read_history
    from .updating.modelfile import load_model
    from .updating.registry import UPDATERS, updater_options

    problems: list[str] = []
    by_name = {s.name: s for s in cfg.sites}
    sites = list(cfg.sites)
    for i, site in enumerate(sites):
        if site.kind != "updatable":
            continue
        key = f"sites[{i}]"
        source = by_name.get(site.learns_from or "")
        if source is None:
            problems.append(f"{key}.learns_from: no site named {site.learns_from!r} (sites: "
                            f"{', '.join(by_name)})")
        elif source.kind != "experimental":
            problems.append(f"{key}.learns_from: site {source.name!r} is {source.kind}; a twin "
                            "learns from an experimental site")
        elif (n := make_setup(source.setup, source.dofs).n_actuators) != 1:
            problems.append(f"{key}.learns_from: site {source.name!r} drives {n} actuators "
                            f"(setup {source.setup}, dofs {source.dofs}); a twin learns from a "
                            "one-actuator site")
        if site.learner_deadline >= cfg.bridge.controller_timeout:
            problems.append(f"{key}.learner_deadline: {site.learner_deadline:g} s must be "
                            f"shorter than bridge.controller_timeout "
                            f"({cfg.bridge.controller_timeout:g} s)")
        if (site.causality == "same-step"
                and 2 * site.learner_deadline >= cfg.bridge.controller_timeout):
            problems.append(f"{key}.learner_deadline: same-step waits up to it for the "
                            "source's trial, then for the learner: twice it must be "
                            "shorter than bridge.controller_timeout "
                            f"({cfg.bridge.controller_timeout:g} s)")
        name = site.updater or ""
        if name not in UPDATERS:
            problems.append(f"{key}.updater: unknown updater {name!r}; known: "
                            f"{', '.join(UPDATERS)}")
            continue
        paths = {k: p if p is None or p.is_absolute() else base / p
                 for k, p in (("offline", site.offline), ("model", site.model))}
        site = sites[i] = site.model_copy(update=paths)
        accepted = updater_options(name)
        for k, option in (("offline", "offline"), ("model", "model_file")):
            if paths[k] is not None and option not in accepted:
                problems.append(f"{key}.{k}: updater {name!r} takes no {k}")
        needs = UPDATERS[name].needs
        if needs and site.offline is None and (site.model is None or "model_file" not in needs):
            wanted = " or ".join(f"{k} = \"...\"" for k, o in (("offline", "offline"),
                                                                ("model", "model_file"))
                                 if o in needs)
            problems.append(f"{key}.updater: updater {name!r} needs {wanted} (the offline "
                            "database or a pre-trained model)")
        given = set(site.updater_options)
        unknown = sorted(given - set(accepted))
        if unknown:
            problems.append(f"{key}.updater_options: unknown option(s) {', '.join(unknown)} of "
                            f"updater {name!r}; allowed: {', '.join(accepted) or '(none)'}")
        for option, instead in (("offline", "offline"), ("model_file", "model")):
            if option in given:
                problems.append(f"{key}.updater_options.{option}: give it as the site's "
                                f"{instead} = \"...\" (a path)")
        try:
            if site.model is not None:
                load_model(site.model)
            if site.offline is not None:
                read_history(site.offline)
        except UpdaterError as exc:
            problems.append(f"{key}.{'model' if site.model is not None else 'offline'}: {exc}")
    return cfg.model_copy(update={"sites": sites}), problems


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
