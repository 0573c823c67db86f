"""Who may do what through the console: loopback by default, control only when asked for.

Three rules, checked on every request (decision 0013):

1. **Host**: on a loopback address the ``Host`` header must name the server itself
   (``127.0.0.1:PORT``, ``localhost:PORT``, ``[::1]:PORT``); beyond loopback it must be an
   IP address (``192.168.1.5:PORT``, ``[fd00::5]:PORT``). Either way a name the user
   listed (``--console-host-name``) is accepted too. So a web page that rebinds its own
   domain name to the console's address (DNS rebinding) gets nothing.
2. **Origin**: a request that carries an ``Origin`` (every browser ``fetch`` POST and every
   WebSocket does) must come from the console's own page, so another site open in the same
   browser cannot read the vehicle's data or press its buttons (cross-site request
   forgery, cross-site WebSocket hijacking). POSTs must be ``application/json``, which a
   plain HTML form cannot send and a cross-site script cannot send without a CORS
   preflight, which the console never grants.
3. **Control**: starting, stopping and restarting components and commanding the vehicle
   (start, arbiter on/off) need the console to be started with control allowed
   (``--console-control``) *and* the per-run token the console prints in its URL's
   fragment (never sent to the server in a URL, so it is in no log). "Stop vehicle" needs
   neither: it is always available.
"""

from __future__ import annotations

import ipaddress
import re
import secrets
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["ControlGuard", "parse_address", "is_loopback", "host_name", "TOKEN_HEADER"]

#: The header the page sends its control token in.
TOKEN_HEADER = "X-Afa-Control-Token"
#: A host name (lower case), as ``--console-host-name`` takes it and a ``Host`` holds it.
_NAME = r"[a-z0-9_.-]+"
#: A ``Host`` header: a name or an IP address (IPv6 in brackets), perhaps a port.
_HOST = re.compile(rf"(?P<host>\[[0-9a-f:.]+\]|{_NAME})(?::[0-9]{{1,5}})?")

Permission = Literal["view", "stop", "replay", "control"]


def parse_address(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """``[HOST:]PORT`` → (host, port). ``PORT`` alone or ``:PORT`` listens on
    ``default_host``; IPv6 hosts go in brackets (``[::1]:8765``). Port 0 picks a free port.
    Raises ValueError with a message for anything else."""
    value = text.strip()
    host, sep, port_text = value.rpartition(":")
    if not sep:
        host, port_text = "", value
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif ":" in host:
        raise ValueError(f"{text!r}: put an IPv6 address in brackets, e.g. [::1]:8765")
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"{text!r} is not [HOST:]PORT (e.g. 8765 or 0.0.0.0:8765)") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"{text!r}: port {port} is outside 0..65535")
    return host or default_host, port


def host_name(text: str) -> str:
    """A name the console may be reached by (``vehicle.lan``), lower case. Raises
    ValueError for anything else (a port, a path)."""
    name = text.strip().lower()
    if not re.fullmatch(_NAME, name):
        raise ValueError(f"{text!r} is not a host name (e.g. vehicle.lan, without a port)")
    return name


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass
class ControlGuard:
    """The rules above for one console listening on ``host:port``."""

    host: str
    port: int
    control: bool = False
    #: further names the console may be reached by (lower case; any port)
    names: frozenset[str] = frozenset()
    token: str = field(default_factory=lambda: secrets.token_urlsafe(18))

    def accepts_host(self, host_header: str) -> bool:
        """Does ``host_header`` name this console (rule 1)?"""
        found = _HOST.fullmatch(host_header.lower())
        if found is None:
            return False
        host = found["host"]
        if host in self.names:
            return True
        if is_loopback(self.host):
            port = self.port
            return host_header.lower() in {f"127.0.0.1:{port}", f"localhost:{port}",
                                           f"[::1]:{port}", f"{self.host}:{port}"}
        try:
            ipaddress.ip_address(host.strip("[]"))  # an IP address: no name to rebind
        except ValueError:
            return False
        return True

    def check_request(self, host_header: str | None, origin: str | None) -> str | None:
        """Why a request must be refused (Host and Origin rules), or None."""
        if host_header is None:
            return "no Host header"
        if not self.accepts_host(host_header):
            hint = "" if is_loopback(self.host) else (
                ": use its IP address, or give the name with --console-host-name")
            return f"Host {host_header!r} is not this console{hint}"
        if origin is not None and origin != "null" and origin.lower() != (
                f"http://{host_header}".lower()):
            return f"requests from {origin!r} are not accepted (only from the console's page)"
        if origin == "null":
            return "requests from opaque origins are not accepted"
        return None

    def check_permission(self, permission: Permission, token: str | None) -> str | None:
        """Why an action needing ``permission`` must be refused, or None."""
        if permission in ("view", "stop", "replay"):
            return None
        if not self.control:
            return ("control is off: start the console with --console-control to start, "
                    "stop or restart components and to command the vehicle ('stop vehicle' "
                    "always works)")
        # as bytes: a header may hold any character (compare_digest refuses non-ASCII str)
        if token is None or not secrets.compare_digest(
                token.encode("utf-8", "surrogateescape"), self.token.encode()):
            return ("missing or wrong control token: open the URL the console printed "
                    "(it ends in #token=...)")
        return None
