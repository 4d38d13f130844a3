"""Dependencies run one way: no import cycle in ``fresco_bridge/``, between its modules or
between its layers (``ABOVE``: the intended direction), the protocol below everything.

Read from the sources with ``ast``, not from ``sys.modules``: every import counts, at module
level, inside a function, or under ``if TYPE_CHECKING:`` (a type-only cycle is still two
concepts that know each other, and a lazy import still runs the first time it is reached).
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.support.paths import REPO

ROOT = "fresco_bridge"
PROTOCOL = "protocol"
DAEMON = ("server", "sites", "telemetry", "twins", "daemon")
ABOVE: dict[str, tuple[str, ...]] = {
    # the numerics are testable alone
    "updating": DAEMON,
    "diagnosis": DAEMON,
    "integrator": DAEMON,
    # the daemon, bottom up: what a site hands its listeners, the record, telemetry (which
    # writes the monitors into the record), the sites, the transports serving them
    "site_output": ("record", "telemetry", *DAEMON),
    "record": ("telemetry", *DAEMON),
    "telemetry": ("sites", "twins", "server", "daemon"),
    "sites": ("twins", "server", "daemon"),
    # updatable sites: above the sites (their controller) and the updaters, below the daemon
    "twins": ("server", "daemon"),
}
"""``{layer: the layers above it}``, which it must not import (``fresco_bridge``'s)."""
IO_MODULES = ("asyncio", "socket", "selectors", "ssl")


@dataclass(frozen=True)
class Import:
    source: str
    target: str
    line: int

    def __str__(self) -> str:
        return f"{self.source} → {self.target} (line {self.line})"


def module_names(package: str) -> dict[str, Path]:
    """``{dotted name: file}`` of every module of *package* (a package is its ``__init__``)."""
    names = {}
    for path in sorted((REPO / package).rglob("*.py")):
        parts = path.relative_to(REPO).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names[".".join(parts)] = path
    return names


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(module: str, path: Path, known: Iterable[str]) -> list[Import]:
    """Every import in *path*, as the module it names: ``from a import b`` is ``a.b`` when that
    is a module, else ``a``."""
    known = set(known)
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [Import(module, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _absolute(module, path.name == "__init__.py", node)
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                found.append(Import(module, submodule if submodule in known else base,
                                    node.lineno))
    return list(dict.fromkeys(found))  # ``from a import b, c``: one import of ``a``


def import_graph(package: str) -> dict[str, list[Import]]:
    """``{module: its imports}`` for every module of *package*."""
    names = module_names(package)
    return {name: imports_of(name, path, names) for name, path in names.items()}


def layer(module: str) -> str:
    """The top-level module or subpackage of ``fresco_bridge`` that *module* belongs to."""
    parts = module.split(".")
    return ".".join(parts[:2])


def cycles(edges: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """A shortest cycle (``[a, b, …, a]``) through each strongly connected part of the
    directed graph *edges*: every tangle is named, not only the first one met."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    parts: list[set[str]] = []

    def connect(node: str) -> None:  # Tarjan's algorithm
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if nxt not in index:
                connect(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            part = {node}
            while (member := stack.pop()) != node:
                part.add(member)
            parts.append(part)

    for start in sorted(edges):
        if start not in index:
            connect(start)
    return sorted(_shortest_cycle(min(part), part, edges) for part in parts if len(part) > 1)


def _shortest_cycle(start: str, part: set[str], edges: Mapping[str, Iterable[str]]) -> list[str]:
    """Breadth first from *start* inside its strongly connected *part* until back at it."""
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for nxt in sorted(edges.get(node, ())):
                if nxt == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(came_from[path[-1]])
                    return [*reversed(path), start]
                if nxt in part and nxt not in came_from:
                    came_from[nxt] = node
                    following.append(nxt)
        frontier = following
    raise AssertionError(f"{start} is in a strongly connected part but on no cycle")


def _report(found: list[list[str]], why: Mapping[tuple[str, str], Import]) -> str:
    return "\n".join(" → ".join(cycle) + "\n  " + "\n  ".join(
        str(why[a, b]) for a, b in itertools.pairwise(cycle)) for cycle in found)


def _edges(why: Iterable[tuple[str, str]]) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for source, target in why:
        edges.setdefault(source, set()).add(target)
    return edges


def _internal(graph: Mapping[str, list[Import]]) -> list[Import]:
    return [imp for imports in graph.values() for imp in imports
            if imp.target in graph and imp.target != imp.source]


def module_imports(graph: Mapping[str, list[Import]]) -> dict[tuple[str, str], Import]:
    """``{(importer, imported): the first such import}`` between modules of the package."""
    why: dict[tuple[str, str], Import] = {}
    for imp in _internal(graph):
        why.setdefault((imp.source, imp.target), imp)
    return why


def layer_imports(graph: Mapping[str, list[Import]]) -> dict[tuple[str, str], Import]:
    """The same between layers; the package's own ``__init__`` (the pure-sources switch) is
    below every layer."""
    why: dict[tuple[str, str], Import] = {}
    for imp in _internal(graph):
        source, target = layer(imp.source), layer(imp.target)
        if source != target and ROOT not in (source, target):
            why.setdefault((source, target), imp)
    return why


def test_no_module_imports_itself_back() -> None:
    why = module_imports(import_graph(ROOT))
    found = cycles(_edges(why))
    assert not found, f"import cycles between modules:\n{_report(found, why)}"


def test_no_two_layers_import_each_other() -> None:
    """Between ``fresco_bridge``'s subpackages and top-level modules (``sites`` ↔ ``record``)."""
    why = layer_imports(import_graph(ROOT))
    found = cycles(_edges(why))
    assert not found, f"import cycles between layers:\n{_report(found, why)}"


def test_a_planted_cycle_is_found_and_named() -> None:
    """The two tests above can fail: each tangle is found, with a path through it."""
    assert cycles({"a": {"b"}, "b": {"c", "d"}, "c": {"a"}, "d": {"b"}, "e": {"a"}}) == [
        ["a", "b", "c", "a"]]
    assert cycles({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []
    assert cycles({"a": {"b"}, "b": {"a"}, "x": {"y"}, "y": {"x"}}) == [
        ["a", "b", "a"], ["x", "y", "x"]]
    graph = {f"{ROOT}.x": [Import(f"{ROOT}.x", f"{ROOT}.y.m", 3)],
             f"{ROOT}.y.m": [Import(f"{ROOT}.y.m", f"{ROOT}.x", 7)]}
    why = layer_imports(graph)
    found = cycles(_edges(why))
    assert found == [[f"{ROOT}.x", f"{ROOT}.y", f"{ROOT}.x"]]
    assert "fresco_bridge.y.m → fresco_bridge.x (line 7)" in _report(found, why)


def test_relative_imports_resolve_to_the_module_they_name() -> None:
    """``from . import x`` is the submodule ``x``; ``from ..a import B`` climbs from the
    importing module's package (a package's ``__init__`` is its own package)."""
    known = module_names(ROOT)
    cli = imports_of(f"{ROOT}.cli", REPO / ROOT / "cli.py", known)
    assert f"{ROOT}._compiled" in {imp.target for imp in cli}
    node = ast.parse("from ..record.writer import RecordWriter").body[0]
    assert isinstance(node, ast.ImportFrom)
    assert _absolute(f"{ROOT}.sites.gate", False, node) == f"{ROOT}.record.writer"
    assert _absolute(f"{ROOT}.sites", True, node) == f"{ROOT}.record.writer"
    node = ast.parse("from . import gate").body[0]
    assert isinstance(node, ast.ImportFrom)
    assert _absolute(f"{ROOT}.sites", True, node) == f"{ROOT}.sites"


def test_the_protocol_knows_no_bridge_and_does_no_io() -> None:
    """``protocol/`` encodes and decodes; sockets and event loops belong to its users."""
    bad = [imp for imports in import_graph(PROTOCOL).values() for imp in imports
           if imp.target.split(".")[0] in (ROOT, "sim_actuator", *IO_MODULES)]
    assert not bad, "protocol/ imports what it must not:\n  " + "\n  ".join(map(str, bad))


@pytest.mark.parametrize("below", sorted(ABOVE))
def test_a_layer_imports_nothing_above_it(below: str) -> None:
    """The intended direction, not only the absence of cycles (``ABOVE``)."""
    assert below not in ABOVE[below]
    above = {f"{ROOT}.{name}" for name in ABOVE[below]}
    bad = [imp for imports in import_graph(ROOT).values() for imp in imports
           if layer(imp.source) == f"{ROOT}.{below}" and layer(imp.target) in above]
    assert not bad, f"{below} imports from above it:\n  " + "\n  ".join(map(str, bad))
