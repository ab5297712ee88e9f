"""Who may reach a served twin (`longwall serve`, twin.opcua.server), checked before anything starts: anonymous
access on a loopback address only; binding any other address needs a user, its password in PASSWORD_ENV, and is
refused without one, in one line. No asyncua here: a refusal does not need the opcua extra."""

from __future__ import annotations

import ipaddress
import os
from urllib.parse import urlparse

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"
PASSWORD_ENV = "LONGWALL_OPCUA_PASSWORD"


class ServeError(ValueError):
    """A serve or record request that cannot be met (one line: what, where, how to fix)."""


def parse_endpoint(endpoint: str, option: str = "--endpoint") -> tuple[str, int]:
    """(host, port) of an opc.tcp:// endpoint given as `option`; ServeError otherwise."""
    url = urlparse(endpoint)
    try:
        port = url.port
    except ValueError:
        port = None
    if url.scheme != "opc.tcp" or not url.hostname or port is None:
        raise ServeError(f"{option} {endpoint}: not opc.tcp://HOST:PORT (e.g. {DEFAULT_ENDPOINT})")
    return url.hostname, port


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_access(host: str, user: str | None) -> None:
    """Anonymous access on loopback only: another address needs --user with its password in PASSWORD_ENV."""
    if is_loopback(host):
        return
    if user is None:
        raise ServeError(f"--endpoint {host}: anonymous access is served on a loopback address only; to bind {host}, "
                         f"give --user NAME and its password in the environment variable {PASSWORD_ENV}")
    if not os.environ.get(PASSWORD_ENV):
        raise ServeError(f"--user {user}: no password in the environment variable {PASSWORD_ENV}; set it to bind {host}")
