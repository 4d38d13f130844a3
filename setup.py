"""Build: the step path's modules compiled with mypyc (``fresco_bridge/_compiled.py`` lists them).

The same source runs compiled (the default install) or pure: with ``FRESCO_BRIDGE_PURE=1``, or
when mypyc or a C compiler is missing or fails, nothing is compiled and the install still
succeeds (a message says so). Every build first removes extensions it will not rebuild (a
pure install, a module taken off the list), so no old build shadows a source. What the
compiled step path saves: BENCHMARKS.md, "Step cost and scaling".
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
from pathlib import Path
from types import ModuleType

from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import BaseError, CCompilerError

HERE = Path(__file__).resolve().parent


def _compiled() -> ModuleType:
    # The list, loaded without importing the package (its dependencies may not be installed).
    spec = importlib.util.spec_from_file_location(
        "_fresco_bridge_compiled", HERE / "fresco_bridge" / "_compiled.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _say(text: str) -> None:
    print(f"fresco-bridge build: {text}", file=sys.stderr, flush=True)


def _remove_extensions(compiled: ModuleType, keep: bool) -> None:
    """Delete built extensions next to the sources, except (``keep``) the listed modules'."""
    wanted = {HERE / source for source in compiled.COMPILED} if keep else set()
    for ext in compiled.built_extensions(HERE):
        origin = ext.with_name(ext.name.split(".", 1)[0] + ".py")
        if origin not in wanted and not (keep and compiled._shared_library(ext, HERE)):
            _say(f"removing {ext.relative_to(HERE)} (not built now)")
            ext.unlink()


def _pure(compiled: ModuleType, why: str) -> list[object]:
    _say(f"{why}: installing pure Python (the step path runs slower; see docs/development.md)")
    _remove_extensions(compiled, keep=False)
    return []


def _extensions() -> list[object]:
    compiled = _compiled()
    if compiled.pure_requested():
        return _pure(compiled, "FRESCO_BRIDGE_PURE is set")
    try:
        from mypyc.build import mypycify
    except ImportError as exc:
        return _pure(compiled, f"mypyc is not available ({exc})")
    from setuptools._distutils.ccompiler import new_compiler
    from setuptools._distutils.sysconfig import customize_compiler

    cc = new_compiler()
    customize_compiler(cc)
    command = getattr(cc, "compiler", None) or ["cc"]
    if shutil.which(command[0]) is None:
        return _pure(compiled, f"no C compiler ({command[0]} not found)")
    _remove_extensions(compiled, keep=True)
    compiled.write_manifest(HERE)  # what is compiled, for the stale-build check
    os.chdir(HERE)  # mypyc takes the paths relative to the tree root
    try:
        return list(mypycify(list(compiled.COMPILED), opt_level="3",
                             group_name=compiled.GROUP))
    except (Exception, SystemExit) as exc:  # mypyc refused the source
        return _pure(compiled, f"mypyc failed ({exc!r}; it type-checks the sources against the "
                     "installed dependencies: install them first, as `make build` does)")


class BuildExt(build_ext):
    """Compile; if the C compiler fails, remove what was built and stay pure Python."""

    def run(self) -> None:
        try:
            super().run()
        except (CCompilerError, BaseError, OSError) as exc:
            self.extensions = []
            _pure(_compiled(), f"compiling the step path failed ({exc})")


setup(ext_modules=_extensions(), cmdclass={"build_ext": BuildExt})
