"""The keys every site kind shares: a listener, its transport and protocol, the basic DOFs,
the setup, the constant matrices, the allowlist, the limits, TLS (``[[sites]]``)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ..config_model import ClientAddress, ConfigPath, Name, StrictConfig
from ..safety import ControlPointLimitsConfig
from ..setups import SetupError, SetupSpec, make_setup

__all__ = ["SiteConfigBase"]


class SiteConfigBase(StrictConfig):
    """One ``[[sites]]`` entry: a listener the integrator connects to (every kind's keys)."""

    name: Name
    kind: str
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

    @field_validator("limits", mode="before")
    @classmethod
    def _single_limits_table(cls, v: Any) -> Any:
        """``[sites.limits]`` (one table, not an array) is the one control point's limits."""
        return [v] if isinstance(v, dict) else v

    @property
    def n_actuators(self) -> int:
        """The actuators (control points) the setup drives (``setups.py`` owns the count)."""
        return make_setup(self.setup, self.dofs).n_actuators

    @model_validator(mode="after")
    def _shared_keys_fit(self) -> SiteConfigBase:
        for key in ("damping", "mass"):
            m = getattr(self, key)
            if m is not None and (len(m) != self.dofs or any(len(r) != self.dofs for r in m)):
                n = self.dofs
                raise ValueError(f"{key} must be a {n}×{n} matrix (dofs = {n})")
        if self.setup == "OneActuator" and self.dofs > 2:
            raise ValueError("setup OneActuator serves dofs = 1 or 2 (two nodes, -dof 1 -dof 1)")
        try:
            n_act = self.n_actuators
        except SetupError as exc:
            raise ValueError(str(exc)) from None
        self.actuators_fit(n_act)
        actuators = [lim.actuator for lim in self.limits]
        if any(a > n_act for a in actuators):
            raise ValueError(f"limits: actuator {max(actuators)} does not exist (setup "
                             f"{self.setup} with {self.dofs} DOF(s) drives {n_act} actuator(s))")
        if len(set(actuators)) != len(actuators):
            raise ValueError(f"limits: one [[sites.limits]] table per actuator; repeated: "
                             f"{sorted({a for a in actuators if actuators.count(a) > 1})}")
        self._tls_fits()
        return self

    def actuators_fit(self, n_actuators: int) -> None:
        """Raise ``ValueError`` if this kind cannot serve ``n_actuators`` control points."""

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
