"""The step path's compiled modules: which they are, whether a build of them is stale, and how
to run their pure sources instead.

``pip install -e .`` (``make demo``/``make test``) compiles the modules in ``COMPILED`` with
mypyc (``setup.py``): the same source, as C extensions next to it. Python imports an extension
before the ``.py`` beside it, so a source edited after the build would be silently ignored;
``stale()`` finds such modules by the digest of each source recorded at the build
(``MANIFEST``; modification times would not do: a wheel's install writes sources and extensions
in no particular order), ``fresco-bridge`` warns at start, a test fails, the Makefile rebuilds
first. ``FRESCO_BRIDGE_PURE=1``: at install, nothing is compiled; at run time, the
pure sources are imported even where extensions are built (``use_pure_sources``, installed by
``fresco_bridge/__init__.py`` before anything else of ours is imported).

Standard library only, and importable as a plain file: ``setup.py`` reads it before anything
is installed.
"""

from __future__ import annotations

import hashlib
import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

# Paths relative to the repository root, roughly in the order of a step (transport → reply →
# record). Left interpreted on purpose: ``site_output.py`` (``CommittedStep`` is subclassed and
# sets its slots through descriptors, which a native class lacks), ``controls/sim.py`` and
# ``sim_actuator/models/`` (base classes of every controller kind and law, shared with the numba
# drives), ``indicators.py`` (runs per batch, not per step), ``record/syncer.py`` (a compiled
# ``threading.Thread`` subclass crashed the garbage collector). Figures: ``BENCHMARKS.md``,
# "Step cost and scaling".
COMPILED: tuple[str, ...] = (
    "protocol/_buffer.py",
    "protocol/wire.py",
    "protocol/events.py",
    "protocol/element.py",
    "fresco_bridge/eager.py",
    "fresco_bridge/server/connection.py",
    "fresco_bridge/server/handlers.py",
    "fresco_bridge/sites/gate.py",
    "fresco_bridge/sites/experimental.py",
    "fresco_bridge/sites/core.py",
    "fresco_bridge/sites/guard.py",
    "fresco_bridge/safety/limits.py",
    "fresco_bridge/record/site.py",
    "fresco_bridge/record/lines.py",
    "fresco_bridge/record/writer.py",
    "fresco_bridge/telemetry/taps.py",
)

GROUP = "fresco_bridge._step_path"
"""mypyc's shared library: ``fresco_bridge/_step_path__mypyc*.so`` (in the package, one stable
name: an editable install finds it whatever the list above)."""

MANIFEST = "fresco_bridge/_step_path.sources"
"""Written by the build next to the shared library: the sha256 of each source it compiled."""

PACKAGES = ("protocol", "fresco_bridge", "sim_actuator")
ROOT = Path(__file__).resolve().parent.parent
REBUILD = "make build (or: .venv/bin/pip install -e .)"
PURE_ENV = "FRESCO_BRIDGE_PURE"


def pure_requested() -> bool:
    """``FRESCO_BRIDGE_PURE`` is set (and not ``0``)."""
    return os.environ.get(PURE_ENV, "") not in ("", "0")


def module_name(source: str) -> str:
    return source.removesuffix(".py").replace("/", ".")


def extension(source: Path) -> Path | None:
    """The extension module built next to *source*, if any."""
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = source.with_name(source.stem + suffix)
        if candidate.exists():
            return candidate
    return None


def built_extensions(root: Path = ROOT) -> list[Path]:
    """Every extension module under our packages (a build's output, current or not)."""
    suffixes = tuple(importlib.machinery.EXTENSION_SUFFIXES)
    return sorted(path for package in PACKAGES if (root / package).is_dir()
                  for path in (root / package).rglob("*.so") if path.name.endswith(suffixes))


def _shared_library(path: Path, root: Path) -> bool:
    return path.parent == root / GROUP.rpartition(".")[0] and path.name.startswith(
        GROUP.rpartition(".")[2] + "__mypyc")


def source_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_manifest(root: Path = ROOT, sources: Sequence[str] = COMPILED) -> None:
    """Record the digest of each source about to be compiled (the build, ``setup.py``)."""
    (root / MANIFEST).write_text("".join(f"{source_digest(root / source)}  {source}\n"
                                         for source in sources))


def _manifest(root: Path) -> dict[str, str]:
    try:
        text = (root / MANIFEST).read_text()
    except OSError:
        return {}
    return {source: digest for digest, _, source in
            (line.partition("  ") for line in text.splitlines())}


def stale(root: Path = ROOT, sources: Sequence[str] = COMPILED) -> list[str]:
    """Modules whose extension would run code that is not their source: the source is not
    the one the build compiled (``MANIFEST``), or the module is no longer in ``COMPILED`` (an
    old build left behind)."""
    found = []
    listed = {root / source for source in sources}
    built = _manifest(root)
    for source in sources:
        path = root / source
        if extension(path) is not None and path.exists() and \
                built.get(source) != source_digest(path):
            found.append(module_name(source))
    for ext in built_extensions(root):
        origin = ext.with_name(ext.name.split(".", 1)[0] + ".py")
        if origin not in listed and not _shared_library(ext, root):
            found.append(module_name(str(origin.relative_to(root))) + " (not in the list)")
    return found


def stale_message(modules: Sequence[str]) -> str:
    return (f"stale compiled module(s) {', '.join(modules)}: the source changed after the "
            f"build, so Python would run the OLD compiled code. Rebuild: {REBUILD}")


def compiled_modules(sources: Sequence[str] = COMPILED) -> dict[str, bool]:
    """Import each listed module: ``{name: runs compiled}``."""
    result = {}
    for source in sources:
        name = module_name(source)
        module = importlib.import_module(name)
        result[name] = not (module.__file__ or "").endswith(".py")
    return result


class PureSourceFinder(importlib.abc.MetaPathFinder):
    """Finds the ``.py`` source of each listed module, ahead of its extension."""

    def __init__(self, root: Path = ROOT, sources: Sequence[str] = COMPILED) -> None:
        self._paths = {module_name(source): root / source for source in sources}

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        source = self._paths.get(fullname)
        if source is None or not source.exists():
            return None
        return importlib.util.spec_from_file_location(fullname, source)


def use_pure_sources() -> None:
    """Import the pure sources of the compiled modules from now on (idempotent). Raises
    RuntimeError when one of them was already imported from its extension."""
    if any(isinstance(finder, PureSourceFinder) for finder in sys.meta_path):
        return
    already = [name for name in map(module_name, COMPILED)
               if name in sys.modules and not (sys.modules[name].__file__ or "").endswith(".py")]
    if already:
        raise RuntimeError(f"{PURE_ENV} is set, but {', '.join(already)} was imported "
                           "compiled first: import fresco_bridge before protocol")
    sys.meta_path.insert(0, PureSourceFinder())
