"""OpenSeesPy made importable and safe to start: the one home for what its wheel and its
``genericClient`` element need around them.

- **The bundled BLAS.** OpenSeesPy's Linux wheel (``openseespylinux``) ships BLAS, LAPACK and
  the Fortran runtime in ``openseespylinux/lib``. ``opensees.so`` finds its direct dependencies
  there through its ``RUNPATH`` (``$ORIGIN/lib``), but a ``RUNPATH`` is not inherited: LAPACK's
  own ``libblas.so.3`` is searched on the system path, so without Debian's ``libblas3`` the
  import fails (``ImportError: libblas.so.3``). :func:`preload_bundled_libs` loads the bundled
  libraries first, ``RTLD_GLOBAL``, dependencies before dependants; the loader then satisfies
  the later lookups by soname. No ``LD_LIBRARY_PATH``, no re-exec. A child process that imports
  OpenSeesPy itself (a test's or a benchmark's client script) gets the variable instead
  (:func:`opensees_env`), set before it starts.
- **A bridge that is not there.** A ``genericClient`` element connects once when the model is
  analysed; refused, OpenSees prints ``failed to setup connection`` and dies with a segfault.
  :func:`require_listening` checks each element's port first (in the kernel's socket table when
  the bridge is local, so the bridge sees no probe) and raises a clear error instead.
"""

from __future__ import annotations

import ctypes
import importlib
import importlib.util
import os
import socket
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import ModuleType

__all__ = [
    "BridgeNotListening",
    "OpenSeesUnavailable",
    "bundled_lib_dir",
    "import_opensees",
    "opensees_env",
    "preload_bundled_libs",
    "require_listening",
]

INSTALL_HINT = "make demo installs it; or: pip install 'fresco-bridge[opensees]'"
"""How to get OpenSeesPy (the ``opensees`` extra of ``pyproject.toml``)."""

_preloaded: list[Path] = []
"""What :func:`preload_bundled_libs` loaded in this process (it runs once)."""


class OpenSeesUnavailable(RuntimeError):
    """OpenSeesPy is not installed, or its library cannot be loaded here."""


class BridgeNotListening(ConnectionError):
    """No server accepts connections on a port a ``genericClient`` element will connect to."""


def bundled_lib_dir() -> Path | None:
    """``openseespylinux/lib`` of the installed wheel, or ``None`` (not Linux, not installed,
    or a build without bundled libraries)."""
    spec = importlib.util.find_spec("openseespylinux")
    if spec is None or not spec.submodule_search_locations:
        return None
    lib = Path(next(iter(spec.submodule_search_locations))) / "lib"
    return lib if lib.is_dir() else None


def preload_bundled_libs() -> list[Path]:
    """Load the wheel's bundled shared libraries into this process (``RTLD_GLOBAL``); the
    libraries loaded, in order. Idempotent; nothing to do off Linux or without the wheel.

    The order is found, not listed: each pass loads what it can and retries the rest (a library
    whose own dependency is not loaded yet fails its pass), so another wheel version's set of
    libraries needs no change here.
    """
    if _preloaded:
        return list(_preloaded)
    lib = bundled_lib_dir()
    if lib is None:
        return []
    pending = sorted(p for p in lib.iterdir() if ".so" in p.name and p.is_file())
    errors: dict[Path, str] = {}
    while pending:
        failed = []
        for path in pending:
            try:
                ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
            except OSError as exc:
                failed.append(path)
                errors[path] = str(exc)
            else:
                _preloaded.append(path)
        if len(failed) == len(pending):
            raise OpenSeesUnavailable(
                f"cannot load OpenSeesPy's bundled libraries from {lib}: "
                + "; ".join(errors[p] for p in failed))
        pending = failed
    return list(_preloaded)


def import_opensees() -> ModuleType:
    """``openseespy.opensees``, its bundled libraries preloaded first.

    Raises :class:`OpenSeesUnavailable` (saying how to install it, or what failed to load)
    rather than OpenSeesPy's bare ``RuntimeError: Failed to import openseespy on Linux``.
    """
    if importlib.util.find_spec("openseespy") is None:
        raise OpenSeesUnavailable(f"OpenSeesPy is not installed in {sys.executable} "
                                  f"({INSTALL_HINT})")
    preload_bundled_libs()
    try:
        return importlib.import_module("openseespy.opensees")
    except (ImportError, RuntimeError) as exc:  # openseespy hides the cause in a RuntimeError
        cause = exc.__cause__ or exc.__context__ or exc
        raise OpenSeesUnavailable(f"OpenSeesPy is installed but cannot be loaded: {cause}") \
            from None


def opensees_env(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """``base`` (default: this process's environment) with the bundled libraries on
    ``LD_LIBRARY_PATH``, for a child process that imports OpenSeesPy itself (the loader reads
    the variable when the process starts, so it is set here, before)."""
    env = dict(os.environ if base is None else base)
    lib = bundled_lib_dir()
    if lib is not None:
        env["LD_LIBRARY_PATH"] = f"{lib}:{env.get('LD_LIBRARY_PATH', '')}".rstrip(":")
    elif importlib.util.find_spec("openseespy") is None:
        raise OpenSeesUnavailable(f"OpenSeesPy is not installed ({INSTALL_HINT})")
    return env


def require_listening(ports: Iterable[int], host: str = "127.0.0.1", *,
                      timeout: float = 2.0, hint: str = "") -> None:
    """Raise :class:`BridgeNotListening` unless every one of ``ports`` on ``host`` accepts TCP
    connections (``hint``: what to start, appended to the message).

    A listener of this machine is seen in the kernel's socket table without touching it: a
    connect-and-close probe would reach the bridge as a connection that never sent its size
    ID, logged as refused. Only what the table does not show (another host; no ``/proc``) is
    probed by connecting, within ``timeout`` seconds.
    """
    listening = _local_listeners()
    missing = []
    for port in ports:
        if (host, port) in listening or ("0.0.0.0", port) in listening:
            continue
        try:
            with socket.create_connection((host, port), timeout=timeout):
                pass
        except OSError as exc:
            missing.append(f"{host}:{port} ({exc.strerror or exc})")
    if missing:
        raise BridgeNotListening(
            f"no bridge is listening on {', '.join(missing)}; the genericClient elements "
            "connect there, so the bridge must be serving before OpenSees starts"
            + (f" ({hint})" if hint else ""))


def _local_listeners(table: Path = Path("/proc/net/tcp")) -> set[tuple[str, int]]:
    """(IPv4 address, port) of every listening TCP socket of this machine (Linux), else empty.

    Each row of the table has ``local_address`` as ``AABBCCDD:PPPP`` (the address as a
    native-endian 32-bit hex number, the port big hex) and the state ``0A`` for LISTEN.
    """
    try:
        rows = table.read_text(encoding="ascii").splitlines()[1:]
    except OSError:
        return set()
    found = set()
    for row in rows:
        fields = row.split()
        if len(fields) > 3 and fields[3] == "0A":
            address, port = fields[1].split(":")
            ip = socket.inet_ntoa(int(address, 16).to_bytes(4, sys.byteorder))
            found.add((ip, int(port, 16)))
    return found
