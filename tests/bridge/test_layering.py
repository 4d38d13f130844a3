"""Dependencies run one way: the numerics below (``lawfit``, ``updating``, ``diagnosis``,
``integrator``) import nothing from the study above them, and these packages import each other
without a cycle, counting imports inside functions too (a lazy import hides a cycle, it does
not remove it)."""

from __future__ import annotations

import ast
from pathlib import Path

import fresco_bridge

ROOT = Path(fresco_bridge.__file__).parent
PACKAGES = ("lawfit", "updating", "study", "diagnosis", "integrator")
BELOW_THE_STUDY = ("lawfit", "updating", "diagnosis", "integrator")


def _unit(module: str) -> str | None:
    """The package of ``PACKAGES`` that ``fresco_bridge.<module>`` belongs to."""
    head = module.split(".")[0]
    return head if head in PACKAGES else None


def _imports() -> dict[str, set[str]]:
    """Package -> the packages of ``PACKAGES`` its modules import (anywhere in the module)."""
    edges: dict[str, set[str]] = {name: set() for name in PACKAGES}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        source = _unit(".".join(parts))
        if source is None:
            continue
        package = parts[:-1]  # a module's package; an __init__'s is itself
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = list(package[: len(package) - (node.level - 1)])
                    targets = [".".join(["fresco_bridge", *base, *([node.module] if node.module
                                                                   else [])])]
                else:
                    targets = [node.module or ""]
                targets += [f"{targets[0]}.{a.name}" for a in node.names]
            for target in targets:
                if target.startswith("fresco_bridge."):
                    unit = _unit(target.removeprefix("fresco_bridge."))
                    if unit is not None and unit != source:
                        edges[source].add(unit)
    return edges


def test_nothing_below_the_study_imports_it() -> None:
    edges = _imports()
    assert {name: sorted(edges[name] & {"study"}) for name in BELOW_THE_STUDY} == {
        name: [] for name in BELOW_THE_STUDY}


def test_the_packages_import_each_other_without_a_cycle() -> None:
    edges = _imports()
    done: set[str] = set()

    def visit(name: str, path: tuple[str, ...]) -> None:
        assert name not in path, f"import cycle: {' -> '.join((*path, name))}"
        if name in done:
            return
        for other in sorted(edges[name]):
            visit(other, (*path, name))
        done.add(name)

    for name in PACKAGES:
        visit(name, ())
    assert edges["lawfit"] == set()  # the fitting home depends on none of its users
