"""Mutual TLS for a site, as OpenFresco's ``TCP_SocketSSL`` server does it.

OpenFresco (``TCP_SocketSSL``): PEM files, ``TLS_server_method``, the server presents
``server.crt``/``server.key`` and, with ``VERIFY_CLIENT`` on (its default), requires a client
certificate (``SSL_VERIFY_PEER | SSL_VERIFY_FAIL_IF_NO_PEER_CERT``) checked against
``server_ca.crt`` with verify depth 1: the client's certificate must be issued *directly* by a
CA of that file. Python's ``ssl`` module has no ``SSL_CTX_set_verify_depth``, so the handshake
verifies the chain (signature, validity dates, purpose) and ``check_issued_directly`` then
refuses any chain longer than the client certificate and one CA of the file.
"""

from __future__ import annotations

import ssl
from pathlib import Path
from typing import Any

from ..config import ConfigError

HANDSHAKE_TIMEOUT = 10.0
"""Seconds a client has to complete the TLS handshake."""
MAX_HANDSHAKES = 8
"""TLS handshakes in flight per site; more connections are refused busy before theirs.

A site serves one client: the others of a burst were refused busy after their handshake
anyway, and each handshake in flight holds an SSL object and a read buffer of up to
256 KiB, whose freed memory the allocator keeps (BENCHMARKS.md, "Fuzz and soak")."""


class TlsConfigError(ConfigError):
    """The site's certificate, key or CA file cannot be used (names the file and why)."""


def server_context(cert_file: Path, key_file: Path, client_ca_file: Path) -> ssl.SSLContext:
    """A server context that requires a client certificate issued by ``client_ca_file``."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.verify_mode = ssl.CERT_REQUIRED
    try:
        ctx.load_cert_chain(str(cert_file), str(key_file))
    except (OSError, ssl.SSLError) as exc:
        raise TlsConfigError(f"{cert_file} / {key_file}: cannot load the site's certificate and "
                             f"key: {exc}") from None
    try:
        ctx.load_verify_locations(cafile=str(client_ca_file))
    except (OSError, ssl.SSLError) as exc:
        raise TlsConfigError(f"{client_ca_file}: cannot load the client CA file: {exc}") from None
    if not ctx.get_ca_certs():
        raise TlsConfigError(f"{client_ca_file}: no CA certificate in the file")
    return ctx


def _name(rdns: Any) -> tuple[tuple[str, str], ...]:
    return tuple(sorted((k, v) for rdn in rdns for k, v in rdn))


def check_issued_directly(ctx: ssl.SSLContext, peer: dict[str, Any] | None) -> str | None:
    """None if the verified client certificate ``peer`` was issued by a CA of the context's
    CA file itself (depth 1), else why not."""
    if not peer:
        return "no client certificate"
    issuer = _name(peer.get("issuer", ()))
    cas = {_name(ca.get("subject", ())) for ca in ctx.get_ca_certs()}
    if issuer not in cas:
        return ("client certificate is not issued directly by a CA of client_ca_file "
                "(verify depth 1, as OpenFresco: no intermediate CAs)")
    return None


def describe_failure(exc: BaseException) -> str:
    """A handshake failure in words (expired, unknown CA, not TLS at all, …)."""
    if isinstance(exc, ssl.SSLCertVerificationError):
        return f"client certificate refused: {exc.verify_message}"
    if isinstance(exc, ssl.SSLError):
        reason = exc.reason or str(exc)
        if reason in ("WRONG_VERSION_NUMBER", "HTTP_REQUEST", "UNKNOWN_PROTOCOL"):
            return f"not a TLS client (plain TCP to a TLS site?): {reason}"
        if reason == "PEER_DID_NOT_RETURN_A_CERTIFICATE":
            return "client presented no certificate (mutual TLS required)"
        return f"TLS handshake failed: {reason}"
    if isinstance(exc, TimeoutError):
        return f"TLS handshake not completed within {HANDSHAKE_TIMEOUT:g} s"
    return f"TLS handshake failed: {type(exc).__name__}: {exc}"
