"""manip's TCP link: each TCP connection is one point-to-point Chaos link (framing ``tcp``).

The client dials the server's host and port; the server accepts any number of TCP connections and
hands each new link to its driver.  The same framing runs on Unix-domain stream sockets (``unix://``
addresses): a local link whose writes reach the reader before ``send`` returns, which a simulated run
on a virtual clock needs (:mod:`manip.links.virtual_clock`).  The peer's Chaos address is known up
front on the client side (``addr=`` of the link address) and learnt from the first good frame's trailer
on the server side.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable

from manip.codecs.framing import TcpFrameDecoder, encode_tcp
from manip.ncp.defects import ChaosDefects

from .errors import LinkError
from .guard import LinkGuard, LinkLimits
from .listener import StreamListener, bind_stream, bind_unix
from .stream import StreamLink, dial, stream_max_body


class TcpLink(StreamLink):
    """One TCP connection carrying manip TCP link framing v1."""

    kind = "tcp"

    def __init__(
        self, *, my_addr: int, peer_addr: int | None = None, defects: ChaosDefects | None = None
    ) -> None:
        decoder = TcpFrameDecoder(max_body=stream_max_body(defects))
        super().__init__(encode_tcp, decoder, my_addr=my_addr, peer_addr=peer_addr, defects=defects)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        peer = transport.get_extra_info("peername")
        if isinstance(peer, tuple) and self.name == self.kind:
            self.name = f"tcp:{_endpoint(peer)}"
        elif self.name == self.kind and transport.get_extra_info("socket").family == socket.AF_UNIX:
            self.name = "unix"  # a Unix peer has no name worth showing (the client's socket is unbound)
        super().connection_made(transport)


def _endpoint(sockaddr: tuple[object, ...]) -> str:
    host, port = str(sockaddr[0]), sockaddr[1]
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


async def connect_tcp(
    host: str, port: int, *, my_addr: int, peer_addr: int | None = None, timeout: float | None = 10.0
) -> TcpLink:
    """Dial a TCP link; raise :class:`LinkError` if the TCP connection cannot be made."""
    link = TcpLink(my_addr=my_addr, peer_addr=peer_addr)
    loop = asyncio.get_running_loop()
    where = f"tcp://{_endpoint((host, port))}"
    return await dial(link, lambda: loop.create_connection(lambda: link, host, port), where, timeout)


async def serve_tcp(
    host: str,
    port: int,
    *,
    my_addr: int,
    on_link: Callable[[TcpLink], None],
    guard: LinkGuard | None = None,
    defects: ChaosDefects | None = None,
) -> StreamListener:
    """Listen for TCP links; ``on_link`` gets each new link before any packet arrives on it.

    ``guard`` admits each peer first and bounds the links (:mod:`~manip.links.guard`; default: everyone,
    no bounds).  ``port`` 0 picks a free port: read it from the listener's ``sockets``."""
    try:
        sockets = await bind_stream(host, port)
    except OSError as exc:
        raise LinkError(f"cannot listen on tcp://{_endpoint((host, port))}: {exc}") from exc
    return _listener(sockets, my_addr, on_link, guard, defects)


async def connect_unix(
    path: str, *, my_addr: int, peer_addr: int | None = None, timeout: float | None = 10.0
) -> TcpLink:
    """Dial the TCP link framing on a Unix-domain socket; :class:`LinkError` if it cannot be made."""
    link = TcpLink(my_addr=my_addr, peer_addr=peer_addr)
    loop = asyncio.get_running_loop()
    return await dial(
        link, lambda: loop.create_unix_connection(lambda: link, path), f"unix://{path}", timeout
    )


async def serve_unix(
    path: str,
    *,
    my_addr: int,
    on_link: Callable[[TcpLink], None],
    guard: LinkGuard | None = None,
    defects: ChaosDefects | None = None,
) -> StreamListener:
    """Listen for links with the TCP link framing on a Unix-domain socket at ``path`` (which must not
    exist yet), under ``guard`` as :func:`serve_tcp` is."""
    try:
        sock = bind_unix(path)
    except OSError as exc:
        raise LinkError(f"cannot listen on unix://{path}: {exc}") from exc
    return _listener([sock], my_addr, on_link, guard, defects)


def _listener(
    sockets: list[socket.socket],
    my_addr: int,
    on_link: Callable[[TcpLink], None],
    guard: LinkGuard | None,
    defects: ChaosDefects | None,
) -> StreamListener:
    """Accept TCP-framed links on ``sockets``; each new link goes to ``on_link`` before it reads (and
    sends with ``defects``, when given)."""

    def factory() -> TcpLink:
        link = TcpLink(my_addr=my_addr, defects=defects)
        on_link(link)
        return link

    return StreamListener(sockets, factory, guard or LinkGuard(LinkLimits.unlimited()))
