"""What the asyncio drivers raise at their user.

Every exception is a :class:`ChaosError` and carries the reason text the peer (or the driver) gave, so
a client can report *why* without knowing which Chaos packet ended the connection.  The names follow the
Chaos vocabulary (a refusal is a CLS, a loss a LOS, a broken connection one whose peer fell silent),
which is why most of them do not end in ``Error``.
"""

from __future__ import annotations

from .address import DEFAULT_CLIENT_ADDR, DEFAULT_SERVER_ADDR


class ChaosError(Exception):
    """Base class of every error the links, the driver and the connection API raise."""

    def __init__(self, reason: str = "") -> None:
        super().__init__(reason)
        self.reason = reason

    def __str__(self) -> str:
        return self.reason or type(self).__name__


class LinkError(ChaosError):
    """A link could not be made or used (TCP connect failed, no route to the host, socket error)."""


class ConnectionRefused(ChaosError):  # noqa: N818 - Chaos vocabulary (CLS in answer to an RFC)
    """The server answered the RFC with CLS; ``reason`` is the text of the CLS."""


class ConnectionAnswered(ChaosError):  # noqa: N818 - Chaos vocabulary (ANS in answer to an RFC)
    """The server gave a simple answer (ANS) instead of a connection; ``data`` is the answer."""

    def __init__(self, data: bytes) -> None:
        super().__init__(f"simple answer of {len(data)} bytes instead of a connection")
        self.data = data


class ConnectionForwarded(ChaosError):  # noqa: N818 - Chaos vocabulary (FWD in answer to an RFC)
    """The server forwarded the RFC: try ``contact`` at ``host`` instead."""

    def __init__(self, host: int, contact: str) -> None:
        super().__init__(f"forwarded to contact {contact!r} at {chaos_host(host)} (named by the FWD)")
        self.host = host
        self.contact = contact


class ConnectTimeout(ChaosError, TimeoutError):  # noqa: N818 - also a TimeoutError
    """No OPN arrived in time (the RFC went unanswered, or the open timed out)."""


class ConnectionClosed(ChaosError):  # noqa: N818 - Chaos vocabulary (CLS or EOF)
    """The connection ended normally: the peer's EOF was read, a CLS arrived, or we closed it.

    ``by_peer`` says whether the peer ended it (EOF or CLS) or we did (close, abort)."""

    def __init__(self, reason: str = "", *, by_peer: bool = True) -> None:
        super().__init__(reason)
        self.by_peer = by_peer


class ConnectionLost(ChaosError):  # noqa: N818 - Chaos vocabulary (LOS)
    """The peer's NCP sent LOS: it does not know the connection or something went badly wrong."""


class ConnectionBroken(ChaosError):  # noqa: N818 - Chaos vocabulary (INCOMPLETE)
    """The peer fell silent for ``broken_after`` seconds, or the link under the connection closed."""


def chaos_host(host: int) -> str:
    """A Chaos address for a message, in octal, saying what it is when it is a default a user who gave
    no ``addr=`` or ``me=`` did not type: ``Chaos host 0440 (the robot's default address)``."""
    default = {
        DEFAULT_SERVER_ADDR: " (the robot's default address)",
        DEFAULT_CLIENT_ADDR: " (the client's default address)",
    }.get(host, "")
    return f"Chaos host 0{host:o}{default}" if host else f"Chaos host 0{default}"


PEER_LINE_SHOWN = 72
"""Characters of a foreign peer's first line shown in :func:`not_a_chaos_link`."""


def not_a_chaos_link(head: bytes) -> str:
    """Why a link whose peer's first bytes are not the link framing is dropped, showing what the peer
    sent: its first line when it is text (an HTTP server's status line, an SSH greeting), else the
    first bytes in hex.  ``the peer answered `HTTP/1.0 400 Bad Request`: not a Chaos link``."""
    line = head.split(b"\n", 1)[0].rstrip(b"\r")
    printable = sum(32 <= b < 127 or b == 9 for b in line)
    if line and printable * 4 >= len(line) * 3:
        text = "".join(chr(b) if 32 <= b < 127 else f"\\x{b:02x}" for b in line[:PEER_LINE_SHOWN])
        shown = f"`{text}{'...' if len(line) > PEER_LINE_SHOWN else ''}`"
    else:
        shown = f"bytes {head[:16].hex(' ')}{' ...' if len(head) > 16 else ''}"
    return f"the peer answered {shown}: not a Chaos link"


def fresh(exc: ChaosError) -> ChaosError:
    """A new instance of ``exc``: raising one stored instance again and again would pile up tracebacks."""
    if isinstance(exc, ConnectionClosed):
        return ConnectionClosed(exc.reason, by_peer=exc.by_peer)
    if isinstance(exc, ConnectionAnswered):
        return ConnectionAnswered(exc.data)
    if isinstance(exc, ConnectionForwarded):
        return ConnectionForwarded(exc.host, exc.contact)
    return type(exc)(exc.reason)
