"""Which requests the viewer's server answers: those addressed to it, from its own page, with a small body.

A web page the user visits can point a name of its own at 127.0.0.1 (DNS rebinding) and then send requests to the
viewer as a page of that name: the browser sends ``Host: evil.example:8765``, and an ``Origin`` of that site on
a POST. Checking both against the viewer's own addresses refuses them before anything runs. A ``Host`` that is an
IP address cannot be rebound; a viewer serving every interface (``--host 0.0.0.0``) takes any of them, so that it
can be reached by the machine's address.
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass
from email.message import Message

#: the most bytes a request body may have: an input is a small JSON object (docs/security.md)
MAX_BODY_BYTES = 4096
#: the names of this machine that a local viewer answers to, besides the ``--host`` it serves on
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
#: hosts that serve every interface of the machine
WILDCARD_HOSTS = ("0.0.0.0", "::", "")


@dataclass(frozen=True)
class Refusal:
    """A request refused before the application sees it: the status and a one-line reason."""

    status: int
    reason: str


class Guard:
    """The viewer's own addresses (names and port), and the checks of a request's head against them."""

    def __init__(self, host: str, port: int) -> None:
        self.port = port
        self.any_address = host in WILDCARD_HOSTS
        names = {*LOOPBACK_NAMES, host.strip("[]")} - set(WILDCARD_HOSTS)
        if self.any_address:
            names.add(socket.gethostname())
        self.names = frozenset(name.lower() for name in names)

    def allows(self, authority: str) -> bool:
        """Whether `authority` (``name:port`` of a Host header or an origin) is this viewer's."""
        parsed = split_authority(authority)
        if parsed is None or parsed[1] != self.port:
            return False
        name = parsed[0]
        return name in self.names or (self.any_address and is_address(name))

    def check(self, target: str, headers: Message) -> Refusal | None:
        """Why a request for `target` with `headers` is refused, or None where it is served."""
        if not target.startswith("/"):
            return Refusal(400, f"the request target {target[:100]!r} is not a path")
        hosts = headers.get_all("Host") or []
        if len(hosts) != 1 or not self.allows(hosts[0]):
            shown = ", ".join(repr(h[:100]) for h in hosts) or "none"
            return Refusal(421, f"Host {shown} is not this viewer's address ({self.described()})")
        origins = headers.get_all("Origin") or []
        if origins and (len(origins) != 1 or not origins[0].startswith("http://") or not self.allows(origins[0][7:])):
            shown = ", ".join(repr(o[:100]) for o in origins)
            return Refusal(403, f"Origin {shown} is not this viewer's page")
        if headers.get_all("Transfer-Encoding"):
            return Refusal(411, "the viewer takes bodies with a Content-Length only (no Transfer-Encoding)")
        lengths = headers.get_all("Content-Length") or []
        if lengths:
            if len(lengths) != 1 or not lengths[0].strip().isdigit() or not lengths[0].strip().isascii():
                return Refusal(400, f"a bad Content-Length: {', '.join(repr(n[:30]) for n in lengths)}")
            if int(lengths[0]) > MAX_BODY_BYTES:
                return Refusal(413, f"a body of {int(lengths[0])} bytes: the viewer takes at most {MAX_BODY_BYTES}")
        return None

    def described(self) -> str:
        """The addresses this viewer answers to, for a refusal's message."""
        names = sorted(f"[{n}]" if ":" in n else n for n in self.names)
        also = " or an IP address of this machine" if self.any_address else ""
        return f"{', '.join(names)}{also}, port {self.port}"


def split_authority(authority: str) -> tuple[str, int] | None:
    """``name:port`` as (lower-case name, port): an IPv6 address in brackets, port 80 where none is given; None where
    it is neither."""
    text = authority.strip()
    if text.startswith("["):
        name, bracket, rest = text[1:].partition("]")
        if not bracket or not is_address(name):
            return None
    else:
        name, colon, port_text = text.partition(":")
        rest = colon + port_text
        if not name or any(c in name for c in "/@?#[] \t"):
            return None
    if not rest:
        return name.lower(), 80
    port = rest[1:]
    if not rest.startswith(":") or not port.isdigit() or not port.isascii() or len(port) > 5:
        return None
    return name.lower(), int(port)


def is_address(name: str) -> bool:
    """Whether `name` is an IPv4 or IPv6 address (which no DNS answer can point elsewhere)."""
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True
