"""Lab configuration (TOML), validated with pydantic; errors name the file, key and reason.

Units at this boundary: displacements mm, forces kN, stiffness kN/mm, mass kN·s²/mm, time s.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)

from sim_actuator.models import MODEL_PARAMETERS, ModelParameterError, make_model

from .controls.modbus import ModbusControllerConfig
from .controls.mts import MtsControllerConfig
from .controls.rig import RigControllerConfig
from .safety import ControlPointLimitsConfig

Name = Annotated[str, Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]


class ConfigError(ValueError):
    """A configuration problem, already phrased for the user (file, key, reason)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SimControllerConfig(_Strict):
    """In-process simulated specimen (one model per actuator)."""

    kind: Literal["sim"] = "sim"
    model: Literal["elastic", "bilinear", "bouc-wen", "bwbn"] = "bilinear"
    params: dict[str, float] = Field(
        default_factory=lambda: {"k0": 8.0, "fy": 12.0, "alpha": 0.05}
    )
    reset_on_new_session: bool = True
    """A new integrator connection starts from a virgin specimen (a simulation, not a lab)."""

    @model_validator(mode="after")
    def _params_fit_model(self) -> SimControllerConfig:
        try:
            make_model(self.model, **self.params)
        except ModelParameterError as exc:
            allowed = ", ".join(MODEL_PARAMETERS.get(self.model, {}))
            raise ValueError(f"{exc} (parameters of {self.model}: {allowed})") from None
        return self


def _controller_kind(v: Any) -> str:
    """``kind`` may be omitted for the default in-process simulated controller."""
    kind = v.get("kind", "sim") if isinstance(v, dict) else getattr(v, "kind", "sim")
    return str(kind)


ControllerConfig = Annotated[
    Annotated[SimControllerConfig, Tag("sim")]
    | Annotated[ModbusControllerConfig, Tag("modbus")]
    | Annotated[MtsControllerConfig, Tag("mts")]
    | Annotated[RigControllerConfig, Tag("rig")],
    Discriminator(_controller_kind),
]


class SiteConfig(_Strict):
    """One experimental site: a listener the integrator connects to, and its controller."""

    name: Name
    port: int = Field(ge=0, le=65535)
    """0 picks a free port (tests, demo); the chosen port is logged and printed."""
    transport: Literal["tcp", "udp"] = "tcp"
    protocol: Literal["element", "site"] = "element"
    """``element``: OpenSees genericClient / OpenFresco EE* clients; ``site``: ShadowExpSite."""
    dofs: int = Field(default=1, ge=1, le=64)
    """Number of basic DOFs of the element served (the -dof entries of genericClient)."""
    setup: Literal["NoTransformation", "OneActuator"] = "NoTransformation"
    controller: ControllerConfig = Field(default_factory=SimControllerConfig)
    """``sim`` (in-process specimen), ``modbus`` or ``mts`` (a controller over TCP)."""
    damping: list[list[float]] | None = None
    """n×n damping matrix in basic DOFs, row by row (answers action 14); default zero."""
    mass: list[list[float]] | None = None
    """n×n mass matrix in basic DOFs, row by row (answers action 15); default zero."""
    allowed_clients: list[str] | None = None
    """Client IPv4 addresses allowed to connect; default: the bridge-wide list."""
    actor_tag: int = 1
    """Tag this site reports to a ShadowExpSite (site protocol only)."""
    limits: list[ControlPointLimitsConfig] = Field(default_factory=list)
    """``[[sites.limits]]``, one per control point (actuator after the setup); default none."""

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
        n_act = self.dofs if self.setup == "NoTransformation" else 1
        if self.controller.kind != "sim" and n_act != 1:
            raise ValueError(
                f"controller {self.controller.kind} drives one actuator; this site needs {n_act} "
                "(use setup OneActuator or dofs = 1)"
            )
        if self.setup == "OneActuator" and self.dofs > 2:
            raise ValueError("setup OneActuator serves dofs = 1 or 2 (two nodes, -dof 1 -dof 1)")
        actuators = [lim.actuator for lim in self.limits]
        if any(a > n_act for a in actuators):
            raise ValueError(f"limits: actuator {max(actuators)} does not exist (setup "
                             f"{self.setup} with {self.dofs} DOF(s) drives {n_act} actuator(s))")
        if len(set(actuators)) != len(actuators):
            raise ValueError(f"limits: one [[sites.limits]] table per actuator; repeated: "
                             f"{sorted({a for a in actuators if actuators.count(a) > 1})}")
        return self


class BridgeConfig(_Strict):
    host: str = "127.0.0.1"
    """Bind address (IPv4: OpenSees clients only speak dotted IPv4)."""
    allowed_clients: list[str] = Field(default_factory=lambda: ["127.0.0.1"])
    max_data_size: int = Field(default=4096, ge=5, le=1_000_000)
    """Largest dataSize (doubles per vector) a client may announce."""
    controller_timeout: float = Field(default=5.0, gt=0)
    """Deadline in seconds for every controller call; past it the site goes to HOLD."""
    controller_recovery: float = Field(default=30.0, ge=0, allow_inf_nan=False)
    """Seconds a site in HOLD for a lost or silent controller keeps probing it inside the
    integrator's waiting request; back in time: the run continues, else the integrator is told
    to stop (NaN answers until its DIE).
    0: no recovery (HOLD answers NaN until the session ends, so the integrator stops)."""
    run_dir: Path = Path("runs")
    run_name: Name = "run"
    control_socket: Path | None = None
    """Operator control socket (``fresco-bridge ctl``); default ``control.sock`` in the run
    directory (no socket when recording is off unless this is set)."""


class RecordConfig(_Strict):
    enabled: bool = True
    fsync: Literal["background", "inline", "off"] = "background"


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
    password: str | None = None
    tls: bool = False
    """Connect to the broker over TLS, verifying its certificate (system CAs unless
    ``tls_ca_file``) and host name."""
    tls_ca_file: Path | None = None
    """PEM file of the CA(s) that signed the broker's certificate."""
    tls_cert_file: Path | None = None
    """PEM client certificate (with ``tls_key_file``), for brokers that authenticate clients."""
    tls_key_file: Path | None = None
    accept_commands: bool = False
    """Accept operator commands (pause/resume/abort) on ``<prefix>/<site>/cmd``; needs
    ``username``/``password`` and ``command_token`` (see README, threat model)."""
    command_token: str | None = None
    """Shared secret every command message must carry (at least 16 characters)."""
    monitor_dt: float = Field(default=0.01, gt=0)
    """Integration time step (s) the monitors assume for FEI frequencies and delays."""
    monitor_window: int = Field(default=512, ge=16)
    warn_tracking_error: float | None = Field(default=None, gt=0)
    """|measured − command| (mm) past which a ``monitor-warning`` event is raised."""
    monitors: bool = True
    """Run the online error monitors per committed step: published with MQTT telemetry and
    written to the run record (``monitor`` lines) when recording is on (~10 µs per step)."""
    metrics_port: int | None = Field(default=None, ge=0, le=65535)
    """Serve Prometheus ``/metrics`` on this port (off when unset; 0 picks a free port)."""
    metrics_host: str = "127.0.0.1"
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
        if self.command_token is None or len(self.command_token) < 16:
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


def _format_errors(source: str, exc: ValidationError) -> str:
    lines = [f"{source}: invalid configuration ({exc.error_count()} problem(s))"]
    for err in exc.errors():
        parts = list(err["loc"])
        parts = [p for i, p in enumerate(parts) if not (i and parts[i - 1] == "controller"
                                                         and p in ("sim", "modbus", "mts"))]
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in parts)
        loc = loc.replace(".[", "[")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown key (typo?)"
        elif err["type"] == "union_tag_invalid":
            msg = f"unknown controller kind {err['ctx']['tag']!r}; expected sim, modbus or mts"
        got = err.get("input")
        quiet = err["type"] in ("missing", "extra_forbidden") or isinstance(got, dict | list)
        shown = "" if quiet else f" (got {got!r})"
        lines.append(f"  {loc or '<top>'}: {msg}{shown}")
    return "\n".join(lines)


def parse_config(text: str, source: str = "<config>") -> LabConfig:
    """Parse TOML text; raise ConfigError with file, key and reason."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    try:
        return LabConfig.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(_format_errors(source, exc)) from None


def load_config(path: Path) -> tuple[LabConfig, str]:
    """Read and validate a config file; returns the model and the text (for the snapshot)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the configuration: {exc.strerror}") from None
    return parse_config(text, str(path)), text
