"""One address syntax for every manip command and the library.

    tcp://HOST:PORT[?contact=PUMA&me=0401&addr=0440]        manip's TCP link (the embedded default)
    chudp://HOST:PORT?addr=0440[&me=0401&local=HOST:PORT]   Chaos over UDP, as klh10 and simh speak it
    chaosd:///PATH[?addr=0440&me=0401]                      usim's chaosd unix socket
    unix:///PATH[?contact=PUMA&me=0401&addr=0440]           manip's TCP link framing on a Unix-domain socket

``addr`` is the Chaos address of the far end (the robot's host), ``me`` our own; both are octal, as
Chaosnet addresses are always written.  ``contact`` is the contact name the server listens on.  IPv6
hosts go in brackets: ``tcp://[::1]:42085``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Final, Literal
from urllib.parse import parse_qs, urlencode, urlsplit

from manip.spec.notation import octal

Scheme = Literal["tcp", "chudp", "chaosd", "unix"]

DEFAULT_TCP_PORT: Final = 42085
"""manip's TCP link port (an arbitrary choice: "Puma, 1985")."""
DEFAULT_CHUDP_PORT: Final = 42042
"""The CHUDP port klh10, simh and the global Chaosnet use."""
DEFAULT_CONTACT: Final = "PUMA"
DEFAULT_SERVER_ADDR: Final = 0o440
DEFAULT_CLIENT_ADDR: Final = 0o401
DEFAULT_CHAOSD_PATH: Final = "/var/tmp/chaosd_server"

_KNOWN_PARAMS = {"contact", "me", "addr", "local"}


class AddressError(ValueError):
    """A link address that cannot be used; the message says which part is wrong."""


@dataclass(frozen=True)
class LinkAddress:
    scheme: Scheme
    host: str = "127.0.0.1"
    port: int = DEFAULT_TCP_PORT
    path: str | None = None
    peer_addr: int = DEFAULT_SERVER_ADDR
    my_addr: int = DEFAULT_CLIENT_ADDR
    contact: str = DEFAULT_CONTACT
    local: tuple[str, int] | None = None

    @property
    def framing(self) -> Literal["tcp", "chudp", "chaosd"]:
        """How packets are framed on this link: a ``unix://`` link carries the TCP link's frames."""
        return "tcp" if self.scheme == "unix" else self.scheme

    def with_port(self, port: int) -> LinkAddress:
        return replace(self, port=port)

    def __str__(self) -> str:
        params: dict[str, str] = {}
        if self.contact != DEFAULT_CONTACT:
            params["contact"] = self.contact
        if self.my_addr != DEFAULT_CLIENT_ADDR:
            params["me"] = octal(self.my_addr)
        if self.peer_addr != DEFAULT_SERVER_ADDR or self.scheme == "chudp":
            params["addr"] = octal(self.peer_addr)
        if self.local is not None:
            params["local"] = f"{_host(self.local[0])}:{self.local[1]}"
        query = f"?{urlencode(params, safe=':[]')}" if params else ""
        if self.scheme in ("chaosd", "unix"):
            return f"{self.scheme}://{self.path}{query}"
        return f"{self.scheme}://{_host(self.host)}:{self.port}{query}"


def _host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def _chaos_address(text: str, name: str) -> int:
    digits = text[2:] if text.lower().startswith("0o") else text
    try:
        value = int(digits, 8)
    except ValueError:
        raise AddressError(f"{name}={text!r} is not an octal Chaos address") from None
    if not 0 < value <= 0xFFFF or value & 0xFF == 0:
        raise AddressError(f"{name}={text!r} is not a Chaos host address (subnet<<8 | host, host non-zero)")
    return value


def _host_port(text: str, name: str) -> tuple[str, int]:
    split = urlsplit(f"//{text}")
    if split.hostname is None or split.port is None:
        raise AddressError(f"{name}={text!r} is not HOST:PORT")
    return split.hostname, split.port


def parse_address(url: str, *, default_scheme: Scheme = "tcp") -> LinkAddress:
    """Parse a link address; a bare ``HOST[:PORT]`` means ``default_scheme``."""
    if "://" not in url:
        url = f"{default_scheme}://{url}"
    split = urlsplit(url)
    scheme = split.scheme
    if scheme not in ("tcp", "chudp", "chaosd", "unix"):
        raise AddressError(f"unknown link scheme {scheme!r}; use tcp://, chudp://, chaosd:// or unix://")
    raw = parse_qs(split.query, keep_blank_values=True)
    unknown = set(raw) - _KNOWN_PARAMS
    if unknown:
        raise AddressError(f"unknown parameter(s) {sorted(unknown)}; known: {sorted(_KNOWN_PARAMS)}")
    params = {k: v[-1] for k, v in raw.items()}
    contact = params.get("contact", DEFAULT_CONTACT)
    if not contact or not contact.isascii() or " " in contact:
        raise AddressError(f"contact={contact!r} must be non-empty ASCII without spaces")
    me = _chaos_address(params["me"], "me") if "me" in params else DEFAULT_CLIENT_ADDR
    peer = _chaos_address(params["addr"], "addr") if "addr" in params else DEFAULT_SERVER_ADDR
    local = _host_port(params["local"], "local") if "local" in params else None
    if scheme == "chaosd":
        path = (split.netloc + split.path) or DEFAULT_CHAOSD_PATH
        return LinkAddress("chaosd", path=path, peer_addr=peer, my_addr=me, contact=contact)
    if scheme == "unix":
        path = split.netloc + split.path
        if not path:
            raise AddressError("a unix:// address needs the socket's path: unix:///PATH")
        return LinkAddress("unix", path=path, peer_addr=peer, my_addr=me, contact=contact)
    if scheme == "chudp" and "addr" not in params:
        raise AddressError("a chudp:// address needs addr=OCTAL, the Chaos address of the peer")
    try:
        port = split.port
    except ValueError as exc:
        raise AddressError(f"bad port in {url!r}: {exc}") from None
    default_port = DEFAULT_TCP_PORT if scheme == "tcp" else DEFAULT_CHUDP_PORT
    return LinkAddress(
        scheme,  # type: ignore[arg-type]
        host=split.hostname or "127.0.0.1",
        port=default_port if port is None else port,
        peer_addr=peer,
        my_addr=me,
        contact=contact,
        local=local,
    )
