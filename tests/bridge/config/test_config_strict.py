"""Strict config: every number finite, every value its exact type, allowlists explicit and
valid, a non-UTF-8 file named in a clear error.

The finiteness test walks every float and int field of every config model (bridge, record,
telemetry, site, limits and each controller kind), so a field added later is covered too.
"""

from __future__ import annotations

import math
import types
import typing
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel

from fresco_bridge.cli import main as cli_main
from fresco_bridge.config import (
    BridgeConfig,
    ConfigError,
    RecordConfig,
    TelemetryConfig,
    load_config,
    parse_config,
)
from fresco_bridge.controls.generic_tcp import GenericTcpControllerConfig
from fresco_bridge.controls.modbus import ModbusControllerConfig
from fresco_bridge.controls.mts import MtsControllerConfig
from fresco_bridge.controls.rig import RigControllerConfig
from fresco_bridge.safety import ControlPointLimitsConfig
from fresco_bridge.sites.experimental_kind import ExperimentalSiteConfig

SITE = '[[sites]]\nname = "s"\nport = 0\n'


def _toml(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return repr(value)


def _numeric_fields(model: type[BaseModel]) -> list[tuple[str, type]]:
    out = []
    for name, field in model.model_fields.items():
        ann = field.annotation
        args = typing.get_args(ann) if isinstance(ann, types.UnionType) or typing.get_origin(
            ann) is typing.Union else (ann,)
        for t in (float, int):
            if t in args:
                out.append((name, t))
                break
    return out


# (model, TOML table header, keys that make the table valid apart from the field under test)
TABLES: list[tuple[type[BaseModel], str, str]] = [
    (BridgeConfig, "[bridge]", ""),
    (RecordConfig, "[record]", ""),
    (TelemetryConfig, "[telemetry]", ""),
    (ExperimentalSiteConfig, "", ""),
    (ControlPointLimitsConfig, "[[sites.limits]]", "disp_max = 10.0\nvelocity = 5.0\n"),
    (ModbusControllerConfig, "[sites.controller]", 'kind = "modbus"\n'),
    (MtsControllerConfig, "[sites.controller]", 'kind = "mts"\n'),
    (RigControllerConfig, "[sites.controller]", 'kind = "rig"\npreset = "ideal"\n'),
    (GenericTcpControllerConfig, "[sites.controller]", 'kind = "generic-tcp"\n'),
]
CASES = [(model, header, base, name, t) for model, header, base in TABLES
         for name, t in _numeric_fields(model)]


def _config(model: type[BaseModel], header: str, base: str, key: str, value: Any) -> str:
    line = f"{key} = {_toml(value)}\n"
    base = "".join(b + "\n" for b in base.splitlines() if b.split(" = ")[0] != key)
    if model is ExperimentalSiteConfig:
        return SITE.replace("port = 0\n", "") + ("port = 0\n" if key != "port" else "") + line
    if "sites" in header:
        return SITE + header + "\n" + base + line
    return header + "\n" + base + line + SITE


@pytest.mark.parametrize(("model", "header", "base", "key", "kind"), CASES,
                         ids=[f"{m.__name__}.{k}" for m, _, _, k, _ in CASES])
def test_every_numeric_value_is_finite_and_of_its_type(
    model: type[BaseModel], header: str, base: str, key: str, kind: type
) -> None:
    bad_values: list[Any] = [math.nan, math.inf, -math.inf, "1"]
    if kind is int:
        bad_values.append(1.5)
    for bad in bad_values:
        with pytest.raises(ConfigError) as err:
            parse_config(_config(model, header, base, key, bad), "lab.toml")
        assert key in str(err.value) and str(err.value).startswith("lab.toml: "), str(err.value)


def test_the_walk_covers_the_limits_the_issue_names() -> None:
    keys = {k for m, *_ in TABLES if m is ControlPointLimitsConfig
            for k, _ in _numeric_fields(m)}
    assert {"disp_min", "disp_max", "force_min", "force_max", "velocity"} <= keys
    assert ("BridgeConfig", "session_idle_timeout") in {(m.__name__, k) for m, _, _, k, _ in
                                                        CASES}


def test_a_nan_limit_alone_is_refused_by_check(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "lab.toml"
    path.write_text(SITE + "[[sites.limits]]\ndisp_max = nan\n", encoding="utf-8")
    assert cli_main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: " in err and "disp_max" in err and "finite" in err


def test_a_nan_sim_parameter_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"params\.k.*finite"):
        parse_config(SITE + '[sites.controller]\nmodel = "elastic"\nparams = { k = nan }\n')


@pytest.mark.parametrize(("text", "key"), [
    ('[[sites]]\nname = "s"\nport = "19050"\n', "port"),
    ('[bridge]\nhost = "localhost"\n' + SITE, "bridge.host"),
    ('[bridge]\nmax_data_size = "4096"\n' + SITE, "max_data_size"),
    ('[record]\nenabled = "yes"\n' + SITE, "enabled"),
    ('[telemetry]\nmetrics_host = "example.org"\n' + SITE, "metrics_host"),
    ('[[sites]]\nname = "s"\nport = 0\ndofs = 1.0\n', "dofs"),
])
def test_values_must_have_their_exact_type(text: str, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_config(text, "lab.toml")
    assert key in str(err.value)


def test_an_empty_allowlist_needs_allow_any_client() -> None:
    with pytest.raises(ConfigError, match=r"bridge\.allowed_clients = \[\].*allow_any_client"):
        parse_config('[bridge]\nhost = "0.0.0.0"\nallowed_clients = []\n' + SITE)
    with pytest.raises(ConfigError, match=r"sites\[0\]\.allowed_clients"):
        parse_config(SITE + "allowed_clients = []\n")
    cfg = parse_config("[bridge]\nallowed_clients = []\nallow_any_client = true\n" + SITE)
    assert cfg.bridge.allowed_clients == [] and cfg.bridge.allow_any_client


@pytest.mark.parametrize("entry", ["not-an-ip", "localhost", "256.1.1.1", "10.0.0.1/33",
                                   "10.0.0.1/24", "::1", ""])
def test_invalid_allowlist_entries_are_errors(entry: str) -> None:
    for where in ("[bridge]\nallowed_clients = [\"{e}\"]\n" + SITE,
                  SITE + "allowed_clients = [\"{e}\"]\n"):
        with pytest.raises(ConfigError, match="allowed_clients"):
            parse_config(where.format(e=entry))


def test_networks_are_valid_allowlist_entries() -> None:
    cfg = parse_config('[bridge]\nallowed_clients = ["192.168.1.0/24", "10.0.0.7"]\n' + SITE)
    assert cfg.bridge.allowed_clients == ["192.168.1.0/24", "10.0.0.7"]


def test_a_non_utf8_file_is_a_clear_error(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "lab.toml"
    path.write_bytes(SITE.encode() + b'# caf\xe9 (latin-1)\n')
    with pytest.raises(ConfigError, match=r"lab\.toml: not UTF-8 .*0xe9 at line 4"):
        load_config(path)
    assert cli_main(["check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "UTF-8" in err and "Traceback" not in err


def test_secrets_never_show_in_a_repr() -> None:
    cfg = parse_config('[telemetry]\nmqtt_host = "127.0.0.1"\nusername = "u"\n'
                       'password = "hunter2-secret"\n' + SITE)
    assert "hunter2-secret" not in repr(cfg) and "hunter2-secret" not in str(cfg.telemetry)
