"""The one base of every lab-config model, and the typed values the config shares.

Strict on purpose (a lab config drives hydraulics): unknown keys are errors, every value must
already have its TOML type (``port = "19050"`` is an error, not a port), no float may be NaN or
infinite (TOML allows ``nan`` and ``inf``: a NaN limit would switch the limit off), and
addresses are dotted IPv4 (what OpenSees clients speak). Secrets are ``SecretStr``: they never
show in a repr, a log line or the run directory's config snapshot (``secret_values``).
"""

from __future__ import annotations

import ipaddress
import re
import tomllib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, SecretStr


class ConfigError(ValueError):
    """A configuration problem, already phrased for the user (file, key, reason)."""


Name = Annotated[str, Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]
"""A site's or a run's name (a file name, a topic level, a record key)."""


class StrictConfig(BaseModel):
    """Base of every config model: exact types, finite numbers, no unknown keys, frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


ConfigPath = Annotated[Path, Field(strict=False)]
"""A file path (TOML has no path type: a string is read as a path)."""


def _dotted_ipv4(value: str) -> str:
    try:
        return str(ipaddress.IPv4Address(value))
    except ValueError:
        raise ValueError(f"not a dotted IPv4 address (e.g. 127.0.0.1); host names are not "
                         f"resolved here: {value!r}") from None


def _ipv4_or_network(value: str) -> str:
    try:
        if "/" in value:
            return str(ipaddress.IPv4Network(value, strict=True))
        return str(ipaddress.IPv4Address(value))
    except ValueError as exc:
        raise ValueError(f"not a dotted IPv4 address or network (e.g. 192.168.1.20 or "
                         f"192.168.1.0/24): {value!r} ({exc})") from None


IPv4Address = Annotated[str, AfterValidator(_dotted_ipv4)]
"""A dotted IPv4 address (bind addresses)."""
ClientAddress = Annotated[str, AfterValidator(_ipv4_or_network)]
"""An allowed client: a dotted IPv4 address or an IPv4 network in CIDR notation."""

REDACTED = "<redacted>"


def secret_values(model: BaseModel) -> Iterator[tuple[str, str]]:
    """``(dotted key, value)`` of every ``SecretStr`` set anywhere in ``model``."""

    def walk(obj: Any, path: str) -> Iterator[tuple[str, str]]:
        if isinstance(obj, SecretStr):
            yield path, obj.get_secret_value()
        elif isinstance(obj, BaseModel):
            for name in type(obj).model_fields:
                yield from walk(getattr(obj, name), f"{path}.{name}" if path else name)
        elif isinstance(obj, list | tuple):
            for i, item in enumerate(obj):
                yield from walk(item, f"{path}[{i}]")
        elif isinstance(obj, dict):
            for k, item in obj.items():
                yield from walk(item, f"{path}.{k}")

    yield from walk(model, "")


_TOML_STRING = re.compile(r'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'')


def redact_config_text(text: str, secrets: Iterable[str]) -> str:
    """``text`` with every TOML string whose value is one of ``secrets`` replaced by
    ``"<redacted>"`` (comments and layout kept). Whatever still shows a secret after that (a
    secret written in a comment, say) loses its line; if the result no longer parses, only a
    note stays. Never returns a text that contains a secret."""
    hidden = {s for s in secrets if s}
    if not hidden:
        return text

    def swap(m: re.Match[str]) -> str:
        try:
            value = tomllib.loads(f"v = {m.group(0)}")["v"]
        except tomllib.TOMLDecodeError:
            return m.group(0)
        return f'"{REDACTED}"' if value in hidden else m.group(0)

    out = _TOML_STRING.sub(swap, text)
    if any(s in out for s in hidden):
        out = "".join(line if not any(s in line for s in hidden)
                      else "# (line withheld: it contained a secret)\n"
                      for line in out.splitlines(keepends=True))
    try:
        tomllib.loads(out)
    except tomllib.TOMLDecodeError:
        return "# config snapshot withheld: its secrets could not be redacted from the text\n"
    return out
