"""The diagnosis package holds what ``diagnose`` runs, and reads one way down.

The bench generators live in ``benchmarks/diagnosis`` and the product never imports them (the
``diagnose-bench`` command loads them by name only when it runs); no module of the diagnosis,
of the report's figures or of ``lawfit`` imports another module's private name.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
PRODUCT = ROOT / "fresco_bridge"
GENERATORS = ("bench", "synth", "realism", "independent", "independent_laws")


def _imports(path: Path) -> list[tuple[str, list[str], int]]:
    """(module as written, names, level) of every import in ``path``."""
    out: list[tuple[str, list[str], int]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            out.append((node.module or "", [a.name for a in node.names], node.level))
        elif isinstance(node, ast.Import):
            out.extend((a.name, [], 0) for a in node.names)
    return out


def test_the_product_imports_no_bench_generator() -> None:
    offenders = []
    for path in sorted(PRODUCT.rglob("*.py")):
        for module, names, level in _imports(path):
            if module.startswith("benchmarks") or (
                    level and module.split(".")[-1] in GENERATORS
                    and "diagnosis" in path.parts):
                offenders.append(f"{path.relative_to(ROOT)}: {module} {names}")
    assert offenders == []
    assert not any((PRODUCT / "diagnosis" / f"{name}.py").exists() for name in GENERATORS)


def test_diagnose_runs_without_the_generators_loaded() -> None:
    code = ("import sys\n"
            "import fresco_bridge.diagnosis.verdict, fresco_bridge.diagnosis.cli\n"
            "import fresco_bridge.diagnosis.multi, fresco_bridge.diagnosis.outputs\n"
            "print(sorted(m for m in sys.modules if m.startswith('benchmarks')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def test_no_private_name_crosses_a_module() -> None:
    paths = [*sorted((PRODUCT / "diagnosis").glob("*.py")), PRODUCT / "lawfit.py",
             PRODUCT / "element_history.py", PRODUCT / "report" / "figures.py",
             PRODUCT / "report" / "diagnosis.py"]
    offenders = [f"{path.relative_to(ROOT)}: from {'.' * level}{module} import {name}"
                 for path in paths for module, names, level in _imports(path)
                 for name in names if name.startswith("_") and not name.startswith("__")]
    assert offenders == []
