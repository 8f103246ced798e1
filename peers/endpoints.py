"""Endpoint strings for secure mode: TLS only, since a ``tcp/`` endpoint bypasses mutual TLS."""

from __future__ import annotations

from collections.abc import Iterable

from sensornet.peers.errors import SecurityError


def tls_endpoint(port: int, host: str = "127.0.0.1") -> str:
    """The ``tls/`` endpoint of ``host:port``."""
    return f"tls/{host}:{port}"


def check_endpoints(endpoints: Iterable[str]) -> None:
    """Secure mode speaks TLS only: a ``tcp/`` endpoint would bypass mutual TLS."""
    bad = [e for e in endpoints if not e.startswith("tls/")]
    if bad:
        raise SecurityError(f"secure mode needs tls/ endpoints, not {', '.join(bad)}")
