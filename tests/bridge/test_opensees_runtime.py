"""``fresco_bridge.opensees_runtime``: OpenSeesPy imports with no ``LD_LIBRARY_PATH`` set, and a
``genericClient`` port nobody listens on is said before OpenSees could crash on it."""

from __future__ import annotations

import ctypes.util
import importlib.util
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from fresco_bridge.opensees_runtime import (
    BridgeNotListening,
    OpenSeesUnavailable,
    _local_listeners,
    bundled_lib_dir,
    import_opensees,
    opensees_env,
    require_listening,
)
from tests.support.net import free_ports
from tests.support.paths import REPO

pytest.importorskip("openseespy")


def _python(code: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter with ``LD_LIBRARY_PATH`` unset (as a newcomer's shell)."""
    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    env["PYTHONPATH"] = str(REPO)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=120)


def test_import_opensees_finds_the_bundled_blas_without_ld_library_path() -> None:
    proc = _python("from fresco_bridge.opensees_runtime import import_opensees, "
                   "preload_bundled_libs\nops = import_opensees()\n"
                   "print('VERSION', ops.version())\n"
                   "print('LOADED', *sorted(p.name for p in preload_bundled_libs()))")
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = dict(ln.split(" ", 1) for ln in proc.stdout.splitlines()
                 if ln.startswith(("VERSION", "LOADED")))
    assert lines["VERSION"].startswith("3.")
    assert "libblas.so.3" in lines["LOADED"].split()


@pytest.mark.skipif(ctypes.util.find_library("blas") is not None,
                    reason="a system libblas is installed: the plain import works anyway")
def test_without_the_preload_the_plain_import_fails_here() -> None:
    """The control: on this machine the wheel alone does not load (what the preload fixes)."""
    proc = _python("import openseespy.opensees")
    assert proc.returncode != 0
    assert "Failed to import openseespy on Linux" in proc.stderr


def test_opensees_env_puts_the_bundled_libs_first() -> None:
    lib = bundled_lib_dir()
    assert lib is not None and (lib / "libblas.so.3").is_file()
    env = opensees_env({"LD_LIBRARY_PATH": "/opt/x", "HOME": "/h"})
    assert env == {"LD_LIBRARY_PATH": f"{lib}:/opt/x", "HOME": "/h"}
    assert opensees_env({})["LD_LIBRARY_PATH"] == str(lib)


def test_require_listening_names_every_port_nobody_listens_on() -> None:
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        open_port = server.getsockname()[1]
        closed = free_ports(2)
        require_listening([open_port])  # a listener: no error
        with pytest.raises(BridgeNotListening) as err:
            require_listening([open_port, *closed], hint="start: fresco-bridge serve")
    message = str(err.value)
    assert all(f"127.0.0.1:{port}" in message for port in closed)
    assert f":{open_port}" not in message
    assert message.endswith("(start: fresco-bridge serve)")


def test_a_local_listener_is_found_without_a_connection_to_it() -> None:
    """The bridge would log a connection that never sent its size ID as a refused client."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        server.setblocking(False)
        require_listening([server.getsockname()[1]])
        with pytest.raises(BlockingIOError):
            server.accept()  # nothing connected


def test_the_socket_table_lists_a_listener_and_an_absent_table_nothing(tmp_path: Path) -> None:
    assert _local_listeners(tmp_path / "absent") == set()
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        assert ("127.0.0.1", port) in _local_listeners()


def test_without_openseespy_the_error_says_how_to_install_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name.startswith("openseespy") else real(name, *a))
    with pytest.raises(OpenSeesUnavailable, match=r"not installed .*make demo installs it; or: "
                                                  r"pip install 'fresco-bridge\[opensees\]'"):
        import_opensees()
    with pytest.raises(OpenSeesUnavailable, match="not installed"):
        opensees_env({})
