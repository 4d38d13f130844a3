"""fresco_bridge uses aiomqtt and paho-mqtt through their public API only.

Their private members change without notice (aiomqtt's maintainers will not expose its paho
client: empicano/aiomqtt#191), so code reaching one breaks silently at the next upgrade. Two
checks over ``fresco_bridge/``'s sources: no private name imported from either library; and a
module that imports either touches no ``_private`` attribute except through ``self``/``cls``
(its own). A third, plain text one catches the internals the batched telemetry once used,
wherever they would come back.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import fresco_bridge

LIBRARIES = ("aiomqtt", "paho")
PACKAGE = Path(fresco_bridge.__file__).parent
KNOWN_INTERNALS = re.compile(
    r"\._client\._|\._sock\b|_sock_close|_packet_queue|_out_packet|_disconnected\b"
    r"|paho\.mqtt\.client\._|aiomqtt\._"
)
"""paho's socket and packet queue, aiomqtt's paho client and futures (the old code's)."""


def _sources() -> list[tuple[Path, ast.Module]]:
    return [(p, ast.parse(p.read_text(), str(p))) for p in sorted(PACKAGE.rglob("*.py"))]


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _library_imports(tree: ast.Module) -> list[tuple[str, list[str]]]:
    """(module, imported names) of every import of aiomqtt or paho in ``tree``."""
    out: list[tuple[str, list[str]]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.split(".")[0] in LIBRARIES]
        elif isinstance(node, ast.ImportFrom) and node.module is not None \
                and node.level == 0 and node.module.split(".")[0] in LIBRARIES:
            out.append((node.module, [a.name for a in node.names]))
    return out


def _others_private(tree: ast.Module) -> list[ast.Attribute]:
    """Every ``x._name`` in ``tree`` whose ``x`` is not ``self`` or ``cls``."""
    return [node for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and _private(node.attr)
            and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))]


def _private_imports(tree: ast.Module) -> list[str]:
    return [f"{module}: {name}" for module, names in _library_imports(tree)
            for name in [*module.split(".")[1:], *names] if _private(name)]


def test_the_scan_sees_the_telemetry_module() -> None:
    users = [p.name for p, tree in _sources() if _library_imports(tree)]
    assert "mqtt.py" in users  # else the checks below would pass on nothing


def test_no_private_name_is_imported_from_aiomqtt_or_paho() -> None:
    offences = [f"{p.relative_to(PACKAGE)}: {bad}" for p, tree in _sources()
                 for bad in _private_imports(tree)]
    assert not offences, offences


def test_modules_using_aiomqtt_or_paho_touch_only_their_own_private_members() -> None:
    offences = [f"{p.relative_to(PACKAGE)}:{node.lineno}: {ast.unparse(node)}"
                 for p, tree in _sources() if _library_imports(tree)
                 for node in _others_private(tree)]
    assert not offences, offences


def test_no_source_names_the_internals_the_batched_telemetry_used() -> None:
    offences = [
        f"{p.relative_to(PACKAGE)}:{n}: {line.strip()}"
        for p in sorted(PACKAGE.rglob("*.py"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if KNOWN_INTERNALS.search(line)
    ]
    assert not offences, offences


def test_the_checks_catch_what_the_old_code_did() -> None:
    """The rules, on lines the old batched telemetry held: each is caught."""
    old = ast.parse("import aiomqtt\n"
                    "from paho.mqtt.client import _OutPacket\n"
                    "def f(client, paho):\n"
                    "    client._client._sock_close()\n"
                    "    paho._packet_queue(3, b'', 0, 0)\n")
    assert _private_imports(old) == ["paho.mqtt.client: _OutPacket"]
    reached = {ast.unparse(n) for n in _others_private(old)}
    assert reached >= {"client._client", "paho._packet_queue"}
    assert KNOWN_INTERNALS.search("client._client._sock_close()")
    assert KNOWN_INTERNALS.search("rc = paho._packet_queue(PUBLISH, data, 0, 0, info)")
