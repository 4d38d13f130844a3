"""The compiled step path (setup.py, ``fresco_bridge/_compiled.py``): what is installed really is
compiled (or, with ``FRESCO_BRIDGE_PURE=1``, really pure), no build is stale, a pure build
compiles nothing and removes old extensions, and the compiled sources avoid the three mypyc
pitfalls found when they were compiled (BENCHMARKS.md, "Step cost and scaling")."""

from __future__ import annotations

import ast
import importlib.machinery
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fresco_bridge import _compiled
from fresco_bridge.cli import main as cli_main
from tests.support.paths import REPO

EXT = importlib.machinery.EXTENSION_SUFFIXES[0]


def test_the_step_path_runs_as_installed() -> None:
    """Compiled in the default install (a silent fall back to pure Python in CI fails here);
    pure under ``FRESCO_BRIDGE_PURE=1`` (``make test`` runs this file in both modes)."""
    compiled = _compiled.compiled_modules()
    if _compiled.pure_requested():
        assert not any(compiled.values()), f"FRESCO_BRIDGE_PURE=1 but compiled: {compiled}"
    else:
        pure = [name for name, is_compiled in compiled.items() if not is_compiled]
        assert not pure, (
            f"{pure} run as pure Python: the install did not compile the step path (no C "
            f"compiler? mypyc failed? see the pip output); {_compiled.REBUILD}, or run the "
            "tests with FRESCO_BRIDGE_PURE=1 on a deliberately pure install")


def test_the_pure_switch_runs_every_listed_source() -> None:
    """``FRESCO_BRIDGE_PURE=1`` at run time imports the ``.py`` of every compiled module."""
    code = ("from fresco_bridge import _compiled; import fresco_bridge.daemon; "
            "print(sorted(n for n, c in _compiled.compiled_modules().items() if c))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "FRESCO_BRIDGE_PURE": "1"}, check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


def test_no_compiled_module_is_stale() -> None:
    stale = _compiled.stale()
    assert not stale, _compiled.stale_message(stale)


def test_stale_names_an_edited_source_and_a_module_left_off_the_list(tmp_path: Path) -> None:
    """By content, not by time: an edit is stale, and stays so however new the extension is;
    an edit undone is not (a wheel's install writes sources and extensions in any order)."""
    files = {"fresco_bridge/fresh.py": "a = 1\n", "fresco_bridge/edited.py": "b = 1\n",
             "protocol/dropped.py": "c = 1\n"}
    for source, text in files.items():
        (tmp_path / source).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / source).write_text(text)
        (tmp_path / source).with_suffix(EXT).write_text("")
    (tmp_path / "fresco_bridge" / f"_step_path__mypyc{EXT}").write_text("")  # the shared library
    listed = ("fresco_bridge/fresh.py", "fresco_bridge/edited.py")
    _compiled.write_manifest(tmp_path, listed)
    assert _compiled.stale(tmp_path, listed) == ["protocol.dropped (not in the list)"]
    (tmp_path / "fresco_bridge" / "edited.py").write_text("b = 2\n")
    (tmp_path / "fresco_bridge" / f"edited{EXT}").touch()  # newer than the edit: still stale
    stale = _compiled.stale(tmp_path, listed)
    assert stale == ["fresco_bridge.edited", "protocol.dropped (not in the list)"]
    message = _compiled.stale_message(stale)
    assert "fresco_bridge.edited" in message and "make build" in message
    (tmp_path / "fresco_bridge" / "edited.py").write_text("b = 1\n")  # the edit undone
    assert _compiled.stale(tmp_path, listed) == ["protocol.dropped (not in the list)"]
    (tmp_path / _compiled.MANIFEST).unlink()  # a build without digests: every module stale
    assert _compiled.stale(tmp_path, listed)[:2] == ["fresco_bridge.fresh",
                                                     "fresco_bridge.edited"]


def test_the_cli_warns_at_start_about_a_stale_build(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(_compiled, "stale", lambda: ["protocol.element"])
    assert cli_main(["check", "--config", str(tmp_path / "missing.toml")]) != 0
    err = capsys.readouterr().err
    assert "WARNING: stale compiled module(s) protocol.element" in err
    assert "make build" in err


def _build_tree(tmp_path: Path) -> Path:
    """The sources and build files, with two old extensions, as a clone would have them."""
    tree = tmp_path / "tree"
    ignore = shutil.ignore_patterns("*.so", "__pycache__")
    for package in _compiled.PACKAGES:
        shutil.copytree(REPO / package, tree / package, ignore=ignore)
    for name in ("setup.py", "pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, tree / name)
    (tree / "protocol" / f"element{EXT}").write_bytes(b"old build")
    (tree / "fresco_bridge" / f"_step_path__mypyc{EXT}").write_bytes(b"old build")
    return tree


@pytest.mark.parametrize("why", ["pure", "no-mypyc", "no-compiler"])
def test_a_pure_build_compiles_nothing_and_removes_old_extensions(
        tmp_path: Path, why: str) -> None:
    tree = _build_tree(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "FRESCO_BRIDGE_PURE"}
    run = "import sys; sys.argv = ['setup.py', 'build_ext', '--inplace']; "
    if why == "pure":
        env["FRESCO_BRIDGE_PURE"] = "1"
    elif why == "no-mypyc":
        run += "sys.modules['mypyc'] = None; "  # import mypyc.build fails
    else:
        env["CC"] = str(tmp_path / "no-such-cc")
    run += ("exec(compile(open('setup.py').read(), 'setup.py', 'exec'), "
            "{'__file__': 'setup.py', '__name__': '__main__'})")
    out = subprocess.run([sys.executable, "-c", run], capture_output=True, text=True, env=env,
                         cwd=tree, timeout=120)
    assert out.returncode == 0, out.stderr
    expected = {"pure": "FRESCO_BRIDGE_PURE is set", "no-mypyc": "mypyc is not available",
                "no-compiler": "no C compiler"}[why]
    assert f"fresco-bridge build: {expected}" in out.stderr
    assert "installing pure Python" in out.stderr
    assert _compiled.built_extensions(tree) == []


def _compiled_trees() -> list[tuple[str, ast.Module]]:
    return [(source, ast.parse((REPO / source).read_text(), source))
            for source in _compiled.COMPILED]


def test_no_slice_bound_of_a_compiled_module_has_a_side_effect() -> None:
    """mypyc 2.4.1 evaluates a slice bound twice when slicing a memoryview (or any type it
    does not specialise): ``view[os.write(fd, view):]`` wrote the rest of a short write
    twice. Calls stay out of slice bounds in compiled code."""
    found = []
    for source, tree in _compiled_trees():
        for node in ast.walk(tree):
            if isinstance(node, ast.Slice):
                for bound in (node.lower, node.upper, node.step):
                    if bound is not None and any(isinstance(n, ast.Call | ast.Await | ast.Yield
                                                            | ast.NamedExpr)
                                                 for n in ast.walk(bound)):
                        found.append(f"{source}:{node.lineno}: {ast.unparse(bound)}")
    assert not found, found


def test_no_compiled_class_derives_from_a_thread() -> None:
    """A compiled ``threading.Thread`` subclass crashed the garbage collector (the record's
    syncer lives in the pure ``record/syncer.py`` for that reason)."""
    found = [f"{source}:{node.lineno}: {node.name}"
             for source, tree in _compiled_trees() for node in ast.walk(tree)
             if isinstance(node, ast.ClassDef)
             and any("Thread" in ast.unparse(base) for base in node.bases)]
    assert not found, found


def test_no_compiled_coroutine_awaits_in_a_finally_block() -> None:
    """mypyc 2.4.1: in a compiled coroutine awaited by another, an exception raised by an
    ``await`` inside a ``finally`` block escapes the handlers inside that block (a cancelled
    recovery probe's CancelledError ended the integrator's request instead of being
    suppressed). Such cleanup goes in ``except BaseException: ...; raise`` plus the normal
    path (``sites/guard.py``, ``_drop``)."""
    found = []
    for source, tree in _compiled_trees():
        for node in ast.walk(tree):
            if isinstance(node, ast.Try | ast.TryStar):
                found += [f"{source}:{n.lineno}: {ast.unparse(n)}"
                          for stmt in node.finalbody for n in ast.walk(stmt)
                          if isinstance(n, ast.Await | ast.AsyncWith | ast.AsyncFor)]
    assert not found, found
